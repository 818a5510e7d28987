// Training tuples (io/training_data.h) from synthetic scenes with exact depth (core/synth.h)
// written as MVSNet folders: crops keep the geometry, zoom works at the images' own pixel scale,
// and views without their neighbours are counted. `umvs train` and jobs/training_run.h: test_train_command.cpp.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <random>
#include <stdexcept>
#include <vector>

#include "training_test_fixtures.h"
#include "unsup_mvs/core/losses.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/loss_curve.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/io/training_data.h"

namespace umvs {
namespace {

using test::run;
using test::write_scene;

TEST(TrainingData, CroppedTuplesKeepGeometryConsistent) {
  // With random zoom/crop (intrinsics and ground truth follow), the loss on the depth grid at the
  // ground-truth depth is clearly below the loss at a wrong depth: images, cameras and depth agree.
  const std::string dir = write_scene("tuples", 192, 160, 6);
  TupleConfig cfg;
  cfg.views_in = 3;
  cfg.views_loss = 4;
  cfg.width = 128;
  cfg.height = 96;
  cfg.jitter = 0.1;
  MvsFolderSource source({dir}, cfg);
  ASSERT_EQ(source.size(), 6u);
  EXPECT_TRUE(source.has_ground_truth());
  std::mt19937_64 rng(3);
  for (int i = 0; i < 3; ++i) {
    const auto t = source.tuple(i, &rng);
    ASSERT_EQ(t.network_views.size(), 3u);
    ASSERT_EQ(t.loss_views.size(), 4u);
    ASSERT_TRUE(t.depth_gt.defined());
    EXPECT_EQ(t.network_views[0].image.size(1), 128);
    const auto b = make_training_batch({t}, 16, DepthSampling::kUniformDepth, torch::kCPU);
    ASSERT_EQ(b.loss_ref.sizes(), (std::vector<int64_t>{1, 3, 24, 32}));
    auto gt = b.depth_gt.clamp_min(0.1);
    LossConfig lc;
    lc.top_k = 2;
    auto at = [&](const torch::Tensor& d) {
      return unsupervised_loss(b.loss_ref, b.loss_src, b.K_ref, b.K_src, b.T_src_ref, d, lc).photometric.item<double>();
    };
    // The true depth is the minimum along the depth axis (the room's fine texture, occlusions and
    // the 1/4-resolution grid keep it above zero).
    const double l_gt = at(gt), l_far = at(gt * 1.15), l_near = at(gt * 0.87);
    EXPECT_LT(l_gt, 0.85 * std::min(l_far, l_near)) << t.name << ": at GT " << l_gt << ", x1.15 " << l_far << ", x0.87 " << l_near;
    // The half-resolution grid of a fine pass agrees as well; its pixel (2i, 2j) is the quarter
    // grid's (i, j), both on input pixel (4i, 4j).
    const auto h = make_training_batch({t}, 16, DepthSampling::kUniformDepth, torch::kCPU, /*map_divisor=*/2);
    ASSERT_EQ(h.loss_ref.sizes(), (std::vector<int64_t>{1, 3, 48, 64}));
    EXPECT_NEAR(h.K_ref[0][0][0].item<double>(), 2 * b.K_ref[0][0][0].item<double>(), 1e-4);
    EXPECT_TRUE(torch::equal(h.depth_gt.slice(1, 0, 48, 2).slice(2, 0, 64, 2), b.depth_gt));
    EXPECT_TRUE(torch::allclose(h.proj_map, mvsnet_projection_matrices({t.network_views[0].camera,
                                                                        t.network_views[1].camera,
                                                                        t.network_views[2].camera}, 0.5)
                                                .unsqueeze(0)));
    const auto gt_half = h.depth_gt.clamp_min(0.1);
    auto at_half = [&](const torch::Tensor& d) {
      return unsupervised_loss(h.loss_ref, h.loss_src, h.K_ref, h.K_src, h.T_src_ref, d, lc).photometric.item<double>();
    };
    const double h_gt = at_half(gt_half), h_far = at_half(gt_half * 1.15), h_near = at_half(gt_half * 0.87);
    EXPECT_LT(h_gt, 0.85 * std::min(h_far, h_near)) << t.name << " at 1/2: at GT " << h_gt << ", x1.15 " << h_far
                                                    << ", x0.87 " << h_near;
  }
  // Deterministic (no rng) tuples are centre crops and repeatable.
  const auto a = source.tuple(2, nullptr), c = source.tuple(2, nullptr);
  EXPECT_TRUE(torch::equal(a.network_views[0].image, c.network_views[0].image));
  TupleConfig bad = cfg;
  bad.views_loss = 9;
  EXPECT_THROW(MvsFolderSource({dir}, bad), std::runtime_error);
  bad = cfg;
  bad.width = 100;
  EXPECT_THROW(MvsFolderSource({dir}, bad), std::invalid_argument);
}

TEST(TrainingData, ZoomRangeCropsAtTheImagesOwnPixelScale) {
  // 256x192 renders trained at 128x96: zoom 1 halves them (focal length x 0.5), zoom 2 crops them
  // at their own scale (focal length x 1, the scale they are used at), zoom 2.5 enlarges them.
  const std::string dir = write_scene("zoom_range", 256, 192, 5);
  const double fx = read_cam_file(dir + "/cams/00000000_cam.txt").camera.K(0, 0);
  TupleConfig cfg;
  cfg.views_in = 3;
  cfg.views_loss = 2;
  cfg.width = 128;
  cfg.height = 96;
  auto focal_ratios = [&](double min_zoom, double max_zoom) {
    cfg.min_zoom = min_zoom;
    cfg.max_zoom = max_zoom;
    MvsFolderSource source({dir}, cfg);
    std::mt19937_64 rng(5);
    std::vector<double> ratios;
    for (int i = 0; i < 20; ++i) {
      const auto t = source.tuple(i % source.size(), &rng);
      EXPECT_EQ(t.network_views[0].image.size(1), 128);
      ratios.push_back(t.network_views[0].camera.K(0, 0) / fx);
    }
    return ratios;
  };
  for (double r : focal_ratios(2.0, 2.0)) EXPECT_NEAR(r, 1.0, 1e-9);
  for (double r : focal_ratios(2.0, 2.5)) {
    EXPECT_GE(r, 1.0 - 0.01);  // (the scaled size is rounded to whole pixels)
    EXPECT_LE(r, 1.25 + 0.01);
  }
  const auto by_default = focal_ratios(1.0, 1.25);
  EXPECT_LE(*std::max_element(by_default.begin(), by_default.end()), 0.625 + 0.01);
  EXPECT_GE(*std::min_element(by_default.begin(), by_default.end()), 0.5 - 0.01);
  cfg.min_zoom = 2.0;
  cfg.max_zoom = 1.5;
  EXPECT_THROW(cfg.validate(), std::invalid_argument);
}

TEST(TrainingData, SkippedViewsAreCountedWithTheNeighboursTheyLack) {
  // A folder where one view has four neighbours and the others two: --views-loss 4 keeps one tuple,
  // and the description says how many were dropped and why.
  const std::string dir = write_scene("skipped", 64, 64, 6);
  auto pairs = read_pair_file(dir + "/pair.txt");
  ASSERT_EQ(pairs.size(), 6u);
  for (size_t i = 0; i < pairs.size(); ++i) {
    ASSERT_GE(pairs[i].sources.size(), 4u);
    const size_t keep = i == 0 ? 4 : 2;
    pairs[i].sources.resize(keep);
    pairs[i].scores.resize(keep);
  }
  write_pair_file(dir + "/pair.txt", pairs);
  TupleConfig cfg;
  cfg.views_in = 3;
  cfg.views_loss = 4;
  cfg.width = 64;
  cfg.height = 64;
  MvsFolderSource source({dir}, cfg);
  EXPECT_EQ(source.size(), 1u);
  EXPECT_NE(source.description().find("1 tuples from 1 folder(s) (5 views skipped: fewer than the 4 neighbours in "
                                      "pair.txt that --views-in 3 and --views-loss 4 need)"),
            std::string::npos)
      << source.description();
  cfg.views_loss = 2;
  EXPECT_EQ(MvsFolderSource({dir}, cfg).size(), 6u);
  EXPECT_EQ(MvsFolderSource({dir}, cfg).description().find("skipped"), std::string::npos);
}

}  // namespace
}  // namespace umvs
