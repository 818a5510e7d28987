// Settings as the nodes read them, without running a node: config/*.yaml as the launch files load
// them, the ~occupancy/extent box, the dynamic_reconfigure cfgs against the config structs, and
// FusionConfig's settings table (core/fusion_settings.h) against cfg/Fusion.cfg and the node's
// parameters.
#include <dynamic_reconfigure/Config.h>
#include <dynamic_reconfigure/ConfigDescription.h>
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <limits>
#include <map>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "unsup_mvs/core/fusion_settings.h"
#include "unsup_mvs/ros/live_settings.h"
#include "unsup_mvs/ros/params.h"
#include "unsup_mvs/ros/reconfigure.h"

namespace {

// The parameter names under `ns` (the keys of a YAML the test launch file loaded there).
std::set<std::string> keys_under(const std::string& ns) {
  std::vector<std::string> all;
  ros::NodeHandle().getParamNames(all);
  std::set<std::string> keys;
  for (const auto& name : all) {
    if (name.rfind(ns + "/", 0) == 0) keys.insert(name.substr(ns.size() + 1));
  }
  return keys;
}

// config/*.yaml say only what differs from the code's defaults, and parse into valid configs (as
// the launch files load them); without them the nodes serve `umvs infer`'s inference.
TEST(ConfigFiles, TheYamlsParseAndSayOnlyWhatDiffersFromTheDefaults) {
  const auto fusion = umvs_ros::fusion_node_config_from_ros(ros::NodeHandle("/yaml/fusion"));
  const umvs::FusionConfig fusion_defaults;
  EXPECT_EQ(keys_under("/yaml/fusion"), (std::set<std::string>{"voxel_size", "min_confidence", "min_agreeing_views"}));
  EXPECT_NE(fusion.fusion.voxel_size, fusion_defaults.voxel_size);
  EXPECT_NE(fusion.fusion.min_confidence, fusion_defaults.min_confidence);
  EXPECT_NE(fusion.fusion.min_agreeing_views, fusion_defaults.min_agreeing_views);

  const auto inference = umvs_ros::inference_node_config_from_ros(ros::NodeHandle("/yaml/inference"));
  const umvs_ros::InferenceNodeConfig inference_defaults;
  EXPECT_EQ(keys_under("/yaml/inference"), (std::set<std::string>{"max_width", "max_height"}));
  EXPECT_NE(inference.estimator.max_width, inference_defaults.estimator.max_width);
  EXPECT_NE(inference.estimator.max_height, inference_defaults.estimator.max_height);
  EXPECT_EQ(inference_defaults.estimator.source_combination, umvs::kRecommendedSourceCombination);
  EXPECT_DOUBLE_EQ(inference_defaults.estimator.completion.min_confidence, umvs::kRecommendedCompletionConfidence);

  umvs_ros::keyframe_stream_config_from_ros(ros::NodeHandle("/yaml/keyframe_selector"));
  EXPECT_EQ(keys_under("/yaml/keyframe_selector"), std::set<std::string>{});

  const auto trainer = umvs_ros::trainer_node_config_from_ros(ros::NodeHandle("/yaml/trainer"));
  EXPECT_EQ(keys_under("/yaml/trainer"), (std::set<std::string>{"train_args"}));
  EXPECT_FALSE(trainer.job.train_args.empty());
  EXPECT_TRUE(umvs::FineTuneConfig{}.train_args.empty());
}

// ~occupancy/extent: a box of six numbers (integers too), anything else refused by name.
TEST(ConfigFiles, TheOccupancyExtentIsABoxOfSixNumbersOrRefusedByName) {
  const std::string ns = "/extent_cases/fusion";
  const auto refusal = [&]() -> std::string {
    try {
      umvs_ros::fusion_node_config_from_ros(ros::NodeHandle(ns));
      return "";
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
  };
  ros::param::set(ns + "/occupancy/extent", std::vector<int>{-5, -4, -1, 5, 4, 3});
  EXPECT_EQ(refusal(), "");
  EXPECT_DOUBLE_EQ(umvs_ros::fusion_node_config_from_ros(ros::NodeHandle(ns)).occupancy_map.min_y, -4.0);
  ros::param::set(ns + "/occupancy/extent", std::string("the ground floor"));
  EXPECT_NE(refusal().find("occupancy/extent must be a list"), std::string::npos) << refusal();
  ros::param::set(ns + "/occupancy/extent", std::vector<double>{1, 2, 3});
  EXPECT_NE(refusal().find("got 3 numbers"), std::string::npos) << refusal();
  ros::param::set(ns + "/occupancy/extent", std::vector<double>{5, 0, 0, 1, 1, 1});
  EXPECT_NE(refusal().find("at least one leaf (resolution) across"), std::string::npos) << refusal();
  ros::param::del(ns);
}


// Every node setting of FusionConfig's table (core/fusion_settings.h) is in cfg/Fusion.cfg as it
// is declared there: name, type, default, range and description; and the cfg has no other
// FusionConfig setting (the rest of the cfg is the occupancy_ ones).
TEST(SettingsTable, TheFusionCfgIsTheFusionSettingsTable) {
  const dynamic_reconfigure::ConfigDescription cfg = unsup_mvs::FusionConfig::__getDescriptionMessage__();
  const auto value_in = [](const dynamic_reconfigure::Config& c, const std::string& name) {
    for (const auto& p : c.ints) {
      if (p.name == name) return static_cast<double>(p.value);
    }
    for (const auto& p : c.doubles) {
      if (p.name == name) return p.value;
    }
    return std::numeric_limits<double>::quiet_NaN();
  };
  std::map<std::string, dynamic_reconfigure::ParamDescription> in_cfg;
  for (const auto& group : cfg.groups) {
    for (const auto& p : group.parameters) {
      if (p.name.rfind("occupancy_", 0) != 0) in_cfg[p.name] = p;
    }
  }
  std::set<std::string> on_node;
  for (const auto& s : umvs::fusion_settings()) {
    if (!s.on_node) {
      EXPECT_EQ(in_cfg.count(s.name), 0u) << s.name << " is a `umvs` option only";
      continue;
    }
    on_node.insert(s.name);
    ASSERT_EQ(in_cfg.count(s.name), 1u) << s.name << " is not in cfg/Fusion.cfg";
    const auto& p = in_cfg[s.name];
    EXPECT_EQ(p.type, s.is_integer() ? "int" : "double") << s.name;
    EXPECT_EQ(p.description, s.help) << s.name;
    EXPECT_DOUBLE_EQ(value_in(cfg.dflt, s.name), s.value(umvs::FusionConfig{})) << s.name;
    EXPECT_DOUBLE_EQ(value_in(cfg.min, s.name), s.min) << s.name;
    EXPECT_DOUBLE_EQ(value_in(cfg.max, s.name), s.max) << s.name;
  }
  std::set<std::string> cfg_names;
  for (const auto& [name, p] : in_cfg) cfg_names.insert(name);
  EXPECT_EQ(cfg_names, on_node);
}

// The node reads each of them by its name, and a live change reaches each field.
TEST(SettingsTable, TheFusionNodeTakesEverySettingByItsName) {
  const std::string ns = "/settings_cases/fusion";
  umvs::FusionConfig changed;
  for (const auto& s : umvs::fusion_settings()) {
    if (!s.on_node) continue;
    const double value = s.is_integer() ? s.value(changed) + 1 : (s.value(changed) + s.max) / 2;
    s.visit(changed, [&](auto& field) { field = value; });
    if (s.is_integer()) ros::param::set(ns + "/" + s.name, static_cast<int>(value));
    else ros::param::set(ns + "/" + s.name, value);
  }
  const umvs::FusionConfig read = umvs_ros::fusion_node_config_from_ros(ros::NodeHandle(ns)).fusion;
  umvs_ros::FusionNodeConfig live_changed;
  live_changed.fusion = changed;
  const umvs::FusionConfig live =
      umvs_ros::with_reconfigure(umvs_ros::FusionNodeConfig{}, umvs_ros::to_reconfigure(live_changed)).fusion;
  for (const auto& s : umvs::fusion_settings()) {
    if (!s.on_node) continue;
    EXPECT_NE(s.value(changed), s.value(umvs::FusionConfig{})) << s.name;
    EXPECT_DOUBLE_EQ(s.value(read), s.value(changed)) << s.name << " (rosparam)";
    EXPECT_DOUBLE_EQ(s.value(live), s.value(changed)) << s.name << " (dynamic_reconfigure)";
  }
  ros::param::del(ns);
}

}  // namespace

// One default per setting: the cfg's defaults, as the generated config reports them, against the
// config structs' defaults mapped by the nodes' own live_settings.
template <typename Generated>
std::string cfg_differences(const Generated& from_structs) {
  dynamic_reconfigure::Config cfg, structs;
  Generated::__getDefault__().__toMessage__(cfg);
  from_structs.__toMessage__(structs);
  return umvs_ros::describe_changes(cfg, structs);
}

TEST(LiveSettings, TheCfgDefaultsAreTheConfigStructs) {
  EXPECT_EQ(cfg_differences(umvs_ros::to_reconfigure(umvs_ros::FusionNodeConfig{})), "") << "cfg/Fusion.cfg";
  EXPECT_EQ(cfg_differences(umvs_ros::to_reconfigure(umvs_ros::InferenceNodeConfig{})), "") << "cfg/Inference.cfg";
  EXPECT_EQ(cfg_differences(umvs_ros::to_reconfigure(umvs::KeyframeStreamConfig{})), "") << "cfg/KeyframeSelector.cfg";
  // The comparison sees a difference when there is one.
  auto fusion = umvs_ros::FusionNodeConfig{};
  fusion.fusion.clear_after_views += 1;
  EXPECT_NE(cfg_differences(umvs_ros::to_reconfigure(fusion)).find("clear_after_views"), std::string::npos);
}
