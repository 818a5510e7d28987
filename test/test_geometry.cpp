#include <gtest/gtest.h>
#include <torch/torch.h>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"

namespace umvs {
namespace {

Camera camera_at_x(double x, int w = 64, int h = 48) {
  Camera c;
  c.width = w;
  c.height = h;
  c.K << 50, 0, (w - 1) / 2.0, 0, 50, (h - 1) / 2.0, 0, 0, 1;
  c.T_cam_world(0, 3) = -x;  // camera centre at (x, 0, 0)
  return c;
}

TEST(DepthHypotheses, UniformAndInverse) {
  auto d = depth_hypotheses(0.425, 0.935, 128, DepthSampling::kUniformDepth);
  ASSERT_EQ(d.size(0), 128);
  EXPECT_FLOAT_EQ(d[0].item<float>(), 0.425f);
  EXPECT_FLOAT_EQ(d[127].item<float>(), 0.935f);
  EXPECT_NEAR((d[1] - d[0]).item<double>(), (0.935 - 0.425) / 127, 1e-6);
  auto inv = depth_hypotheses(0.5, 50.0, 64, DepthSampling::kUniformInverseDepth);
  EXPECT_FLOAT_EQ(inv[0].item<float>(), 0.5f);
  EXPECT_NEAR(inv[63].item<double>(), 50.0, 1e-4);
  auto step = (1.0 / inv.to(torch::kFloat64)).diff();
  EXPECT_LT((step - step[0]).abs().max().item<double>(), 1e-5);
  EXPECT_TRUE((inv.diff() > 0).all().item<bool>());
  EXPECT_THROW(depth_hypotheses(2.0, 1.0, 8, DepthSampling::kUniformDepth), std::invalid_argument);
  EXPECT_THROW(depth_hypotheses(0.0, 1.0, 8, DepthSampling::kUniformDepth), std::invalid_argument);
  EXPECT_THROW(depth_hypotheses(1.0, std::nan(""), 8, DepthSampling::kUniformDepth), std::invalid_argument);
}

TEST(HomographyWarp, IdenticalCamerasReturnTheFeatures) {
  torch::manual_seed(1);
  auto fea = torch::rand({1, 4, 12, 16});
  auto P = mvsnet_projection_matrix(camera_at_x(0.0)).unsqueeze(0);
  auto dv = depth_hypotheses(1.0, 5.0, 8, DepthSampling::kUniformDepth).unsqueeze(0);
  auto warped = homography_warp(fea, P, P, dv, FeatureWarp::kExact);
  ASSERT_EQ(warped.sizes(), (std::vector<int64_t>{1, 4, 8, 12, 16}));
  for (int d = 0; d < 8; ++d) EXPECT_LT((warped.select(2, d) - fea).abs().max().item<double>(), 1e-5) << "plane " << d;
  // MVSNet_pytorch's warp reads up to half a pixel off towards the borders: the features come
  // back blurred and shifted, the same for every plane.
  auto legacy = homography_warp(fea, P, P, dv, FeatureWarp::kMvsNetPytorch);
  EXPECT_GT((legacy.select(2, 0) - fea).abs().max().item<double>(), 0.05);
  EXPECT_LT((legacy.select(2, 0) - legacy.select(2, 7)).abs().max().item<double>(), 1e-6);
}

TEST(HomographyWarp, FrontoParallelPlaneShiftsByDisparity) {
  // A source camera translated by b along x sees a plane at depth z shifted by f*b/z pixels.
  const int W = 64, H = 48;
  auto ref = camera_at_x(0.0, W, H), src = camera_at_x(0.2, W, H);
  auto dv = torch::tensor({2.5f}).view({1, 1});
  auto dv8 = dv.expand({1, 8}).contiguous();
  // A horizontal ramp image: the warped value tells where the sample came from.
  auto ramp = torch::arange(W / 4, torch::kFloat32).view({1, 1, 1, W / 4}).expand({1, 1, H / 4, W / 4}).contiguous();
  const auto warp = [&](FeatureWarp w) {
    return homography_warp(ramp, mvsnet_projection_matrix(src).unsqueeze(0), mvsnet_projection_matrix(ref).unsqueeze(0), dv8, w);
  };
  const double disparity = 50.0 / 4 * 0.2 / 2.5;  // feature-resolution focal length * b / z = 1 px
  const int w = W / 4;
  // Every pixel of row 6 whose source lies inside: exact reads at x - disparity.
  auto exact = warp(FeatureWarp::kExact);
  for (int x = 2; x < w; ++x) EXPECT_NEAR(exact[0][0][0][6][x].item<double>(), x - disparity, 1e-4) << "x " << x;
  // grid_sample(align_corners=false) with the (W-1)/2 normalisation reads at x' = x * w/(w-1) - 0.5,
  // exactly as MVSNet_pytorch on torch>=1.3.
  auto legacy = warp(FeatureWarp::kMvsNetPytorch);
  const double x = 8, xs = x - disparity;
  EXPECT_NEAR(legacy[0][0][0][6][8].item<double>(), xs * w / (w - 1.0) - 0.5, 1e-4);
}

TEST(HomographyWarp, PointsOnTheSourceCameraPlaneSampleNothingInsteadOfNaN) {
  // Reference: identity projection, pixel (x, y) at depth d is (x d, y d, d). Source: x and z
  // swapped, so the reference's column x = 0 lies exactly on the source's z = 0 plane (x/0).
  auto fea = torch::ones({1, 2, 6, 8});
  auto ref = torch::eye(4).unsqueeze(0);
  auto src = torch::tensor({0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 1.f}).view({1, 4, 4});
  auto dv = depth_hypotheses(1.0, 2.0, 4, DepthSampling::kUniformDepth).unsqueeze(0);
  for (const FeatureWarp warp : {FeatureWarp::kExact, FeatureWarp::kMvsNetPytorch}) {
    auto warped = homography_warp(fea, src, ref, dv, warp);
    EXPECT_TRUE(torch::isfinite(warped).all().item<bool>());
    EXPECT_EQ(warped.select(4, 0).abs().max().item<float>(), 0.0f);  // out of view: zero padding
  }
}

TEST(InverseWarp, RecoversTheReferenceFromATranslatedView) {
  // A source image made of a smooth pattern; the reference is the source warped with known depth.
  const int W = 40, H = 30;
  auto ref = camera_at_x(0.0, W, H), src = camera_at_x(0.1, W, H);
  auto xs = torch::arange(W, torch::kFloat32).view({1, W}).expand({H, W});
  auto ys = torch::arange(H, torch::kFloat32).view({H, 1}).expand({H, W});
  auto pattern = [](const torch::Tensor& x, const torch::Tensor& y) { return torch::sin(x * 0.3) + torch::cos(y * 0.2); };
  auto src_img = pattern(xs, ys).view({1, 1, H, W});
  auto depth = torch::full({1, H, W}, 2.0);
  auto K = intrinsics_tensor(ref).unsqueeze(0);
  auto T = relative_pose_tensor(ref, src).unsqueeze(0);
  auto out = inverse_warp(src_img, K, K, T, depth);
  // Expected: the source pattern at x - f*b/z = x - 2.5.
  auto expected = pattern(xs - 2.5, ys);
  auto valid = out.valid[0][0] > 0.5;
  EXPECT_GT(valid.sum().item<int64_t>(), H * (W - 4));
  auto err = (out.warped[0][0] - expected).abs().masked_select(valid);
  // Bilinear interpolation of a smooth function at half-pixel offsets: small error.
  EXPECT_LT(err.max().item<double>(), 0.02);
  // The first columns come from outside the source image.
  EXPECT_FALSE(valid[10][0].item<bool>());
}

TEST(InverseWarp, GradientFlowsIntoDepth) {
  const int W = 16, H = 12;
  auto ref = camera_at_x(0.0, W, H), src = camera_at_x(0.1, W, H);
  auto src_img = torch::rand({1, 1, H, W});
  auto depth = torch::full({1, H, W}, 2.0, torch::requires_grad());
  auto out = inverse_warp(src_img, intrinsics_tensor(ref).unsqueeze(0), intrinsics_tensor(src).unsqueeze(0),
                          relative_pose_tensor(ref, src).unsqueeze(0), depth);
  out.warped.sum().backward();
  ASSERT_TRUE(depth.grad().defined());
  EXPECT_GT(depth.grad().abs().sum().item<double>(), 0.0);
}

TEST(MvsNetHead, SoftArgminOfOneHotReturnsThatDepth) {
  const int D = 16;
  auto dv = depth_hypotheses(1.0, 4.0, D, DepthSampling::kUniformDepth).unsqueeze(0);
  auto prob = torch::zeros({1, D, 2, 3});
  prob.select(1, 5).fill_(1.0);
  auto depth = expected_depth(prob, dv);
  EXPECT_NEAR(depth[0][1][2].item<double>(), dv[0][5].item<double>(), 1e-6);
  auto conf = photometric_confidence(prob);
  EXPECT_NEAR(conf[0][0][0].item<double>(), 1.0, 1e-6);
}

TEST(MvsNetHead, ConfidenceSumsFourPlanesAroundTheEstimate) {
  const int D = 8;
  auto prob = torch::zeros({1, D, 1, 1});
  // Mass 0.1 at planes 0..7 except plane 3 (0.3): expected index = sum p*d.
  prob.fill_(0.1);
  prob[0][3][0][0] = 0.3;
  const double e = (prob.view({D}) * torch::arange(D)).sum().item<double>();  // 3.4
  const int i = static_cast<int>(e);
  double expected = 0;
  for (int k = i - 1; k <= i + 2; ++k) if (k >= 0 && k < D) expected += prob[0][k][0][0].item<double>();
  EXPECT_NEAR(photometric_confidence(prob).item<double>(), expected, 1e-6);
  // At the border only the existing planes count: all mass on plane 0 -> 1, on plane D-1 -> 1.
  auto edge = torch::zeros({1, D, 1, 2});
  edge[0][0][0][0] = 1;
  edge[0][D - 1][0][1] = 1;
  auto c = photometric_confidence(edge);
  EXPECT_NEAR(c[0][0][0].item<double>(), 1.0, 1e-6);
  EXPECT_NEAR(c[0][0][1].item<double>(), 1.0, 1e-6);
}

TEST(MvsNet, ForwardShapesAndRefinementChangesDepth) {
  torch::manual_seed(0);
  MvsNetConfig cfg;
  cfg.num_depth = 16;
  cfg.refine = true;
  MvsNet net(cfg);
  net->eval();
  std::vector<Camera> cams = {camera_at_x(0.0, 64, 32), camera_at_x(0.1, 64, 32), camera_at_x(-0.1, 64, 32)};
  auto images = torch::rand({1, 3, 3, 32, 64});
  auto proj = mvsnet_projection_matrices(cams).unsqueeze(0);
  auto dv = depth_hypotheses(1.0, 4.0, 16, DepthSampling::kUniformDepth).unsqueeze(0);
  torch::NoGradGuard ng;
  auto out = net->forward(images, proj, dv, true);
  EXPECT_EQ(out.depth.sizes(), (std::vector<int64_t>{1, 8, 16}));
  EXPECT_EQ(out.prob_volume.sizes(), (std::vector<int64_t>{1, 16, 8, 16}));
  EXPECT_NEAR(out.prob_volume.sum(1).mean().item<double>(), 1.0, 1e-5);
  EXPECT_TRUE(torch::isfinite(out.depth).all().item<bool>());
  EXPECT_TRUE((out.depth_init >= 1.0 - 1e-4).all().item<bool>());
  EXPECT_TRUE((out.depth_init <= 4.0 + 1e-4).all().item<bool>());
  // The refinement branch runs and adds a (random-weight, non-zero) residual.
  EXPECT_GT((out.depth - out.depth_init).abs().max().item<double>(), 0.0);
  // Its gradient reaches the refinement weights in training mode.
  torch::GradMode::set_enabled(true);
  net->train();
  auto train_out = net->forward(images, proj, dv);
  train_out.depth.mean().backward();
  bool refine_has_grad = false;
  for (const auto& p : net->refine_network->parameters()) {
    if (p.grad().defined() && p.grad().abs().sum().item<double>() > 0) refine_has_grad = true;
  }
  EXPECT_TRUE(refine_has_grad);
}

TEST(MvsNet, RejectsBadShapes) {
  MvsNetConfig cfg;
  cfg.num_depth = 12;
  EXPECT_THROW(MvsNet{cfg}, std::invalid_argument);
  cfg.num_depth = 8;
  MvsNet net(cfg);
  auto images = torch::rand({1, 2, 3, 30, 64});
  auto proj = torch::eye(4).expand({1, 2, 4, 4});
  auto dv = torch::linspace(1, 2, 8).unsqueeze(0);
  EXPECT_THROW(net->forward(images, proj, dv), c10::Error);
}

TEST(MvsNet, FlopCountGrowsWithResolutionAndDepth) {
  const double a = mvsnet_forward_flops(256, 320, 64, 3);
  EXPECT_NEAR(mvsnet_forward_flops(512, 640, 64, 3) / a, 4.0, 1e-9);
  // Linear in the number of planes (cost volume) and in the number of views (features).
  const double per_64_planes = mvsnet_forward_flops(256, 320, 128, 3) - a;
  EXPECT_NEAR(mvsnet_forward_flops(256, 320, 192, 3) - mvsnet_forward_flops(256, 320, 128, 3), per_64_planes, 1.0);
  // The first FeatureNet layer alone is 2*8*3*9 flops per pixel and view.
  EXPECT_GT(mvsnet_forward_flops(256, 320, 64, 4) - a, 2.0 * 8 * 3 * 9 * 256 * 320);
}

}  // namespace
}  // namespace umvs
