// The unsupervised loss (core/losses.h) on analytic scenes: textured planes seen by translated
// cameras, rendered exactly (ray/plane intersection, texture a smooth function of the world point).
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/losses.h"

namespace umvs {
namespace {

constexpr int kW = 64, kH = 48;
constexpr double kFocal = 60.0;

Camera camera_at_xy(double x, double y, int w = kW, int h = kH) {
  Camera c;
  c.width = w;
  c.height = h;
  c.K << kFocal, 0, (w - 1) / 2.0, 0, kFocal, (h - 1) / 2.0, 0, 0, 1;
  c.T_cam_world(0, 3) = -x;  // centre at (x, y, 0), looking along +z
  c.T_cam_world(1, 3) = -y;
  return c;
}

// A scene: background plane z = 3 and, optionally, a square occluder at z = 1.5 in front of the
// reference's centre. The texture is a sum of smooth sinusoids of the world point (per channel),
// different on the two surfaces, so every pixel's colour is exact and bilinear sampling of a
// rendered view is accurate to second order.
struct PlaneScene {
  bool occluder = false;
  double z_back = 3.0, z_front = 1.5, half = 0.25;

  // -> image [3,H,W], depth [H,W]
  std::pair<torch::Tensor, torch::Tensor> render(const Camera& cam) const {
    auto img = torch::empty({3, cam.height, cam.width}, torch::kFloat64);
    auto depth = torch::empty({cam.height, cam.width}, torch::kFloat64);
    auto ia = img.accessor<double, 3>();
    auto da = depth.accessor<double, 2>();
    for (int v = 0; v < cam.height; ++v)
      for (int u = 0; u < cam.width; ++u) {
        Eigen::Vector3d X = cam.backproject(u, v, z_front);
        bool front = occluder && std::abs(X.x()) < half && std::abs(X.y()) < half;
        const double z = front ? z_front : z_back;
        if (!front) X = cam.backproject(u, v, z_back);
        da[v][u] = z;
        for (int c = 0; c < 3; ++c) {
          const double o = front ? 1.7 : 0.0;
          ia[c][v][u] = 0.5 + 0.2 * std::sin(9.0 * X.x() + 2.0 * c + o) * std::cos(7.0 * X.y() - c) +
                        0.15 * std::sin(13.0 * X.x() + 11.0 * X.y() + c * 1.3 + o);
        }
      }
    return {img.to(torch::kFloat32), depth.to(torch::kFloat32)};
  }
};

struct LossInputs {
  torch::Tensor ref, src, K_ref, K_src, T, depth_gt;
};

LossInputs make_inputs(const PlaneScene& scene, const std::vector<std::pair<double, double>>& offsets) {
  const Camera ref = camera_at_xy(0, 0);
  auto [ref_img, depth] = scene.render(ref);
  std::vector<torch::Tensor> srcs, ks, ts;
  for (auto [x, y] : offsets) {
    const Camera c = camera_at_xy(x, y);
    srcs.push_back(scene.render(c).first);
    ks.push_back(intrinsics_tensor(c));
    ts.push_back(relative_pose_tensor(ref, c));
  }
  return {ref_img.unsqueeze(0), torch::stack(srcs).unsqueeze(0), intrinsics_tensor(ref).unsqueeze(0),
          torch::stack(ks).unsqueeze(0), torch::stack(ts).unsqueeze(0), depth.unsqueeze(0)};
}

LossTerms loss_at(const LossInputs& in, const torch::Tensor& depth, const LossConfig& cfg) {
  return unsupervised_loss(in.ref, in.src, in.K_ref, in.K_src, in.T, depth, cfg);
}

const std::vector<std::pair<double, double>> kFourNeighbours = {{0.3, 0}, {-0.3, 0}, {0, 0.25}, {0, -0.25}};

TEST(Losses, NearZeroAtTrueDepthAndClearlyHigherWhenPerturbed) {
  const auto in = make_inputs(PlaneScene{}, kFourNeighbours);
  for (auto term : {PhotometricTerm::kNaive, PhotometricTerm::kFirstOrder}) {
    LossConfig cfg;
    cfg.term = term;
    const double at_gt = loss_at(in, in.depth_gt, cfg).photometric.item<double>();
    const double off = loss_at(in, in.depth_gt * 1.1, cfg).photometric.item<double>();
    const double far = loss_at(in, in.depth_gt * 0.8, cfg).photometric.item<double>();
    SCOPED_TRACE(to_string(term));
    EXPECT_LT(at_gt, 0.006);  // bilinear resampling error of a smooth texture only
    EXPECT_GT(off, 5 * at_gt);
    EXPECT_GT(far, 5 * at_gt);
    const auto terms = loss_at(in, in.depth_gt, cfg);
    EXPECT_LT(terms.ssim.item<double>(), 0.01);
    EXPECT_GT(loss_at(in, in.depth_gt * 1.1, cfg).ssim.item<double>(), 3 * terms.ssim.item<double>());
    EXPECT_NEAR(terms.smoothness.item<double>(), 0.0, 1e-6);  // constant depth
    EXPECT_GT(terms.valid_fraction.item<double>(), 0.6);
  }
}

TEST(Losses, TopKPicksExactlyTheKSmallestValidEntries) {
  torch::manual_seed(3);
  const int B = 2, M = 5, H = 4, W = 6;
  auto losses = torch::rand({B, M, H, W});
  auto valid = (torch::rand({B, M, H, W}) > 0.3).to(torch::kFloat32);
  for (int k : {0, 1, 2, 3, 5}) {
    double sum = 0;
    int count = 0;
    auto la = losses.accessor<float, 4>();
    auto va = valid.accessor<float, 4>();
    for (int b = 0; b < B; ++b)
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          std::vector<double> vals;
          for (int m = 0; m < M; ++m)
            if (va[b][m][y][x] > 0.5) vals.push_back(la[b][m][y][x]);
          std::sort(vals.begin(), vals.end());
          const int kk = k == 0 ? M : k;
          for (int i = 0; i < std::min<int>(kk, vals.size()); ++i) sum += vals[i], ++count;
        }
    SCOPED_TRACE(k);
    EXPECT_NEAR(top_k_aggregate(losses, valid, k).item<double>(), sum / count, 1e-6);
  }
  EXPECT_THROW(top_k_aggregate(losses, valid, 6), std::invalid_argument);
  EXPECT_EQ(top_k_aggregate(losses, torch::zeros_like(valid), 2).item<double>(), 0.0);
}

TEST(Losses, TopKAtOcclusionsBeatsAllViewsAtTrueDepth) {
  PlaneScene scene;
  scene.occluder = true;
  const auto in = make_inputs(scene, kFourNeighbours);
  LossConfig all, robust;
  all.top_k = 0;
  robust.top_k = 2;
  const double l_all = loss_at(in, in.depth_gt, all).photometric.item<double>();
  const double l_top = loss_at(in, in.depth_gt, robust).photometric.item<double>();
  EXPECT_LT(l_top, 0.5 * l_all) << "all views " << l_all << ", top-2 " << l_top;
  // Even with top-K the true depth beats a wrong one.
  EXPECT_LT(l_top, loss_at(in, in.depth_gt * 1.05, robust).photometric.item<double>());
  // K = 1 is legal; more views than exist is not.
  robust.top_k = 1;
  EXPECT_LE(loss_at(in, in.depth_gt, robust).photometric.item<double>(), l_top + 1e-7);
  robust.top_k = 5;
  EXPECT_THROW(loss_at(in, in.depth_gt, robust), std::invalid_argument);
}

TEST(Losses, GradientWithRespectToDepthMatchesFiniteDifferences) {
  // Tiny case in float64: every term of the total loss (first-order, top-2 of 3, SSIM, smoothness).
  PlaneScene scene;
  scene.occluder = true;
  const int w = 20, h = 16;
  const Camera ref = camera_at_xy(0, 0, w, h);
  auto render = [&](const Camera& c) { return scene.render(c).first.to(torch::kFloat64); };
  std::vector<torch::Tensor> srcs, ks, ts;
  for (auto [x, y] : std::vector<std::pair<double, double>>{{0.2, 0}, {-0.2, 0.05}, {0, 0.15}}) {
    const Camera c = camera_at_xy(x, y, w, h);
    srcs.push_back(render(c));
    ks.push_back(intrinsics_tensor(c).to(torch::kFloat64));
    ts.push_back(relative_pose_tensor(ref, c).to(torch::kFloat64));
  }
  const auto ref_img = render(ref).unsqueeze(0), src = torch::stack(srcs).unsqueeze(0);
  const auto K_ref = intrinsics_tensor(ref).to(torch::kFloat64).unsqueeze(0);
  const auto K_src = torch::stack(ks).unsqueeze(0), T = torch::stack(ts).unsqueeze(0);
  torch::manual_seed(5);
  auto depth = (scene.render(ref).second.to(torch::kFloat64) * (1 + 0.05 * torch::randn({h, w}, torch::kFloat64)))
                   .unsqueeze(0)
                   .requires_grad_(true);
  LossConfig cfg;
  cfg.top_k = 2;
  cfg.gamma = 0.5;  // make the smoothness term matter in the check
  auto f = [&](const torch::Tensor& d) { return unsupervised_loss(ref_img, src, K_ref, K_src, T, d, cfg).total; };
  auto grad = torch::autograd::grad({f(depth)}, {depth})[0];
  ASSERT_GT(grad.abs().max().item<double>(), 0.0);
  const double eps = 1e-6;
  int checked = 0, agreed = 0;
  for (int y = 1; y < h - 1; y += 3)
    for (int x = 1; x < w - 1; x += 3) {
      auto dp = depth.detach().clone(), dm = depth.detach().clone();
      dp[0][y][x] += eps;
      dm[0][y][x] -= eps;
      const double fd = (f(dp).item<double>() - f(dm).item<double>()) / (2 * eps);
      const double an = grad[0][y][x].item<double>();
      ++checked;
      if (std::abs(fd - an) <= 1e-5 * std::max(1.0, std::abs(fd)) + 1e-7) ++agreed;
      else ADD_FAILURE() << "pixel (" << x << "," << y << "): analytic " << an << " vs finite difference " << fd;
    }
  EXPECT_EQ(agreed, checked);
}

TEST(Losses, SsimAndSmoothnessBehave) {
  torch::manual_seed(7);
  auto img = torch::rand({1, 3, 16, 16});
  auto valid = torch::ones({1, 1, 16, 16});
  EXPECT_NEAR(ssim_loss(img, img, valid).item<double>(), 0.0, 1e-5);
  const double noisy = ssim_loss(img, (img + 0.2 * torch::randn_like(img)).clamp(0, 1), valid).item<double>();
  EXPECT_GT(noisy, 0.05);
  EXPECT_LE(noisy, 1.0);
  // Edge-aware: a depth step where the image has an edge costs less than one in a flat region.
  auto depth = torch::ones({1, 16, 16});
  depth.slice(2, 8, 16).fill_(2.0);
  auto flat = torch::full({1, 3, 16, 16}, 0.5);
  auto edge = flat.clone();
  edge.slice(3, 8, 16).fill_(1.0);
  const double s_flat = smoothness_loss(depth, flat).item<double>();
  const double s_edge = smoothness_loss(depth, edge).item<double>();
  EXPECT_GT(s_flat, 0.0);
  EXPECT_NEAR(s_edge / s_flat, std::exp(-0.5), 1e-4);
  // Scale-free: the same shape in other units costs the same.
  EXPECT_NEAR(smoothness_loss(depth * 1000, flat).item<double>(), s_flat, 1e-6);
}

// The rotation search judges a source's warp by SSIM only where the reference has texture: two
// black windows match perfectly whatever the geometry, so they must be told apart from real matches.
TEST(Losses, FlatWindowsMatchPerfectlyAndLocalStdFindsThem) {
  torch::manual_seed(8);
  auto ref = torch::zeros({1, 3, 12, 12});
  ref.slice(3, 6, 12).copy_(torch::rand({1, 3, 12, 6}));  // left half black, right half textured
  auto unrelated = torch::zeros({1, 3, 12, 12});
  unrelated.slice(3, 6, 12).copy_(torch::rand({1, 3, 12, 6}));
  auto valid = torch::ones({1, 1, 12, 12});
  valid.slice(2, 0, 1).zero_();  // the top row unseen: its windows and the next row's are invalid
  const SsimLossMap map = ssim_loss_map(ref, unrelated, valid);
  EXPECT_EQ(map.window_valid.sum().item<double>(), 10 * 12);
  EXPECT_NEAR(map.loss.slice(2, 2, 12).slice(3, 0, 4).abs().max().item<double>(), 0.0, 1e-6)
      << "black against black should be a perfect match";
  EXPECT_GT(map.loss.slice(2, 2, 12).slice(3, 8, 12).mean().item<double>(), 0.3)
      << "random textures should not match";
  const double mean = (map.loss * map.window_valid).sum().item<double>() / map.window_valid.sum().item<double>();
  EXPECT_NEAR(ssim_loss(ref, unrelated, valid).item<double>(), mean, 1e-6);
  // local_std: zero on the black half, about the std of uniform noise (0.29) on the textured one.
  const auto spread = local_std(ref);
  EXPECT_LT(spread.slice(3, 0, 5).max().item<double>(), 1e-3);
  EXPECT_NEAR(spread.slice(3, 7, 12).mean().item<double>(), 0.27, 0.05);
}

TEST(Losses, PlaneEntropyIsZeroOnOnePlaneOneWhenSpreadAndFallsAlongItsGradient) {
  const int64_t D = 16;
  auto one_plane = torch::zeros({1, D, 2, 3});
  one_plane.select(1, 5).fill_(1.0);
  EXPECT_NEAR(normalized_plane_entropy(one_plane).abs().max().item<double>(), 0.0, 1e-6);
  EXPECT_NEAR(normalized_plane_entropy(torch::full({1, D, 2, 3}, 1.0 / D)).min().item<double>(), 1.0, 1e-5);
  // Two planes of equal mass: log 2 / log D.
  auto two_planes = torch::zeros({1, D, 1, 1});
  two_planes.index_put_({0, torch::tensor({3, 9}), 0, 0}, 0.5);
  EXPECT_NEAR(normalized_plane_entropy(two_planes).item<double>(), std::log(2.0) / std::log(16.0), 1e-6);
  // A step down its gradient (on the network's scores before the softmax) sharpens the peak it has.
  torch::manual_seed(3);
  auto scores = (torch::randn({1, D, 4, 4}) * 0.5).requires_grad_(true);
  const auto prob = torch::softmax(scores, 1);
  const auto entropy = normalized_plane_entropy(prob);
  entropy.sum().backward();
  const auto stepped = torch::softmax(scores.detach() - 20.0 * scores.grad(), 1);
  EXPECT_LT(normalized_plane_entropy(stepped).mean().item<double>(), entropy.mean().item<double>() - 0.02);
  EXPECT_TRUE(torch::equal(stepped.argmax(1), prob.detach().argmax(1))) << "sharpening keeps each pixel's most likely plane";
  EXPECT_THROW(normalized_plane_entropy(torch::ones({4, 4})), c10::Error);
}

TEST(Losses, PlaneLossesAreLowestOnTheTruePlaneAndTeachTheVolumeWhereItIs) {
  // The background plane at z = 3 seen by four neighbours; 17 planes from 2 to 4 m, 3 m the 9th.
  const auto in = make_inputs(PlaneScene{}, kFourNeighbours);
  const auto depth_values = torch::linspace(2.0, 4.0, 17).unsqueeze(0);
  LossConfig cfg;
  const PlaneLosses planes = plane_photometric_losses(in.ref, in.src, in.K_ref, in.K_src, in.T, depth_values, cfg);
  ASSERT_EQ(planes.loss.sizes(), (std::vector<int64_t>{1, 17, kH, kW}));
  EXPECT_FALSE(planes.loss.requires_grad());
  // Where every plane is judged, the true plane wins at nearly every pixel, and matches the
  // robust loss of the true depth map there.
  const auto judged = std::get<0>(planes.valid.min(1)) > 0.5;
  ASSERT_GT(judged.sum().item<int64_t>(), kW * kH / 3);
  const auto best = std::get<1>(planes.loss.min(1));
  EXPECT_GT((best == 8).masked_select(judged).to(torch::kFloat).mean().item<double>(), 0.95);
  EXPECT_LT(planes.loss.select(1, 8).masked_select(judged).mean().item<double>(), 0.006);
  // The expected loss: all mass on the true plane < spread evenly < all on a wrong plane.
  auto one_hot = [&](int64_t d) { return torch::one_hot(torch::full({1, kH, kW}, d, torch::kLong), 17).permute({0, 3, 1, 2}).to(torch::kFloat); };
  const double on_true = expected_plane_loss(one_hot(8), planes).item<double>();
  const double spread = expected_plane_loss(torch::full({1, 17, kH, kW}, 1.0 / 17), planes).item<double>();
  const double on_wrong = expected_plane_loss(one_hot(3), planes).item<double>();
  EXPECT_LT(on_true, 0.5 * spread);
  EXPECT_LT(spread, on_wrong);
  // A step down its gradient moves probability to the true plane.
  auto scores = torch::zeros({1, 17, kH, kW}).requires_grad_(true);
  expected_plane_loss(torch::softmax(scores, 1), planes).backward();
  const auto stepped = torch::softmax(scores.detach() - 5.0 * scores.grad() / scores.grad().abs().max(), 1);
  EXPECT_GT(stepped.select(1, 8).masked_select(judged).mean().item<double>(), 2.0 / 17);
  EXPECT_THROW(expected_plane_loss(torch::ones({1, 16, kH, kW}), planes), c10::Error);
}

TEST(Losses, PresetsAndValidation) {
  const auto p = LossConfig::paper();
  EXPECT_DOUBLE_EQ(p.alpha, 0.8);
  EXPECT_DOUBLE_EQ(p.beta, 0.2);
  EXPECT_DOUBLE_EQ(p.gamma, 0.0067);
  const auto a = LossConfig::authors_code();
  EXPECT_DOUBLE_EQ(a.alpha, 12.0);
  EXPECT_TRUE(a.normalize_images);
  // The authors' preset is invariant to a global gain and bias of one view (normalised inputs).
  const auto in = make_inputs(PlaneScene{}, kFourNeighbours);
  auto lit = in;
  lit.src = in.src.clone();
  lit.src.select(1, 0).mul_(0.7).add_(0.1);
  const double base = loss_at(in, in.depth_gt, a).photometric.item<double>();
  EXPECT_NEAR(loss_at(lit, in.depth_gt, a).photometric.item<double>(), base, 0.2 * base + 1e-3);
  // ... while the naive loss is not.
  LossConfig naive;
  naive.term = PhotometricTerm::kNaive;
  naive.top_k = 0;
  EXPECT_GT(loss_at(lit, in.depth_gt, naive).photometric.item<double>(),
            3 * loss_at(in, in.depth_gt, naive).photometric.item<double>());
  LossConfig bad;
  bad.top_k = -1;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad = LossConfig{};
  bad.alpha = NAN;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace umvs
