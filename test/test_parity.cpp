// Parity with the reference MVSNet_pytorch on the published weights (../shared/data/mvsnet_parity).
// Expected on CPU: depth within 1e-4 relative and confidence within 1e-4 absolute on >= 99.9% of
// pixels (confidence is discontinuous where the expected plane index is near an integer).
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <charconv>
#include <cstdlib>
#include <filesystem>
#include <iostream>

#include "test_util.h"
#include "unsup_mvs/core/fast_mvsnet.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {
namespace {

struct CaseData {
  torch::Tensor imgs, imgs_u8, proj, intrinsics, extrinsics, depth_values, depth, confidence, features, prob;
};

CaseData load_case(const std::string& dir) {
  namespace fs = std::filesystem;
  CaseData c;
  if (fs::exists(dir + "/imgs.npy")) {
    c.imgs = read_npy(dir + "/imgs.npy");
  } else {
    c.imgs_u8 = read_npy(dir + "/imgs_u8.npy");
    c.imgs = c.imgs_u8.to(torch::kFloat32).div(255);
  }
  c.proj = read_npy(dir + "/proj_matrices.npy");
  c.intrinsics = read_npy(dir + "/intrinsics.npy");
  c.extrinsics = read_npy(dir + "/extrinsics.npy");
  c.depth_values = read_npy(dir + "/depth_values.npy");
  c.depth = read_npy(dir + "/depth.npy");
  c.confidence = read_npy(dir + "/photometric_confidence.npy");
  c.features = read_npy(dir + "/ref_features.npy");
  if (fs::exists(dir + "/prob_volume.npy")) c.prob = read_npy(dir + "/prob_volume.npy");
  return c;
}

void report(const std::string& what, const torch::Tensor& ours, const torch::Tensor& ref, double rtol, double atol,
            double min_fraction) {
  const double frac = test::fraction_close(ours, ref, rtol, atol);
  const double max_abs = (ours - ref).abs().max().item<double>();
  const double max_rel = ((ours - ref).abs() / ref.abs().clamp_min(1e-12)).max().item<double>();
  std::cout << "[parity] " << what << ": " << 100.0 * frac << "% within (rtol " << rtol << ", atol " << atol
            << "), max abs " << max_abs << ", max rel " << max_rel << "\n";
  EXPECT_GE(frac, min_fraction) << what;
}

class Parity : public ::testing::TestWithParam<std::string> {};

TEST_P(Parity, NetworkMatchesReference) {
  UMVS_REQUIRE_SHARED("mvsnet_parity/" + GetParam(), dir);
  torch::set_num_threads(2);
  auto model = load_model(test::shared_data_dir() + "/mvsnet_parity/mvsnet_pytorch_d192.pt", torch::kCPU);
  ASSERT_EQ(model.format, "mvsnet_pytorch");
  const CaseData c = load_case(dir);
  torch::NoGradGuard no_grad;
  auto features = model.model->feature(c.imgs.select(1, 0));
  report(GetParam() + " ref_features", features, c.features, 1e-4, 1e-4, 0.999);
  // The same tolerances through the autograd path (training) and the inference path (umvs infer,
  // umvs bench, the inference nodelet).
  FastMvsNet fast(model.model);
  for (const bool use_fast : {false, true}) {
    const std::string name = GetParam() + (use_fast ? " fast path" : " autograd path");
    MvsStageTimes times;
    auto out = use_fast ? fast.forward(c.imgs, c.proj, c.depth_values, c.prob.defined(), &times)
                        : model.model->forward(c.imgs, c.proj, c.depth_values, c.prob.defined());
    if (use_fast) {
      EXPECT_GT(times.cost_volume, 0.0) << "the fast path did not run";
    }
    if (c.prob.defined()) report(name + " prob_volume", out.prob_volume, c.prob, 0.0, 1e-4, 0.999);
    report(name + " depth", out.depth, c.depth, 1e-4, 0.0, 0.999);
    report(name + " confidence", out.confidence, c.confidence, 0.0, 1e-4, 0.999);
  }
}

INSTANTIATE_TEST_SUITE_P(MvsNetPytorch, Parity, ::testing::Values("parity_small", "parity_full", "parity_livingroom"));

// The exact feature warp against the reference run with grid_sample(align_corners = true), the
// sampling its (W-1)/2 grid normalisation was written for (parity_small's extra arrays).
TEST(ExactWarpParity, MatchesTheReferenceRunWithAlignCorners) {
  UMVS_REQUIRE_SHARED("mvsnet_parity/parity_small", dir);
  torch::set_num_threads(2);
  auto model = load_model(test::shared_data_dir() + "/mvsnet_parity/mvsnet_pytorch_d192.pt", torch::kCPU);
  EXPECT_EQ(model.model->config().feature_warp, FeatureWarp::kMvsNetPytorch);
  model.model->set_feature_warp(FeatureWarp::kExact);
  const CaseData c = load_case(dir);
  const auto depth = read_npy(dir + "/depth_aligncorners_true.npy");
  const auto confidence = read_npy(dir + "/photometric_confidence_aligncorners_true.npy");
  torch::NoGradGuard no_grad;
  FastMvsNet fast(model.model);
  for (const bool use_fast : {false, true}) {
    const std::string name = std::string("parity_small exact warp, ") + (use_fast ? "fast path" : "autograd path");
    auto out = use_fast ? fast.forward(c.imgs, c.proj, c.depth_values) : model.model->forward(c.imgs, c.proj, c.depth_values);
    report(name + " depth", out.depth, depth, 1e-4, 0.0, 0.999);
    report(name + " confidence", out.confidence, confidence, 0.0, 1e-4, 0.999);
    // ... and it is not the default warp's result.
    EXPECT_LT(test::fraction_close(out.depth, c.depth, 1e-4, 0.0), 0.9) << name;
  }
}

// The same numbers through `umvs infer` on an MVSNet-format folder made from the case.
class InferParity : public ::testing::TestWithParam<std::string> {};

TEST_P(InferParity, UmvsInferMatchesReference) {
  UMVS_REQUIRE_SHARED("mvsnet_parity/" + GetParam(), dir);
  const CaseData c = load_case(dir);
  ASSERT_TRUE(c.imgs_u8.defined()) << "case has no 8-bit images";
  const std::string data = test::temp_dir("infer_parity_" + GetParam());
  make_directories(data + "/images");
  make_directories(data + "/cams");
  const int V = static_cast<int>(c.imgs_u8.size(1));
  const int D = static_cast<int>(c.depth_values.size(1));
  std::vector<ViewPair> pairs(1);
  pairs[0].ref = 0;
  for (int v = 0; v < V; ++v) {
    write_png(data + "/images/" + view_file_stem(v) + ".png", c.imgs_u8[0][v].permute({1, 2, 0}).contiguous());
    MvsCam cam;
    auto K = c.intrinsics[v].to(torch::kFloat64), E = c.extrinsics[v].to(torch::kFloat64);
    for (int r = 0; r < 3; ++r) for (int k = 0; k < 3; ++k) cam.camera.K(r, k) = K[r][k].item<double>();
    for (int r = 0; r < 4; ++r) for (int k = 0; k < 4; ++k) cam.camera.T_cam_world(r, k) = E[r][k].item<double>();
    // The shortest decimal of the float32 bounds (0.488, not 0.488000005), as the case was made.
    auto shortest = [](float f) {
      char buf[32];
      auto res = std::to_chars(buf, buf + sizeof(buf), f);
      return std::stod(std::string(buf, res.ptr));
    };
    cam.depth_min = shortest(c.depth_values[0][0].item<float>());
    cam.depth_max = shortest(c.depth_values[0][D - 1].item<float>());
    cam.depth_num = D;
    cam.depth_interval = (cam.depth_max - cam.depth_min) / (D - 1);
    write_cam_file(data + "/cams/" + view_file_stem(v) + "_cam.txt", cam);
    if (v > 0) {
      pairs[0].sources.push_back(v);
      pairs[0].scores.push_back(1.0);
    }
  }
  write_pair_file(data + "/pair.txt", pairs);
  // The cams as written give the reference's projection matrices.
  std::vector<Camera> cams;
  for (int v = 0; v < V; ++v) cams.push_back(read_cam_file(data + "/cams/" + view_file_stem(v) + "_cam.txt").camera);
  const double proj_err = (mvsnet_projection_matrices(cams) - c.proj[0]).abs().max().item<double>();
  EXPECT_EQ(proj_err, 0.0) << "projection matrices differ from the reference's";
  const std::string out = data + "/out";
  const std::string cmd = test::umvs_binary() + " infer --data " + data + " --checkpoint " + test::shared_data_dir() +
                          "/mvsnet_parity/mvsnet_pytorch_d192.pt --out " + out + " --ref 0 --threads 2 --views " +
                          std::to_string(V) + " --num-depth " + std::to_string(D) +
                          " --source-combination variance --complete-below-confidence 0";  // MVSNet's one pass, as the reference's
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  auto depth = read_pfm(out + "/depth_est/00000000.pfm");
  auto conf = read_pfm(out + "/confidence/00000000.pfm");
  report("umvs infer " + GetParam() + " depth", depth, c.depth[0], 1e-4, 0.0, 0.999);
  report("umvs infer " + GetParam() + " confidence", conf, c.confidence[0], 0.0, 1e-4, 0.999);
  // The written depth-map camera and colours belong to the 1/4-resolution grid.
  const MvsCam out_cam = read_cam_file(out + "/cams/00000000_cam.txt");
  EXPECT_NEAR(out_cam.camera.K(0, 0), c.intrinsics[0][0][0].item<double>() / 4, 1e-4);
  EXPECT_EQ(read_image_rgb8(out + "/images/00000000.png").size(1), depth.size(1));
}

INSTANTIATE_TEST_SUITE_P(MvsNetPytorch, InferParity, ::testing::Values("parity_full", "parity_livingroom"));

}  // namespace
}  // namespace umvs
