// Self-training on a robot's unlabelled images (core/training.h pseudo_labelled_tuples,
// reference_depths, seen_by_loss_views): the pseudo-labels and their anchors (`umvs train
// --self-training-every` itself: test_self_training_runs.cpp).
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <stdexcept>
#include <vector>

#include "training_test_fixtures.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/training_data.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {
namespace {

using test::default_model;
using test::room_tuples;
using test::write_room;

// Every tuple of a rendered room without ground truth (4 loss views, unaugmented), as self-training
// sees a robot's unlabelled images.
std::vector<TrainingTuple> unlabelled_room_tuples(const std::string& name, int seed) {
  const std::string dir = write_room(name, seed, false);
  TupleConfig cfg = room_tuples(4);
  cfg.read_ground_truth = false;
  return fixed_tuples(MvsFolderSource({dir}, cfg), 0);
}

TEST(SelfTraining, PseudoLabelsAreTheAccuratePixels) {
  // The pixels the views agree on are far more accurate than the model's depth elsewhere: that is
  // what makes them labels. Scored against the rendered ground truth (which labelling never reads).
  const std::string dir = write_room("pseudo_accuracy", 41, true);
  TupleConfig cfg = room_tuples(4);
  MvsFolderSource with_gt({dir}, cfg);
  cfg.read_ground_truth = false;
  MvsFolderSource blind({dir}, cfg);
  auto model = load_model(default_model(), torch::kCPU).model;
  std::vector<TrainingTuple> tuples;
  for (size_t i = 0; i < blind.size(); ++i) {
    tuples.push_back(blind.tuple(i, nullptr));
    ASSERT_FALSE(tuples.back().depth_gt.defined()) << "read_ground_truth = false still read depth_gt/";
  }
  ConsistencyScore score;
  FusionConfig rule;  // umvs train's self-training defaults
  rule.min_confidence = 0.5;
  rule.max_relative_depth = 0.03;
  rule.min_agreeing_views = 2;
  const auto labelled = pseudo_labelled_tuples(model, tuples, 32, rule, torch::kCPU, &score);
  ASSERT_EQ(labelled.size(), tuples.size());
  EXPECT_GT(score.confirmed_fraction, 0.02);
  EXPECT_LT(score.confirmed_fraction, 0.95);
  std::vector<torch::Tensor> label, truth_at_label;
  for (size_t i = 0; i < labelled.size(); ++i) {
    ASSERT_TRUE(labelled[i].supervised);
    const auto gt = with_gt.tuple(i, nullptr).depth_gt;
    const auto mask = (labelled[i].depth_gt > 0) & (gt > 0);
    label.push_back(labelled[i].depth_gt.masked_select(mask));
    truth_at_label.push_back(gt.masked_select(mask));
  }
  const auto l = torch::cat(label), g = torch::cat(truth_at_label);
  ASSERT_GT(l.numel(), 100);
  const double label_abs_rel = ((l - g).abs() / g).mean().item<double>();
  // The model's own depth on the pixels left unlabelled (those self-training leaves to the
  // photometric loss), on the same depth grid.
  std::vector<torch::Tensor> est_elsewhere, truth_elsewhere;
  torch::NoGradGuard no_grad;
  for (size_t i = 0; i < labelled.size(); ++i) {
    const auto truth = make_training_batch({with_gt.tuple(i, nullptr)}, 32, model->config().depth_sampling, torch::kCPU);
    const auto labels = make_training_batch({labelled[i]}, 32, model->config().depth_sampling, torch::kCPU).depth_gt;
    const auto depth = model->forward(truth.images, truth.proj, truth.depth_values).depth;
    const auto elsewhere = (labels <= 0) & (truth.depth_gt > 0);
    est_elsewhere.push_back(depth.masked_select(elsewhere));
    truth_elsewhere.push_back(truth.depth_gt.masked_select(elsewhere));
  }
  const auto e = torch::cat(est_elsewhere), t = torch::cat(truth_elsewhere);
  ASSERT_GT(e.numel(), 100);
  const double elsewhere_abs_rel = ((e - t).abs() / t).mean().item<double>();
  std::cout << "[self-training] labels abs rel " << label_abs_rel << " on " << l.numel() << " pixels, the model elsewhere "
            << elsewhere_abs_rel << " on " << e.numel() << "\n";
  EXPECT_LT(label_abs_rel, 0.5 * elsewhere_abs_rel)
      << "labels abs rel " << label_abs_rel << " vs the model elsewhere " << elsewhere_abs_rel;
}

TEST(SelfTraining, AnchoredLabelsKeepTheStartDepthWhereNoViewConfirms) {
  // With the start model's depth maps, every depth-grid pixel gets a label: the confirmed depth
  // where views agree (the same labels as without), the start depth everywhere else.
  const auto tuples = unlabelled_room_tuples("anchored_labels", 42);
  auto model = load_model(default_model(), torch::kCPU).model;
  FusionConfig rule;
  rule.min_confidence = 0.5;
  rule.max_relative_depth = 0.03;
  rule.min_agreeing_views = 2;
  const auto start = reference_depths(model, tuples, 32, torch::kCPU);
  ASSERT_EQ(start.size(), tuples.size());
  const auto plain = pseudo_labelled_tuples(model, tuples, 32, rule, torch::kCPU);
  const auto anchored = pseudo_labelled_tuples(model, tuples, 32, rule, torch::kCPU, nullptr, &start);
  ASSERT_EQ(anchored.size(), tuples.size());
  int64_t confirmed = 0, unconfirmed = 0;
  for (size_t i = 0; i < tuples.size(); ++i) {
    const auto grid = [](const torch::Tensor& full) { return full.slice(0, 0, full.size(0), 4).slice(1, 0, full.size(1), 4); };
    const auto p = grid(plain[i].depth_gt), a = grid(anchored[i].depth_gt);
    ASSERT_EQ(a.sizes(), start[i].sizes());
    const auto is_confirmed = p > 0;
    EXPECT_TRUE(torch::equal(a.masked_select(is_confirmed), p.masked_select(is_confirmed))) << tuples[i].name;
    EXPECT_TRUE(torch::equal(a.masked_select(~is_confirmed), start[i].masked_select(~is_confirmed))) << tuples[i].name;
    EXPECT_TRUE((a > 0).all().item<bool>()) << "an anchored label map has no hole";
    // Off the depth grid nothing is labelled, as without anchors.
    EXPECT_EQ(anchored[i].depth_gt.gt(0).sum().item<int64_t>(), a.numel());
    confirmed += is_confirmed.sum().item<int64_t>();
    unconfirmed += (~is_confirmed).sum().item<int64_t>();
  }
  EXPECT_GT(confirmed, 100);  // both kinds of pixel were checked
  EXPECT_GT(unconfirmed, 100);
  // One map per tuple, of the reference's depth size.
  std::vector<torch::Tensor> short_list(start.begin(), start.end() - 1);
  EXPECT_THROW(pseudo_labelled_tuples(model, tuples, 32, rule, torch::kCPU, nullptr, &short_list), std::invalid_argument);
  std::vector<torch::Tensor> wrong_size = start;
  wrong_size[0] = torch::ones({3, 3});
  EXPECT_THROW(pseudo_labelled_tuples(model, tuples, 32, rule, torch::kCPU, nullptr, &wrong_size), std::invalid_argument);
}

TEST(SelfTraining, AnchorsCanBeLimitedToConfidentPixels) {
  // reference_depths with a confidence floor keeps the same depth where the model is confident
  // enough and 0 (no label) elsewhere; a higher floor keeps fewer pixels.
  const auto tuples = unlabelled_room_tuples("anchored_confident", 43);
  auto model = load_model(default_model(), torch::kCPU).model;
  const auto all = reference_depths(model, tuples, 32, torch::kCPU);
  int64_t previous_kept = -1;
  for (const double floor : {0.0, 0.3, 0.6, 0.9}) {
    const auto kept = reference_depths(model, tuples, 32, torch::kCPU, floor);
    int64_t n = 0;
    for (size_t i = 0; i < tuples.size(); ++i) {
      const auto has = kept[i].gt(0);
      EXPECT_TRUE(torch::equal(kept[i].masked_select(has), all[i].masked_select(has))) << tuples[i].name;
      n += has.sum().item<int64_t>();
    }
    if (floor == 0.0) {
      int64_t every = 0;
      for (const auto& d : all) every += d.numel();
      EXPECT_EQ(n, every) << "no floor keeps every pixel";
    } else {
      EXPECT_LE(n, previous_kept) << floor;
    }
    if (floor == 0.9) {
      int64_t every = 0;
      for (const auto& d : all) every += d.numel();
      EXPECT_LT(n, every) << "a 0.9 floor drops the unconfident pixels";
      EXPECT_GT(n, 0) << "and keeps the confident ones";
    }
    previous_kept = n;
  }
}

TEST(SelfTraining, SeenByLossViewsIsWhereThePhotometricLossCompares) {
  // The pixels seen_by_loss_views marks are exactly those the loss's inverse warp finds valid in
  // at least one loss view (at the same depth).
  auto tuples = unlabelled_room_tuples("seen_by_loss_views", 44);
  auto model = load_model(default_model(), torch::kCPU).model;
  const auto depth = reference_depths(model, tuples, 32, torch::kCPU);
  // A tuple whose loss views are its reference with the principal point moved half a width: the
  // right half of the reference falls outside each of them.
  TrainingTuple shifted = tuples[0];
  for (auto& v : shifted.loss_views) {
    v = shifted.network_views[0];
    v.camera.K(0, 2) += v.camera.width / 2.0;
  }
  tuples.push_back(shifted);
  std::vector<torch::Tensor> depths = depth;
  depths.push_back(depth[0]);
  int64_t seen_total = 0, unseen_total = 0;
  for (size_t i = 0; i < tuples.size(); ++i) {
    const auto seen = seen_by_loss_views(tuples[i], depths[i]);
    const auto batch = make_training_batch({tuples[i]}, 32, DepthSampling::kUniformDepth, torch::kCPU);
    auto valid = torch::zeros_like(seen);
    for (int64_t m = 0; m < batch.loss_src.size(1); ++m) {
      const auto w = inverse_warp(batch.loss_src.select(1, m), batch.K_ref, batch.K_src.select(1, m),
                                  batch.T_src_ref.select(1, m), depths[i].unsqueeze(0));
      valid |= w.valid[0][0] > 0.5;
    }
    EXPECT_TRUE(torch::equal(seen, valid)) << tuples[i].name << ": " << seen.sum().item<int64_t>() << " seen against "
                                           << valid.sum().item<int64_t>() << " valid";
    seen_total += seen.sum().item<int64_t>();
    unseen_total += (~seen).sum().item<int64_t>();
  }
  const auto half = seen_by_loss_views(shifted, depth[0]);
  // Away from the image's edges, where float rounding decides.
  const int64_t h = half.size(0), w = half.size(1);
  EXPECT_TRUE(half.slice(0, 1, h - 1).slice(1, 0, w / 2 - 1).all().item<bool>()) << "the left half is seen";
  EXPECT_FALSE(half.slice(1, w / 2 + 1, w).any().item<bool>()) << "the right half is not";
  EXPECT_GT(seen_total, 100);
  EXPECT_GT(unseen_total, 100);
  EXPECT_THROW(seen_by_loss_views(tuples[0], torch::ones({3, 3})), std::invalid_argument);
}

TEST(SelfTraining, AnchorsCanAddThePixelsNoLossViewSees) {
  // With keep_unseen, the floor's anchors plus every pixel no loss view sees keep the start depth.
  auto tuples = unlabelled_room_tuples("anchored_unseen", 45);
  TrainingTuple shifted = tuples[0];  // half of its reference outside its loss views, as above
  for (auto& v : shifted.loss_views) {
    v = shifted.network_views[0];
    v.camera.K(0, 2) += v.camera.width / 2.0;
  }
  tuples.push_back(shifted);
  auto model = load_model(default_model(), torch::kCPU).model;
  const auto all = reference_depths(model, tuples, 32, torch::kCPU);
  const auto confident = reference_depths(model, tuples, 32, torch::kCPU, 0.9);
  const auto with_unseen = reference_depths(model, tuples, 32, torch::kCPU, 0.9, true);
  int64_t added = 0;
  for (size_t i = 0; i < tuples.size(); ++i) {
    const auto expected = confident[i].gt(0) | seen_by_loss_views(tuples[i], all[i]).logical_not();
    EXPECT_TRUE(torch::equal(with_unseen[i].gt(0), expected)) << tuples[i].name;
    EXPECT_TRUE(torch::equal(with_unseen[i].masked_select(expected), all[i].masked_select(expected))) << tuples[i].name;
    added += (with_unseen[i].gt(0) & confident[i].eq(0)).sum().item<int64_t>();
  }
  EXPECT_GT(added, 100) << "the unconfident pixels outside the loss views are anchored too";
  // Without a floor every pixel is anchored anyway.
  const auto every = reference_depths(model, tuples, 32, torch::kCPU, 0.0, true);
  for (size_t i = 0; i < tuples.size(); ++i) EXPECT_TRUE(torch::equal(every[i], all[i]));
}

}  // namespace
}  // namespace umvs
