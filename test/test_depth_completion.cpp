#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <limits>

#include "unsup_mvs/core/depth_completion.h"

namespace umvs {
namespace {

constexpr int64_t kH = 40, kW = 56;

// Inverse depth of a tilted plane, affine in the pixel: 1/z = a + b x + c y.
torch::Tensor plane_depth() {
  auto grid = torch::meshgrid({torch::arange(kH, torch::kFloat32), torch::arange(kW, torch::kFloat32)}, "ij");
  return 1.0 / (0.4 + 0.004 * grid[1] - 0.003 * grid[0]);
}

DepthCompletionConfig on(double floor = 0.7) {
  DepthCompletionConfig c;
  c.min_confidence = floor;
  return c;
}

TEST(DepthCompletion, FillsAWallSeenConfidentlyOnlyAtItsEdgesAsThePlaneItIs) {
  // A textureless wall: the network is sure only along a border 3 pixels wide and guessed the
  // rest (here: twice too far). Completion brings the inside back to the plane; the guesses still
  // weigh a thousandth each, which holds the middle of a hole this wide a few per cent towards them.
  const auto truth = plane_depth();
  auto confidence = torch::full({kH, kW}, 0.2f);
  confidence.slice(0, 0, 3).fill_(0.9f);
  confidence.slice(0, kH - 3).fill_(0.9f);
  confidence.slice(1, 0, 3).fill_(0.9f);
  confidence.slice(1, kW - 3).fill_(0.9f);
  const auto guessed = torch::where(confidence > 0.5, truth, 2 * truth);
  const auto guide = torch::full({kH, kW}, 0.5f);
  DepthCompletionStats stats;
  const auto completed = complete_depth(guessed, confidence, guide, on(), &stats);
  const auto error = (completed - truth).abs() / truth;
  RecordProperty("worst", std::to_string(error.max().item<double>()));
  RecordProperty("mean", std::to_string(error.mean().item<double>()));
  EXPECT_LT(error.max().item<double>(), 0.08);
  EXPECT_LT(error.mean().item<double>(), 0.03);
  // Where the guesses were right, the plane comes back but for its outermost pixels, which the
  // smoothness pulls towards their inner neighbours (no neighbour outside balances it).
  const auto kept = (complete_depth(truth, confidence, guide, on()) - truth).abs() / truth;
  const auto inner = kept.slice(0, 2, kH - 2).slice(1, 2, kW - 2);
  RecordProperty("plane_border", std::to_string(kept.max().item<double>()));
  RecordProperty("plane_inner", std::to_string(inner.max().item<double>()));
  EXPECT_LT(kept.max().item<double>(), 0.02);
  EXPECT_LT(inner.max().item<double>(), 0.005);
  EXPECT_TRUE(stats.converged);
  EXPECT_NEAR(stats.completed_share, (kH - 6) * (kW - 6) / double(kH * kW), 1e-9);
  RecordProperty("iterations", stats.iterations);
  // The confidence floor decides what is completed: at 0.1 every guess is kept.
  EXPECT_TRUE(torch::equal(complete_depth(guessed, confidence, guide, on(0.1)), guessed));
}

TEST(DepthCompletion, AFullSizeMapIsSolvedFromItsCoarserGridsInFewIterations) {
  // A 320x256 map (sweep2d's at a 640x512 input) of a tilted plane, seen confidently only on a
  // grid of lines 4 pixels wide every 48 pixels; the network guessed 1.5x too far in between
  // (holes this wide keep a few per cent of the guess, as in the test above). Conjugate gradient
  // from the guesses needs 140 iterations on this map; started from the halved grids' solution,
  // about half as many.
  constexpr int64_t h = 256, w = 320;
  auto grid = torch::meshgrid({torch::arange(h, torch::kFloat32), torch::arange(w, torch::kFloat32)}, "ij");
  const auto truth = 1.0 / (0.4 + 0.0005 * grid[1] - 0.0004 * grid[0]);
  const auto on_line = (torch::remainder(grid[0], 48) < 4).logical_or(torch::remainder(grid[1], 48) < 4);
  const auto confidence = torch::where(on_line, torch::full({h, w}, 0.9f), torch::full({h, w}, 0.2f));
  const auto guessed = torch::where(on_line, truth, 1.5 * truth);
  DepthCompletionStats stats;
  const auto completed = complete_depth(guessed, confidence, torch::full({h, w}, 0.5f), on(), &stats);
  const auto error = (completed - truth).abs() / truth;
  RecordProperty("iterations", stats.iterations);
  RecordProperty("worst", std::to_string(error.max().item<double>()));
  EXPECT_TRUE(stats.converged);
  EXPECT_LT(error.max().item<double>(), 0.1);
  EXPECT_LT(error.mean().item<double>(), 0.03);
  EXPECT_LT(stats.iterations, 100) << "the coarser grids did not give the fine one a head start";
}

TEST(DepthCompletion, ImageEdgesStopTheFillBleedingAcrossObjects) {
  // Two surfaces side by side, 1 m and 3 m away, each seen confidently except in the 8 columns
  // next to their boundary, where the network guessed 2 m. With an image edge between them each
  // keeps its own depth up to the boundary; a uniform guide (no edge) blends them across it.
  auto depth = torch::ones({kH, kW});
  depth.slice(1, kW / 2).fill_(3.0f);
  auto confidence = torch::full({kH, kW}, 0.1f);
  confidence.slice(1, 0, kW / 2 - 8).fill_(0.95f);
  confidence.slice(1, kW / 2 + 8).fill_(0.95f);
  const auto guessed = torch::where(confidence > 0.5, depth, torch::full_like(depth, 2.0f));
  auto edge_guide = torch::full({kH, kW}, 0.2f);
  edge_guide.slice(1, kW / 2).fill_(0.8f);
  const auto with_edge = complete_depth(guessed, confidence, edge_guide, on());
  const auto without_edge = complete_depth(guessed, confidence, torch::full({kH, kW}, 0.5f), on());
  const auto rel = [&](const torch::Tensor& d) { return ((d - depth).abs() / depth).max().item<double>(); };
  RecordProperty("with_edge", std::to_string(rel(with_edge)));
  RecordProperty("without_edge", std::to_string(rel(without_edge)));
  EXPECT_LT(rel(with_edge), 0.05);
  EXPECT_GT(rel(without_edge), 0.2);
}

TEST(DepthCompletion, LeavesMapsWithNothingToCompleteFromAndUnusableDepthAlone) {
  auto depth = plane_depth();
  depth[5][7] = 0.0f;
  depth[9][11] = std::numeric_limits<float>::quiet_NaN();
  const auto guide = torch::full({kH, kW}, 0.5f);
  // No pixel reaches the floor: nothing to complete from, the map comes back as it was.
  auto unsure = torch::full({kH, kW}, 0.3f);
  auto same = complete_depth(depth, unsure, guide, on());
  EXPECT_TRUE(torch::equal(same.nan_to_num(-1), depth.nan_to_num(-1)));
  // Half the map confident: holes and NaNs stay what they were, everything else is a depth.
  auto half = unsure.clone();
  half.slice(0, 0, kH / 2).fill_(0.9f);
  auto completed = complete_depth(depth, half, guide, on());
  EXPECT_EQ(completed[5][7].item<float>(), 0.0f);
  EXPECT_TRUE(std::isnan(completed[9][11].item<float>()));
  completed[5][7] = 1.0f;
  completed[9][11] = 1.0f;
  EXPECT_TRUE((completed > 0).all().item<bool>() && torch::isfinite(completed).all().item<bool>());
}

TEST(DepthCompletion, BadSettingsAndShapesAreRefusedByName) {
  const auto d = torch::ones({4, 4});
  for (double floor : {-0.1, 1.5, std::nan("")}) {
    try {
      complete_depth(d, d, d, on(floor));
      ADD_FAILURE() << "floor " << floor << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("min_confidence"), std::string::npos) << e.what();
    }
  }
  DepthCompletionConfig bad_sigma = on();
  bad_sigma.edge_sigma = 0.0;
  EXPECT_THROW(complete_depth(d, d, d, bad_sigma), std::invalid_argument);
  EXPECT_THROW(complete_depth(d, torch::ones({4, 5}), d, on()), std::invalid_argument);
  EXPECT_THROW(complete_depth(torch::ones({1, 4, 4}), d, d, on()), std::invalid_argument);
  EXPECT_FALSE(DepthCompletionConfig{}.enabled()) << "off unless asked for";
}

}  // namespace
}  // namespace umvs
