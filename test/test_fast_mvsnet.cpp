// The inference path (core/fast_mvsnet.h) against MvsNetImpl::forward (the autograd path) on
// random weights, random images and cameras, several sizes, view counts and both depth samplings.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <iostream>

#include "test_util.h"
#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/fast_mvsnet.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"

namespace umvs {
namespace {

// Cameras on a small arc around a point 3 m ahead, slightly rotated, so that part of every source
// view falls outside the image (zero padding) and the sampling is not axis-aligned.
std::vector<Camera> arc_cameras(int width, int height, int views) {
  std::vector<Camera> cams;
  for (int v = 0; v < views; ++v) {
    Camera c;
    c.width = width;
    c.height = height;
    c.K << 0.9 * width, 0, width / 2.0 - 0.5, 0, 0.9 * width, height / 2.0 - 0.5, 0, 0, 1;
    const double a = (v % 2 ? 1 : -1) * 0.06 * ((v + 1) / 2);
    Eigen::Matrix3d R = Eigen::AngleAxisd(a, Eigen::Vector3d::UnitY()).toRotationMatrix() *
                        Eigen::AngleAxisd(0.02 * v, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    const Eigen::Vector3d centre(3.0 * std::sin(a), 0.03 * v, 3.0 - 3.0 * std::cos(a));
    c.T_cam_world.topLeftCorner<3, 3>() = R.transpose();
    c.T_cam_world.topRightCorner<3, 1>() = -R.transpose() * centre;
    cams.push_back(c);
  }
  return cams;
}

// Random weights everywhere, BatchNorm statistics included (the default ones, mean 0 and
// variance 1, would hide a wrong fold).
MvsNet random_model(int num_depth, int views, bool refine) {
  MvsNetConfig cfg;
  cfg.num_depth = num_depth;
  cfg.num_views = views;
  cfg.refine = refine;
  MvsNet net(cfg);
  torch::NoGradGuard no_grad;
  for (auto& item : net->named_buffers()) {
    if (item.key().find("running_mean") != std::string::npos) item.value().uniform_(-0.2, 0.2);
    if (item.key().find("running_var") != std::string::npos) item.value().uniform_(0.5, 2.0);
  }
  for (auto& item : net->named_parameters()) {
    if (item.key().find(".bn.") != std::string::npos || item.key().find(".1.") != std::string::npos) {
      item.value().uniform_(item.key().find("weight") != std::string::npos ? 0.5 : -0.2,
                            item.key().find("weight") != std::string::npos ? 1.5 : 0.2);
    }
  }
  // Default-initialised logits barely vary over the planes (a flat probability volume would make
  // any two paths agree): sharpen them.
  for (auto& item : net->named_parameters()) {
    if (item.key() == "cost_regularization.prob.weight") item.value().mul_(50.0);
  }
  net->eval();
  return net;
}

struct Case {
  int width, height, num_depth, views;
  DepthSampling sampling;
};

class FastPath : public ::testing::TestWithParam<Case> {};

TEST_P(FastPath, MatchesTheAutogradPath) {
  const Case c = GetParam();
  torch::manual_seed(c.width * 7 + c.num_depth + c.views);
  MvsNet model = random_model(c.num_depth, c.views, false);
  auto images = torch::rand({1, c.views, 3, c.height, c.width});
  auto proj = mvsnet_projection_matrices(arc_cameras(c.width, c.height, c.views)).unsqueeze(0);
  auto dv = depth_hypotheses(2.0, 4.5, c.num_depth, c.sampling).unsqueeze(0);
  torch::NoGradGuard no_grad;
  const MvsOutput ref = model->forward(images, proj, dv, true);
  FastMvsNet fast(model);
  MvsStageTimes times;
  const MvsOutput out = fast.forward(images, proj, dv, true, &times);
  // The comparison means something only if the fast path ran.
  ASSERT_TRUE(FastMvsNet::accelerates(torch::kCPU)) << "this LibTorch has no oneDNN";
  EXPECT_GT(times.cost_volume, 0.0);
  EXPECT_GT(times.regularization, 0.0);

  const double prob_err = (out.prob_volume - ref.prob_volume).abs().max().item<double>();
  const double depth_rel = ((out.depth - ref.depth).abs() / ref.depth).max().item<double>();
  const double conf_close = test::fraction_close(out.confidence, ref.confidence, 0.0, 1e-4);
  // Spread of the outputs, so that agreement is not trivial (e.g. a flat probability volume).
  const double prob_max = ref.prob_volume.max().item<double>();
  const double depth_spread = (ref.depth.max() - ref.depth.min()).item<double>();
  std::cout << "[fast path] " << c.width << "x" << c.height << " D=" << c.num_depth << " V=" << c.views << " "
            << to_string(c.sampling) << ": prob max abs diff " << prob_err << " (max prob " << prob_max
            << "), depth max rel diff " << depth_rel << " (spread " << depth_spread << " m), confidence within 1e-4 on "
            << 100 * conf_close << "% of pixels\n";
  EXPECT_GT(prob_max, 2.0 / c.num_depth);
  EXPECT_GT(depth_spread, 0.01);
  EXPECT_LT(prob_err, 1e-5);
  EXPECT_LT(depth_rel, 1e-5);
  EXPECT_GE(conf_close, 0.999);
  EXPECT_TRUE(torch::allclose(out.depth_init, ref.depth_init, 1e-5, 0.0));

  // Built a few planes at a time (one plane per slab here), the volume gives the same result.
  FastMvsNet sliced(model, 1);
  const MvsOutput slabs = sliced.forward(images, proj, dv, true);
  EXPECT_LT((slabs.prob_volume - out.prob_volume).abs().max().item<double>(), 1e-6);
}

INSTANTIATE_TEST_SUITE_P(Sizes, FastPath,
                         ::testing::Values(Case{32, 32, 8, 2, DepthSampling::kUniformDepth},
                                           Case{96, 64, 16, 3, DepthSampling::kUniformInverseDepth},
                                           Case{160, 128, 32, 3, DepthSampling::kUniformDepth},
                                           Case{128, 96, 24, 4, DepthSampling::kUniformInverseDepth},
                                           Case{320, 256, 16, 3, DepthSampling::kUniformInverseDepth}));

TEST(Threads, ParallelLoopsOfThisLibraryRunOnTheThreadsAsked) {
  // at::parallel_for compiled into our code without OpenMP runs on one thread whatever
  // torch::set_num_threads says (the cost volume and fusion were serial that way).
  const int before = torch::get_num_threads();
  torch::set_num_threads(2);
  EXPECT_EQ(parallel_loop_threads(), 2);
  torch::set_num_threads(1);
  EXPECT_EQ(parallel_loop_threads(), 1);
  torch::set_num_threads(before);
}

TEST(FastPath, CostVolumeMatchesTheWarpedVolumes) {
  // variance_cost_volume against its definition: mean of squares minus square of the mean over
  // the reference and the homography-warped sources, for both feature warps. The third view
  // (x and z swapped) sees part of the reference frustum behind it or on its camera plane.
  torch::manual_seed(3);
  const int64_t C = 5, H = 6, W = 8, D = 4;
  auto features = torch::randn({1, 3, C, H, W});
  auto cams = arc_cameras(4 * W, 4 * H, 2);
  auto swapped = torch::tensor({0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 1.f}).view({4, 4});
  auto proj = torch::stack({mvsnet_projection_matrix(cams[0]), mvsnet_projection_matrix(cams[1]), swapped}).unsqueeze(0);
  auto dv = depth_hypotheses(1.0, 2.0, D, DepthSampling::kUniformDepth).unsqueeze(0);
  torch::Tensor volumes[2];
  for (const FeatureWarp warp : {FeatureWarp::kExact, FeatureWarp::kMvsNetPytorch}) {
    SCOPED_TRACE(to_string(warp));
    auto sum = features.select(1, 0).unsqueeze(2).repeat({1, 1, D, 1, 1});
    auto sq = sum.pow(2);
    for (int v = 1; v < 3; ++v) {
      auto w = homography_warp(features.select(1, v), proj.select(1, v), proj.select(1, 0), dv, warp);
      sum = sum + w;
      sq = sq + w.pow(2);
    }
    auto expected = sq / 3.0 - (sum / 3.0).pow(2);
    auto volume = variance_cost_volume(features, proj, dv, warp);
    ASSERT_EQ(volume.sizes(), expected.sizes());
    // A range of planes, with a zero plane on either side beyond the volume.
    auto slab = VarianceCostVolume(features, proj, dv, warp).planes(-1, 2);
    EXPECT_TRUE(torch::equal(slab.slice(2, 1, 3), volume.slice(2, 0, 2)));
    EXPECT_EQ(slab.select(2, 0).abs().max().item<float>(), 0.0f);
    EXPECT_EQ(VarianceCostVolume(features, proj, dv, warp).planes(D, D + 1).abs().max().item<float>(), 0.0f);
    EXPECT_TRUE(torch::isfinite(volume).all().item<bool>());
    const double err = (volume - expected).abs().max().item<double>();
    std::cout << "[fast path] " << to_string(warp) << " cost volume max abs diff " << err << " (values up to "
              << expected.abs().max().item<double>() << ")\n";
    EXPECT_LT(err, 1e-5);
    volumes[warp == FeatureWarp::kExact ? 0 : 1] = volume;
  }
  // The two warps sample different places.
  EXPECT_GT((volumes[0] - volumes[1]).abs().max().item<double>(), 1e-2);
}

TEST(FastPath, RefinementAndStageTimes) {
  torch::manual_seed(5);
  MvsNet model = random_model(16, 3, true);
  auto images = torch::rand({1, 3, 3, 64, 96});
  auto proj = mvsnet_projection_matrices(arc_cameras(96, 64, 3)).unsqueeze(0);
  auto dv = depth_hypotheses(2.0, 4.5, 16, DepthSampling::kUniformDepth).unsqueeze(0);
  torch::NoGradGuard no_grad;
  const MvsOutput ref = model->forward(images, proj, dv);
  FastMvsNet fast(model);
  MvsStageTimes times;
  const MvsOutput out = fast.forward(images, proj, dv, false, &times);
  EXPECT_FALSE(out.prob_volume.defined());
  EXPECT_GT((ref.depth - ref.depth_init).abs().max().item<double>(), 0.0);  // the refinement does something
  EXPECT_LT(((out.depth - ref.depth).abs() / ref.depth).max().item<double>(), 1e-5);
  EXPECT_GT(times.features, 0.0);
  EXPECT_GT(times.regression, 0.0);
  EXPECT_GT(times.refinement, 0.0);
}

TEST(FastPath, RejectsBadShapesLikeTheModel) {
  FastMvsNet fast(random_model(8, 2, false));
  auto images = torch::rand({1, 2, 3, 30, 64});
  auto proj = torch::eye(4).expand({1, 2, 4, 4});
  auto dv = torch::linspace(1, 2, 8).unsqueeze(0);
  EXPECT_THROW(fast.forward(images, proj, dv), c10::Error);
}

TEST(FastPath, CudaRunsTheTorchOpPath) {
  if (!torch::cuda::is_available()) GTEST_SKIP() << "no CUDA device";
  torch::manual_seed(9);
  MvsNet model = random_model(16, 3, false);
  auto images = torch::rand({1, 3, 3, 64, 96});
  auto proj = mvsnet_projection_matrices(arc_cameras(96, 64, 3)).unsqueeze(0);
  auto dv = depth_hypotheses(2.0, 4.5, 16, DepthSampling::kUniformDepth).unsqueeze(0);
  torch::NoGradGuard no_grad;
  const MvsOutput cpu = FastMvsNet(model).forward(images, proj, dv);
  model->to(torch::kCUDA);
  const MvsOutput gpu = FastMvsNet(model).forward(images.cuda(), proj.cuda(), dv.cuda());
  EXPECT_LT(((gpu.depth.cpu() - cpu.depth).abs() / cpu.depth).max().item<double>(), 1e-4);
}

}  // namespace
}  // namespace umvs
