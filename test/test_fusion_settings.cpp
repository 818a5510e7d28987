// Settings declared once (core/settings.h): FusionConfig's table drives `umvs fuse`'s options
// (earlier spellings still taken, with a note) and docs/fusion.md's reference table. The ROS side
// (node parameters, the dynamic_reconfigure cfg): test/ros/test_settings.cpp.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/core/fusion_settings.h"

namespace umvs {
namespace {

using test::contains;
using test::Result;
using test::run_umvs;

// The text between `<!-- settings: NAME -->` and `<!-- end settings -->` in a docs page.
std::string docs_block(const std::string& page, const std::string& name) {
  std::ifstream in(std::string(UMVS_SOURCE_DIR) + "/" + page);
  std::stringstream text;
  text << in.rdbuf();
  const std::string all = text.str(), begin = "<!-- settings: " + name + " -->\n", end = "<!-- end settings -->";
  const size_t from = all.find(begin), to = all.find(end, from == std::string::npos ? 0 : from);
  if (from == std::string::npos || to == std::string::npos) return "(no settings block " + name + " in " + page + ")";
  return all.substr(from + begin.size(), to - from - begin.size());
}

TEST(FusionSettings, EachFieldOnceWithItsOwnNameAndAValidDefault) {
  const auto& settings = fusion_settings();
  ASSERT_EQ(settings.size(), 8u);
  std::set<std::string> names;
  for (const auto& s : settings) {
    EXPECT_TRUE(names.insert(s.name).second) << s.name << " twice";
    EXPECT_EQ(s.option().find('_'), std::string::npos) << s.option();
    EXPECT_FALSE(s.help.empty()) << s.name;
    EXPECT_LE(s.min, s.value(FusionConfig{})) << s.name;
    EXPECT_GE(s.max, s.value(FusionConfig{})) << s.name;
  }
  EXPECT_EQ(settings[3].option(), "min-agreeing-views");
  EXPECT_TRUE(settings[3].is_integer());
  FusionConfig c;
  settings[3].visit(c, [](auto& field) { field = 7; });
  EXPECT_EQ(c.min_agreeing_views, 7);
}

TEST(FusionSettings, TheDocsTableIsMadeFromTheTable) {
  EXPECT_EQ(docs_block("docs/fusion.md", "fusion"), settings_table(fusion_settings(), "fuse"))
      << "docs/fusion.md's table is out of date; the block between its settings markers should read:\n"
      << settings_table(fusion_settings(), "fuse");
}

TEST(FusionSettings, UmvsFuseShowsEachSettingWithItsDefault) {
  const Result help = run_umvs("fuse --help");
  ASSERT_EQ(help.status, 0) << help.output;
  for (const auto& s : fusion_settings()) {
    const std::string shown = "--" + s.option() + (s.is_integer() ? " INT=" : " NUMBER=") + setting_text(s.value(FusionConfig{}));
    EXPECT_TRUE(contains(help.output, shown)) << shown << " not in:\n" << help.output;
  }
}

// The number of points `umvs fuse` reports ("fused N views into M points").
long fused_points(const std::string& output) {
  std::smatch m;
  return std::regex_search(output, m, std::regex("into (\\d+) points")) ? std::stol(m[1]) : -1;
}

TEST(FusionSettings, UmvsFuseTakesTheOldSpellingsWithADeprecationNote) {
  const std::string data = test::scene("settings_fuse_data");
  const std::string dir = test::temp_dir("settings_fuse");
  const std::string base = "fuse --depth " + data + "/depth_gt --data " + data + " --min-confidence 0 --threads 1 --out " + dir;
  const Result strict = run_umvs(base + "/a.ply --min-agreeing-views 3 --voxel-size 0.05", "2>&1");
  const Result old = run_umvs(base + "/b.ply --min-views 3 --voxel=0.05", "2>&1");
  const Result loose = run_umvs(base + "/c.ply --min-agreeing-views 1 --voxel-size 0.05", "2>&1");
  ASSERT_EQ(strict.status, 0) << strict.output;
  ASSERT_EQ(old.status, 0) << old.output;
  ASSERT_EQ(loose.status, 0) << loose.output;
  EXPECT_FALSE(contains(strict.output, "deprecated")) << strict.output;
  EXPECT_TRUE(contains(old.output, "--min-views is deprecated and will be removed in the next release; use --min-agreeing-views"))
      << old.output;
  EXPECT_TRUE(contains(old.output, "--voxel is deprecated")) << old.output;
  EXPECT_GT(fused_points(strict.output), 0) << strict.output;
  EXPECT_EQ(fused_points(old.output), fused_points(strict.output));  // the same settings, by either name
  EXPECT_GT(fused_points(loose.output), fused_points(strict.output));  // and they take effect
}

}  // namespace
}  // namespace umvs
