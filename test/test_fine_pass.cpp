// The fine pass of a coarse-to-fine estimate (core/fine_pass.h, FastMvsNet::forward_coarse_to_fine):
// its hypotheses, the naive 2x interpolation, the per-pixel warp, and the two passes against
// their definition on random weights.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>

#include "unsup_mvs/core/fast_mvsnet.h"
#include "unsup_mvs/core/fine_pass.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"

namespace umvs {
namespace {

// Three cameras 3 m from the origin, 0.2 m apart along x, looking along +z.
std::vector<Camera> row_of_cameras(int width, int height) {
  std::vector<Camera> cams;
  for (int v = 0; v < 3; ++v) {
    Camera c;
    c.width = width;
    c.height = height;
    c.K << 0.9 * width, 0, width / 2.0 - 0.5, 0, 0.9 * width, height / 2.0 - 0.5, 0, 0, 1;
    c.T_cam_world.topRightCorner<3, 1>() = Eigen::Vector3d(0.2 * (v - 1), 0.0, 3.0);
    cams.push_back(c);
  }
  return cams;
}

TEST(FinePass, HypothesesAreCentredEvenlySpacedIncreasingAndInsideTheRange) {
  for (const DepthSampling sampling : {DepthSampling::kUniformDepth, DepthSampling::kUniformInverseDepth}) {
    SCOPED_TRACE(to_string(sampling));
    const bool inverse = sampling == DepthSampling::kUniformInverseDepth;
    const auto s = [inverse](const torch::Tensor& d) { return inverse ? d.reciprocal() : d; };
    const auto planes = depth_hypotheses(1.0, 5.0, 33, sampling).unsqueeze(0);  // 32 intervals
    // Mid-range, at the near end, at the far end.
    const auto depth = torch::tensor({2.0f, 1.0f, 5.0f}).view({1, 1, 3});
    FinePassConfig fine;
    fine.planes = 8;
    fine.span = 4.0;
    const auto h = fine_pass_hypotheses(depth, planes, sampling, fine);
    ASSERT_EQ(h.sizes(), (std::vector<int64_t>{1, 8, 1, 3}));
    EXPECT_TRUE((h.diff(1, 1) > 0).all().item<bool>()) << "not increasing in depth";
    const double interval = std::abs((s(planes.select(1, 32)) - s(planes.select(1, 0))).item<double>()) / 32;
    const auto steps = s(h).diff(1, 1).abs();  // in the sampling's coordinate: all the same
    EXPECT_NEAR(steps.min().item<double>(), 4.0 * interval / 7, 1e-5 * interval * 32);
    EXPECT_NEAR(steps.max().item<double>(), 4.0 * interval / 7, 1e-5 * interval * 32);
    // Centred mid-range: the middle of the window is the first pass's depth.
    const auto mid = s(h.select(3, 0)).mean().item<double>();
    EXPECT_NEAR(mid, s(torch::tensor(2.0)).item<double>(), 1e-5);
    // At the ends the window is moved inside the range, touching its end.
    EXPECT_NEAR(h.select(3, 1).min().item<double>(), 1.0, 1e-5);
    EXPECT_NEAR(h.select(3, 2).max().item<double>(), 5.0, 1e-4);
    EXPECT_GE(h.min().item<double>(), 1.0 - 1e-5);
    EXPECT_LE(h.max().item<double>(), 5.0 + 1e-4);
  }
  FinePassConfig bad;
  bad.planes = 12;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad.planes = 8;
  bad.resolution_divisor = 3;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad.resolution_divisor = 2;
  bad.span = 0;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad.span = 4;
  bad.first_pass_downscale = 4;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

TEST(FinePass, UpsamplingKeepsEvenPixelsAndAveragesOddOnes) {
  const auto x = torch::arange(12, torch::kFloat32).view({1, 1, 3, 4});
  const auto up = upsample2_naive(x);
  ASSERT_EQ(up.sizes(), (std::vector<int64_t>{1, 1, 6, 8}));
  EXPECT_TRUE(torch::equal(up.slice(2, 0, 6, 2).slice(3, 0, 8, 2), x));
  EXPECT_FLOAT_EQ(up[0][0][0][1].item<float>(), 0.5f);   // between columns 0 and 1
  EXPECT_FLOAT_EQ(up[0][0][1][0].item<float>(), 2.0f);   // between rows 0 and 1 (0 and 4)
  EXPECT_FLOAT_EQ(up[0][0][1][1].item<float>(), 2.5f);   // between all four
  EXPECT_FLOAT_EQ(up[0][0][5][7].item<float>(), 11.0f);  // the last row and column repeat
}

TEST(FinePass, PerPixelHypothesesWarpAsPlanesDo) {
  torch::manual_seed(1);
  const int64_t H = 8, W = 12, D = 5;
  const auto cams = row_of_cameras(4 * W, 4 * H);
  const auto proj = mvsnet_projection_matrices(cams).unsqueeze(0);
  const auto features = torch::randn({1, 3, 4, H, W});
  const auto planes = depth_hypotheses(2.0, 4.0, D, DepthSampling::kUniformDepth).unsqueeze(0);
  const auto per_pixel = planes.view({1, D, 1, 1}).expand({1, D, H, W}).contiguous();
  for (const FeatureWarp warp : {FeatureWarp::kExact, FeatureWarp::kMvsNetPytorch}) {
    SCOPED_TRACE(to_string(warp));
    EXPECT_TRUE(torch::allclose(variance_volume_by_warps(features, proj, per_pixel, warp),
                                variance_cost_volume(features, proj, planes, warp), 1e-5, 1e-5));
  }
  // A different depth per pixel samples a different place.
  auto varied = per_pixel.clone();
  varied.select(3, 0).mul_(1.3);
  const auto a = homography_warp(features.select(1, 1), proj.select(1, 1), proj.select(1, 0), per_pixel, FeatureWarp::kExact);
  const auto b = homography_warp(features.select(1, 1), proj.select(1, 1), proj.select(1, 0), varied, FeatureWarp::kExact);
  EXPECT_TRUE(torch::equal(a.slice(4, 1), b.slice(4, 1)));
  EXPECT_GT((a.select(4, 0) - b.select(4, 0)).abs().max().item<double>(), 1e-3);
  // The inference path's volume (built in one pass per row) takes per-pixel hypotheses too.
  for (const FeatureWarp warp : {FeatureWarp::kExact, FeatureWarp::kMvsNetPytorch}) {
    SCOPED_TRACE(to_string(warp));
    const auto fast = VarianceCostVolume(features, proj, varied, warp).planes(0, D);
    EXPECT_LT((fast - variance_volume_by_warps(features, proj, varied, warp)).abs().max().item<double>(), 1e-5);
  }
  EXPECT_THROW(homography_warp(features.select(1, 1), proj.select(1, 1), proj.select(1, 0),
                               torch::ones({1, D, H, W + 1}), FeatureWarp::kExact),
               c10::Error);
}

// Random weights with sharpened logits (a flat probability volume would agree with anything).
MvsNet sharpened_random_model() {
  MvsNetConfig config;
  config.depth_sampling = DepthSampling::kUniformInverseDepth;  // the fine hypotheses follow the model's sampling
  MvsNet net(config);
  torch::NoGradGuard no_grad;
  for (auto& item : net->named_parameters()) {
    if (item.key() == "cost_regularization.prob.weight") item.value().mul_(50.0);
  }
  net->eval();
  return net;
}

TEST(FinePass, TwoPassesFollowTheirDefinition) {
  torch::manual_seed(2);
  MvsNet model = sharpened_random_model();
  const int W = 128, H = 64;
  const auto cams = row_of_cameras(W, H);
  const auto images = torch::rand({1, 3, 3, H, W});
  const auto proj = mvsnet_projection_matrices(cams).unsqueeze(0);
  const auto planes = depth_hypotheses(2.0, 4.5, 16, DepthSampling::kUniformInverseDepth).unsqueeze(0);
  FastMvsNet fast(model);
  torch::NoGradGuard no_grad;
  const MvsOutput one_pass = fast.forward(images, proj, planes);
  for (const int divisor : {4, 2}) {
    SCOPED_TRACE(divisor);
    FinePassConfig fine;
    fine.planes = 8;
    fine.resolution_divisor = divisor;
    const auto proj_fine = mvsnet_projection_matrices(cams, 1.0 / divisor).unsqueeze(0);
    MvsStageTimes times;
    const MvsOutput out = fast.forward_coarse_to_fine(images, proj, planes, fine, proj_fine, &times);
    // The first pass is the one pass.
    EXPECT_TRUE(torch::allclose(out.depth_init, one_pass.depth_init, 1e-5, 0.0));
    ASSERT_EQ(out.depth.sizes(), (std::vector<int64_t>{1, H / divisor, W / divisor}));
    ASSERT_EQ(out.confidence.sizes(), out.depth.sizes());
    EXPECT_GT(times.fine_cost_volume, 0.0);
    EXPECT_GT(times.fine_regularization, 0.0);
    // The training path's two passes (torch ops, the model's own U-Net) are the same.
    const MvsOutput reference = coarse_to_fine_forward(*model, images, proj, planes, fine, proj_fine);
    EXPECT_LT(((out.depth - reference.depth).abs() / reference.depth).max().item<double>(), 1e-4);
    EXPECT_LT((out.confidence - reference.confidence).abs().max().item<double>(), 1e-4);
    // The fine pass by its definition: the variance over its hypotheses through the same 3-D U-Net.
    auto centre = out.depth_init;
    auto features = model->view_features(images);
    if (divisor == 2) {
      centre = upsample2_naive(centre.unsqueeze(1)).squeeze(1);
      features = upsample2_naive(features.squeeze(0)).unsqueeze(0);
    }
    const auto hypotheses = fine_pass_hypotheses(centre, planes, DepthSampling::kUniformInverseDepth, fine);
    const auto volume = variance_volume_by_warps(features, proj_fine, hypotheses, model->config().feature_warp);
    const auto prob = torch::softmax(model->cost_regularization->forward(volume), 1);
    const auto expected = (prob * hypotheses).sum(1);
    EXPECT_LT(((out.depth - expected).abs() / expected).max().item<double>(), 1e-4);
    // Inside the window, and not merely its middle.
    EXPECT_TRUE((out.depth >= hypotheses.select(1, 0) - 1e-4).all().item<bool>());
    EXPECT_TRUE((out.depth <= hypotheses.select(1, 7) + 1e-4).all().item<bool>());
    EXPECT_GT((out.depth - centre).abs().max().item<double>(), 1e-5);
  }
  // A first pass at half the size: depth_init at 1/8, the map still at 1/4.
  FinePassConfig half;
  half.planes = 8;
  half.first_pass_downscale = 2;
  const MvsOutput out = fast.forward_coarse_to_fine(images, proj, planes, half, proj);
  EXPECT_EQ(out.depth_init.sizes(), (std::vector<int64_t>{1, H / 8, W / 8}));
  EXPECT_EQ(out.depth.sizes(), (std::vector<int64_t>{1, H / 4, W / 4}));
  EXPECT_TRUE(torch::isfinite(out.depth).all().item<bool>());
  const MvsOutput reference = coarse_to_fine_forward(*model, images, proj, planes, half, proj);
  EXPECT_LT(((out.depth_init - reference.depth_init).abs() / reference.depth_init).max().item<double>(), 1e-4);
  EXPECT_LT(((out.depth - reference.depth).abs() / reference.depth).max().item<double>(), 1e-4);
  // A half-size first pass needs an input in multiples of 64, and says so.
  const auto odd = images.narrow(4, 0, 96);
  const auto odd_proj = mvsnet_projection_matrices(row_of_cameras(96, H)).unsqueeze(0);
  try {
    fast.forward_coarse_to_fine(odd, odd_proj, planes, half, odd_proj);
    ADD_FAILURE() << "a 96x64 input was accepted for a half-size first pass";
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what()).find("multiples of 64, got 96x64"), std::string::npos) << e.what();
  }
}

TEST(FinePass, TrainingLearnsBothPassesWithoutAGradientThroughTheHypotheses) {
  torch::manual_seed(3);
  MvsNet model = sharpened_random_model();
  model->train();
  const int W = 128, H = 64;
  const auto cams = row_of_cameras(W, H);
  const auto images = torch::rand({1, 3, 3, H, W});
  const auto proj = mvsnet_projection_matrices(cams).unsqueeze(0);
  const auto planes = depth_hypotheses(2.0, 4.5, 16, DepthSampling::kUniformInverseDepth).unsqueeze(0);
  FinePassConfig fine;
  fine.planes = 8;
  fine.resolution_divisor = 2;
  fine.first_pass_downscale = 2;
  const auto proj_fine = mvsnet_projection_matrices(cams, 0.5).unsqueeze(0);
  const MvsOutput out = coarse_to_fine_forward(*model, images, proj, planes, fine, proj_fine);
  ASSERT_EQ(out.depth.sizes(), (std::vector<int64_t>{1, H / 2, W / 2}));
  ASSERT_TRUE(out.depth.requires_grad());
  ASSERT_TRUE(out.depth_init.requires_grad());  // the first pass learns from its own loss
  // The map's depth does not depend on the first pass's depth: its hypotheses are detached.
  const auto through_first_pass = torch::autograd::grad({out.depth.sum()}, {out.depth_init}, {}, /*retain_graph=*/true,
                                                        /*create_graph=*/false, /*allow_unused=*/true);
  EXPECT_FALSE(through_first_pass[0].defined());
  // Both losses reach the weights they share: the 2-D features and the 3-D U-Net.
  for (const auto* depth : {&out.depth, &out.depth_init}) {
    model->zero_grad();
    depth->sum().backward({}, /*retain_graph=*/true);
    for (const char* name : {"feature.conv0.conv.weight", "cost_regularization.prob.weight"}) {
      const auto grad = model->named_parameters()[name].grad();
      ASSERT_TRUE(grad.defined()) << name;
      EXPECT_GT(grad.abs().sum().item<double>(), 0.0) << name;
      EXPECT_TRUE(torch::isfinite(grad).all().item<bool>()) << name;
    }
  }
}

}  // namespace
}  // namespace umvs
