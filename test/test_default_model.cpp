// The shipped model (models/unsup_mvsnet.pt) on rendered rooms: the adaptation judge's evidence,
// depth blind to exposure, the source combinations (most_confident, auto) against a source that
// sees something else, self-training labels from each source alone, and depth completion.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <stdexcept>
#include <string>
#include <vector>

#include "training_test_fixtures.h"
#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/training_data.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {
namespace {

using test::abs_rel_on_depth_grid;
using test::default_model;
using test::room_tuples;
using test::write_room;

TEST(AdaptationJudge, FindsEvidenceOnSparseViewsAndRanksWorseDepthLower) {
  // Each reference is checked against only two other views, as with a robot's far-apart
  // keyframes. The judge still confirms a share of the trained model's depth above the trainer
  // node's 1 % evidence floor, and far less of the depth of the same network untrained.
  const std::string dir = write_room("judge_sparse", 43, false);
  TupleConfig cfg = room_tuples(2);
  const auto tuples = fixed_tuples(MvsFolderSource({dir}, cfg), 0);  // all, unaugmented
  auto trained = load_model(default_model(), torch::kCPU).model;
  torch::manual_seed(1);
  MvsNet untrained(trained->config());
  const FusionConfig judge = adaptation_judge_rule();
  const double trained_share = depth_consistency(trained, tuples, 32, judge, torch::kCPU).confirmed_fraction;
  const double untrained_share = depth_consistency(untrained, tuples, 32, judge, torch::kCPU).confirmed_fraction;
  RecordProperty("trained_share", std::to_string(trained_share));
  RecordProperty("untrained_share", std::to_string(untrained_share));
  EXPECT_GT(trained_share, 0.01);
  EXPECT_GT(trained_share, 3 * untrained_share) << "untrained " << untrained_share;
}

TEST(DefaultModel, DepthIgnoresExposure) {
  // A camera recording everything at 0.3x brightness (quantised to 8 bits like a real dark
  // camera) gets the same depth from the shipped model: median change < 1 %.
  const std::string dir = write_room("exposure_default_model", 61, true);
  TupleConfig cfg = room_tuples(2);
  MvsFolderSource source({dir}, cfg);
  auto loaded = load_model(default_model(), torch::kCPU);
  DepthEstimator estimator(loaded.model, torch::kCPU);
  std::vector<double> changes;
  for (size_t i = 0; i < source.size(); i += 2) {
    const auto t = source.tuple(i, nullptr);
    std::vector<ViewInput> bright = t.network_views, dark = t.network_views;
    for (auto& v : dark) v.image = (v.image.to(torch::kFloat32) * 0.3).round().to(torch::kUInt8);
    const auto a = estimator.estimate(bright, t.depth_min, t.depth_max).depth;
    const auto b = estimator.estimate(dark, t.depth_min, t.depth_max).depth;
    changes.push_back(((a - b).abs() / a).median().item<double>());
  }
  std::sort(changes.begin(), changes.end());
  EXPECT_LT(changes[changes.size() / 2], 0.01) << "median of per-view median relative changes";
  EXPECT_LT(changes.back(), 0.02) << "worst view";
}

TEST(DefaultModel, MostConfidentSourcesResistASourceThatSeesSomethingElse) {
  // The second source's image is mirrored, as if its camera saw another scene: in MVSNet's
  // variance it spoils the depth (abs rel summed over 3 references 0.649, against 0.506 for the
  // reference with the first source alone). With SourceCombination::kMostConfident the pass of
  // the reference and the first source wins where it is more confident: 0.517.
  const std::string dir = write_room("most_confident_sources", 71, true);
  TupleConfig cfg = room_tuples(2);
  MvsFolderSource source({dir}, cfg);
  auto loaded = load_model(default_model(), torch::kCPU);
  DepthEstimator variance(loaded.model, torch::kCPU);
  DepthEstimatorConfig most_confident_config;
  most_confident_config.source_combination = SourceCombination::kMostConfident;
  DepthEstimator most_confident(loaded.model, torch::kCPU, most_confident_config);
  const auto abs_rel = abs_rel_on_depth_grid;
  double spoiled_variance = 0, spoiled_most_confident = 0, clean_pair = 0;
  for (size_t i = 0; i < source.size(); i += 2) {
    const auto t = source.tuple(i, nullptr);
    ASSERT_EQ(t.network_views.size(), 3u);
    std::vector<ViewInput> spoiled = t.network_views;
    spoiled[2].image = spoiled[2].image.flip({1}).contiguous();
    const std::vector<ViewInput> pair(t.network_views.begin(), t.network_views.begin() + 2);
    const DepthMap a = variance.estimate(spoiled, t.depth_min, t.depth_max);
    const DepthMap b = most_confident.estimate(spoiled, t.depth_min, t.depth_max);
    EXPECT_TRUE((b.confidence >= a.confidence).all().item<bool>()) << "the variance pass is one of the candidates";
    spoiled_variance += abs_rel(a.depth, t.depth_gt);
    spoiled_most_confident += abs_rel(b.depth, t.depth_gt);
    clean_pair += abs_rel(variance.estimate(pair, t.depth_min, t.depth_max).depth, t.depth_gt);
  }
  RecordProperty("spoiled_variance", std::to_string(spoiled_variance));
  RecordProperty("spoiled_most_confident", std::to_string(spoiled_most_confident));
  RecordProperty("clean_pair", std::to_string(clean_pair));
  EXPECT_LT(spoiled_most_confident, 0.9 * spoiled_variance) << "clean pair " << clean_pair;
  EXPECT_LT(spoiled_most_confident, 1.1 * clean_pair) << "spoiled variance " << spoiled_variance;
  EXPECT_THROW(source_combination_from_string("bogus"), std::invalid_argument);
  EXPECT_EQ(source_combination_from_string(to_string(SourceCombination::kMostConfident)), SourceCombination::kMostConfident);
}

TEST(DefaultModel, AutoSourcesAddThePerSourcePassesOnlyWhereTheVarianceIsUnsure) {
  // SourceCombination::kAuto keeps the one variance pass where it is confident, byte for byte, and
  // where a source's image is noise (a camera that sees nothing of the reference's scene) the
  // variance pass is unsure of most of the map, so auto runs most_confident's passes as well and
  // its depth is most_confident's, better than the spoiled variance's.
  const std::string dir = write_room("auto_sources", 73, true);
  MvsFolderSource source({dir}, room_tuples(2));
  auto loaded = load_model(default_model(), torch::kCPU);
  const auto estimator = [&](SourceCombination combination) {
    DepthEstimatorConfig config;
    config.source_combination = combination;
    return DepthEstimator(loaded.model, torch::kCPU, config);
  };
  DepthEstimator variance = estimator(SourceCombination::kVariance);
  DepthEstimator most_confident = estimator(SourceCombination::kMostConfident);
  DepthEstimator automatic = estimator(SourceCombination::kAuto);
  const auto confident_share = [](const DepthMap& m) {
    return (m.confidence >= kAutoConfidentLevel).to(torch::kFloat32).mean().item<double>();
  };
  double spoiled_variance = 0, spoiled_auto = 0, least_clean_share = 1, most_spoiled_share = 0;
  for (size_t i = 0; i < source.size(); i += 2) {
    const auto t = source.tuple(i, nullptr);
    ASSERT_EQ(t.network_views.size(), 3u);
    const DepthMap clean = variance.estimate(t.network_views, t.depth_min, t.depth_max);
    least_clean_share = std::min(least_clean_share, confident_share(clean));
    const DepthMap clean_auto = automatic.estimate(t.network_views, t.depth_min, t.depth_max);
    ASSERT_GE(confident_share(clean), kAutoMinConfidentShare) << "reference " << i;
    EXPECT_FALSE(clean.per_source_passes);
    EXPECT_FALSE(clean_auto.per_source_passes) << "reference " << i;
    EXPECT_TRUE(torch::equal(clean_auto.depth, clean.depth)) << "reference " << i;

    std::vector<ViewInput> spoiled = t.network_views;
    torch::manual_seed(static_cast<uint64_t>(i));
    spoiled[2].image = torch::randint(0, 256, spoiled[2].image.sizes(), torch::kUInt8);
    const DepthMap a = variance.estimate(spoiled, t.depth_min, t.depth_max);
    const DepthMap b = automatic.estimate(spoiled, t.depth_min, t.depth_max);
    most_spoiled_share = std::max(most_spoiled_share, confident_share(a));
    ASSERT_LT(confident_share(a), kAutoMinConfidentShare) << "reference " << i;
    EXPECT_TRUE(b.per_source_passes) << "reference " << i;
    EXPECT_TRUE(torch::equal(b.depth, most_confident.estimate(spoiled, t.depth_min, t.depth_max).depth));
    spoiled_variance += abs_rel_on_depth_grid(a.depth, t.depth_gt);
    spoiled_auto += abs_rel_on_depth_grid(b.depth, t.depth_gt);
  }
  RecordProperty("spoiled_variance", std::to_string(spoiled_variance));
  RecordProperty("spoiled_auto", std::to_string(spoiled_auto));
  RecordProperty("least_clean_confident_share", std::to_string(least_clean_share));
  RecordProperty("most_spoiled_confident_share", std::to_string(most_spoiled_share));
  EXPECT_LT(spoiled_auto, 0.8 * spoiled_variance);
  EXPECT_EQ(source_combination_from_string(to_string(SourceCombination::kAuto)), SourceCombination::kAuto);
}

TEST(DefaultModel, SelfTrainingLabelsFromEachSourceAloneSurviveASourceThatSeesNothing) {
  // One view of every tuple is noise (a camera that sees nothing of the scene). Self-training
  // labels made with SourceCombination::kMostConfident (`umvs train --source-combination
  // most_confident`) keep the pass of each reference with its good view alone, so other views
  // confirm twice as much of the reference's depth as with the variance pass over all views
  // (5.3 % against 2.4 %), and the labels are as accurate (abs rel 0.039 both); the consistency
  // judge scores it the same way.
  const std::string dir = write_room("label_sources", 75, true);
  MvsFolderSource source({dir}, room_tuples(2));
  auto model = load_model(default_model(), torch::kCPU).model;
  std::vector<TrainingTuple> tuples;
  for (size_t i = 0; i < source.size(); i += 2) {
    TrainingTuple t = source.tuple(i, nullptr);
    ASSERT_EQ(t.network_views.size(), 3u);
    torch::manual_seed(static_cast<uint64_t>(i));
    t.network_views[2].image = torch::randint(0, 256, t.network_views[2].image.sizes(), torch::kUInt8);
    tuples.push_back(std::move(t));
  }
  FusionConfig rule;  // umvs train's self-training defaults
  rule.min_confidence = 0.5;
  rule.max_relative_depth = 0.03;
  rule.min_agreeing_views = 2;
  const auto labels = [&](SourceCombination sources, ConsistencyScore* score) {
    const auto labelled = pseudo_labelled_tuples(model, tuples, 32, rule, torch::kCPU, score, nullptr, sources);
    std::vector<torch::Tensor> errors;
    for (size_t i = 0; i < labelled.size(); ++i) {
      const auto mask = (labelled[i].depth_gt > 0) & (tuples[i].depth_gt > 0);
      const auto truth = tuples[i].depth_gt.masked_select(mask);
      errors.push_back((labelled[i].depth_gt.masked_select(mask) - truth).abs() / truth);
    }
    return torch::cat(errors);
  };
  ConsistencyScore variance_score, most_confident_score;
  const auto variance_errors = labels(SourceCombination::kVariance, &variance_score);
  const auto most_confident_errors = labels(SourceCombination::kMostConfident, &most_confident_score);
  RecordProperty("variance_confirmed", std::to_string(variance_score.confirmed_fraction));
  RecordProperty("most_confident_confirmed", std::to_string(most_confident_score.confirmed_fraction));
  ASSERT_GT(most_confident_errors.numel(), 100);
  const double variance_abs_rel = variance_errors.numel() ? variance_errors.mean().item<double>() : 1.0;
  const double most_confident_abs_rel = most_confident_errors.mean().item<double>();
  RecordProperty("variance_label_abs_rel", std::to_string(variance_abs_rel));
  RecordProperty("most_confident_label_abs_rel", std::to_string(most_confident_abs_rel));
  EXPECT_GT(most_confident_score.confirmed_fraction, 1.5 * variance_score.confirmed_fraction);
  EXPECT_LT(most_confident_abs_rel, 1.1 * variance_abs_rel);
  const FusionConfig judge = adaptation_judge_rule();
  EXPECT_GT(depth_consistency(model, tuples, 32, judge, torch::kCPU, SourceCombination::kMostConfident).confirmed_fraction,
            depth_consistency(model, tuples, 32, judge, torch::kCPU).confirmed_fraction);
}

TEST(DefaultModel, CompletionLowersTheErrorWhereTheNetworkIsUnsure) {
  // The shipped model on a rendered room at its own size (640x512): completing the pixels below
  // confidence 0.7 from the confident ones lowers the depth error (as on every rendered scene
  // and on the living room, docs/results.md) and leaves the confidence map as the network gave
  // it. (At 128x96 the maps are 32x24 and completion barely changes the error.)
  const std::string dir = write_room("completion_default_model", 81, true, 640, 512);
  MvsFolderSource source({dir}, room_tuples(2, 640, 512));
  auto loaded = load_model(default_model(), torch::kCPU);
  DepthEstimator plain(loaded.model, torch::kCPU);
  DepthEstimatorConfig completing_config;
  completing_config.completion.min_confidence = 0.7;
  DepthEstimator completing(loaded.model, torch::kCPU, completing_config);
  double plain_error = 0, completed_error = 0, completed_share = 0;
  int maps = 0;
  for (size_t i = 0; i < source.size(); i += 2, ++maps) {
    const auto t = source.tuple(i, nullptr);
    const DepthMap a = plain.estimate(t.network_views, t.depth_min, t.depth_max);
    const DepthMap b = completing.estimate(t.network_views, t.depth_min, t.depth_max);
    EXPECT_TRUE(torch::equal(a.confidence, b.confidence));
    EXPECT_EQ(a.depth.sizes(), b.depth.sizes());
    plain_error += abs_rel_on_depth_grid(a.depth, t.depth_gt);
    completed_error += abs_rel_on_depth_grid(b.depth, t.depth_gt);
    completed_share += b.completion.completed_share;
  }
  RecordProperty("plain_abs_rel", std::to_string(plain_error / maps));
  RecordProperty("completed_abs_rel", std::to_string(completed_error / maps));
  RecordProperty("completed_share", std::to_string(completed_share / maps));
  EXPECT_GT(completed_share / maps, 0.05) << "the network is unsure somewhere";
  EXPECT_LT(completed_error, 0.95 * plain_error);
}

}  // namespace
}  // namespace umvs
