// Supervised training on rendered depth and mixed runs (core/losses.h supervised_depth_loss,
// core/training.h Trainer, io/training_data.h MixedSampler), input normalisation and exposure.
// Self-training: test_self_training.cpp; the shipped model: test_default_model.cpp.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>

#include "training_test_fixtures.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/losses.h"
#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/training_data.h"

namespace umvs {
namespace {

using test::room_tuples;
using test::write_room;

TEST(SupervisedLoss, CountsErrorsInDepthIntervalsForBothSamplings) {
  // An estimate k planes away from the truth costs smooth L1 of k: k - 0.5 beyond one interval,
  // k^2 / 2 within it, whatever the sampling and the scene's scale.
  for (auto sampling : {DepthSampling::kUniformDepth, DepthSampling::kUniformInverseDepth}) {
    for (double scale : {0.01, 1.0, 50.0}) {
      const auto planes = depth_hypotheses(0.5 * scale, 8.0 * scale, 32, sampling).to(torch::kFloat64);
      const auto depth_values = planes.unsqueeze(0);
      const auto gt = planes.slice(0, 4, 20).view({1, 4, 4});
      const auto two_away = planes.slice(0, 6, 22).view({1, 4, 4});
      // (hypotheses are float32: 1e-6)
      EXPECT_NEAR(supervised_depth_loss(two_away, gt, depth_values, sampling).item<double>(), 1.5, 1e-6)
          << to_string(sampling) << " scale " << scale;
      const auto half_way = (planes.slice(0, 4, 20) + 0.5 * (planes.slice(0, 5, 21) - planes.slice(0, 4, 20)));
      if (sampling == DepthSampling::kUniformDepth) {  // half an interval in depth is half a plane
        EXPECT_NEAR(supervised_depth_loss(half_way.view({1, 4, 4}), gt, depth_values, sampling).item<double>(),
                    0.125, 1e-6);
      }
      EXPECT_NEAR(supervised_depth_loss(gt.clone(), gt, depth_values, sampling).item<double>(), 0.0, 1e-12);
    }
  }
}

TEST(SupervisedLoss, IgnoresPixelsWithoutGroundTruth) {
  const auto planes = depth_hypotheses(1.0, 5.0, 16, DepthSampling::kUniformDepth).to(torch::kFloat64);
  auto gt = torch::full({1, 3, 3}, 2.0, torch::kFloat64);
  auto est = torch::full({1, 3, 3}, 2.0, torch::kFloat64);
  gt[0][1][1] = 0.0;  // unknown
  est[0][1][1] = 4.9;  // far off, but unknown there
  EXPECT_NEAR(supervised_depth_loss(est, gt, planes.unsqueeze(0), DepthSampling::kUniformDepth).item<double>(), 0.0,
              1e-12);
  gt.zero_();  // no ground truth at all: zero, and still differentiable
  auto e = est.clone().requires_grad_(true);
  auto l = supervised_depth_loss(e, gt, planes.unsqueeze(0), DepthSampling::kUniformDepth);
  l.backward();
  EXPECT_EQ(l.item<double>(), 0.0);
  EXPECT_EQ(e.grad().abs().sum().item<double>(), 0.0);
}

TEST(SupervisedLoss, GradientMatchesFiniteDifferences) {
  torch::manual_seed(5);
  for (auto sampling : {DepthSampling::kUniformDepth, DepthSampling::kUniformInverseDepth}) {
    const auto depth_values = depth_hypotheses(0.4, 6.0, 24, sampling).to(torch::kFloat64).unsqueeze(0);
    auto gt = torch::rand({1, 5, 6}, torch::kFloat64) * 4.0 + 1.0;
    gt[0][2][3] = 0.0;  // one pixel without ground truth
    // Errors of 0.1-0.8 or 1.3-3 intervals: both branches of smooth L1, away from its kink at 1.
    auto offset = torch::rand({1, 5, 6}, torch::kFloat64) * 0.7 + 0.1;
    offset = torch::where(torch::rand({1, 5, 6}) > 0.5, offset, offset * 2.4 + 1.06);
    offset = torch::where(torch::rand({1, 5, 6}) > 0.5, offset, -offset);
    const auto gt_index = depth_to_plane_index(gt.clamp_min(1.0), depth_values, sampling);
    // The estimate at gt_index + offset, mapped back to depth through the sampling.
    const double first = depth_values[0][0].item<double>(), last = depth_values[0][23].item<double>();
    const auto f = (gt_index + offset) / 23.0;
    const auto est = sampling == DepthSampling::kUniformDepth ? first + f * (last - first)
                                                               : 1.0 / (1.0 / first + f * (1.0 / last - 1.0 / first));
    auto x = est.clone().requires_grad_(true);
    supervised_depth_loss(x, gt, depth_values, sampling).backward();
    const auto analytic = x.grad().clone();
    const double h = 1e-7;
    double worst = 0;
    for (int64_t i = 0; i < est.numel(); ++i) {
      auto plus = est.clone(), minus = est.clone();
      plus.view(-1)[i] += h;
      minus.view(-1)[i] -= h;
      const double numeric = (supervised_depth_loss(plus, gt, depth_values, sampling).item<double>() -
                              supervised_depth_loss(minus, gt, depth_values, sampling).item<double>()) /
                             (2 * h);
      worst = std::max(worst, std::abs(numeric - analytic.view(-1)[i].item<double>()));
    }
    EXPECT_LT(worst, 1e-6) << to_string(sampling);
    EXPECT_EQ(analytic[0][2][3].item<double>(), 0.0) << "a pixel without ground truth got a gradient";
    EXPECT_GT(analytic.abs().max().item<double>(), 1e-3);
  }
}

TEST(SupervisedLoss, SupervisedFolderWithoutGroundTruthIsRefusedByName) {
  const std::string dir = write_room("sup_no_gt", 3, /*keep_ground_truth=*/false);
  TupleConfig cfg = room_tuples(4);
  cfg.supervised = true;
  EXPECT_THAT([&] { MvsFolderSource source({dir}, cfg); },
              testing::ThrowsMessage<std::runtime_error>(testing::AllOf(testing::HasSubstr("depth_gt"), testing::HasSubstr(dir))));
}

TEST(MixedTraining, LearnsOnRenderedAndRealKindsInOneRun) {
  // Rendered tuples (ground truth, supervised) and "real" tuples (no ground truth: photometric)
  // in one optimisation: both losses fall on fixed tuples of each kind.
  const std::string rendered = write_room("mixed_rendered", 11, true);
  const std::string real = write_room("mixed_real", 12, false);
  TupleConfig cfg;
  cfg.views_in = 3;
  cfg.views_loss = 4;
  cfg.width = 64;
  cfg.height = 64;
  cfg.max_zoom = 1.0;
  TupleConfig sup_cfg = cfg;
  sup_cfg.supervised = true;
  MvsFolderSource rendered_source({rendered}, sup_cfg), real_source({real}, cfg);
  MixedSampler sampler(rendered_source, &real_source, 0.5, 7);

  torch::manual_seed(1);
  MvsNetConfig mcfg;
  mcfg.num_depth = 16;
  mcfg.input_normalization = InputNormalization::kPerImageChannel;
  TrainerConfig tcfg;
  tcfg.num_depth = 16;
  tcfg.loss.top_k = 2;
  tcfg.supervised_weight = 0.1;
  Trainer trainer(MvsNet(mcfg), torch::kCPU, tcfg);

  const auto sup_fixed = rendered_source.tuple(0, nullptr), real_fixed = real_source.tuple(0, nullptr);
  ASSERT_TRUE(sup_fixed.supervised);
  ASSERT_FALSE(real_fixed.supervised);
  auto supervised_error = [&] {
    torch::NoGradGuard no_grad;
    trainer.model()->eval();
    const auto b = make_training_batch({sup_fixed}, 16, DepthSampling::kUniformDepth, torch::kCPU);
    const auto out = trainer.model()->forward(b.images, b.proj, b.depth_values);
    trainer.model()->train();
    return supervised_depth_loss(out.depth, b.depth_gt, b.depth_values, DepthSampling::kUniformDepth).item<double>();
  };
  auto photometric = [&] { return trainer.evaluate({real_fixed}).loss.total; };
  const double sup0 = supervised_error(), photo0 = photometric();
  int supervised_steps = 0, photometric_steps = 0;
  for (int i = 0; i < 60; ++i) {
    const auto t = sampler.next(false);
    (t.supervised ? supervised_steps : photometric_steps)++;
    const auto v = trainer.step({t});
    ASSERT_TRUE(std::isfinite(v.total));
    if (t.supervised) {
      EXPECT_GT(v.supervised, 0.0);
      EXPECT_EQ(v.photometric, 0.0);
    }
  }
  EXPECT_GT(supervised_steps, 15);
  EXPECT_GT(photometric_steps, 15);
  const double sup1 = supervised_error(), photo1 = photometric();
  EXPECT_LT(sup1, 0.7 * sup0) << "supervised error " << sup0 << " -> " << sup1;
  EXPECT_LT(photo1, 0.95 * photo0) << "photometric loss " << photo0 << " -> " << photo1;
}

TEST(MixedTraining, SamplerStateResumesExactly) {
  const std::string rendered = write_room("mixed_state_rendered", 21, true);
  const std::string real = write_room("mixed_state_real", 22, false);
  TupleConfig cfg;
  cfg.views_loss = 4;
  cfg.width = 64;
  cfg.height = 64;
  TupleConfig sup_cfg = cfg;
  sup_cfg.supervised = true;
  MvsFolderSource a({rendered}, sup_cfg), b({real}, cfg);
  MixedSampler sampler(a, &b, 0.3, 9), resumed(a, &b, 0.3, 1234);
  for (int i = 0; i < 7; ++i) sampler.next(true);
  resumed.set_state(sampler.state());
  for (int i = 0; i < 10; ++i) {
    const auto x = sampler.next(true), y = resumed.next(true);
    EXPECT_EQ(x.name, y.name);
    EXPECT_EQ(x.supervised, y.supervised);
    EXPECT_TRUE(torch::equal(x.network_views[0].image, y.network_views[0].image));
  }
  EXPECT_THROW(resumed.set_state("garbage"), std::runtime_error);
}

TEST(InputNormalization, MakesTheNetworkBlindToExposureGainAndWhiteBalance) {
  // Trained weights on a rendered room, and the same room at 0.3x exposure with a colour cast:
  // the same depth with per-image normalisation, a clearly different one without it.
  const std::string dir = write_room("normalisation", 71, true);
  TupleConfig cfg = room_tuples(2);
  const auto t = MvsFolderSource({dir}, cfg).tuple(0, nullptr);
  const auto b = make_training_batch({t}, 32, DepthSampling::kUniformDepth, torch::kCPU);
  const auto cast = b.images * torch::tensor({0.3, 0.25, 0.35}).view({1, 1, 3, 1, 1});
  const auto trained = load_model(std::string(UMVS_SOURCE_DIR) + "/models/unsup_mvsnet.pt", torch::kCPU).model;
  for (auto n : {InputNormalization::kPerImageChannel, InputNormalization::kNone}) {
    MvsNetConfig mcfg = trained->config();
    mcfg.input_normalization = n;
    MvsNet net(mcfg);
    {
      torch::NoGradGuard no_grad;
      auto dst = net->named_parameters(), dst_buffers = net->named_buffers();
      for (const auto& p : trained->named_parameters()) dst[p.key()].copy_(p.value());
      for (const auto& p : trained->named_buffers()) dst_buffers[p.key()].copy_(p.value());
    }
    net->eval();
    torch::NoGradGuard no_grad;
    const auto a = net->forward(b.images, b.proj, b.depth_values).depth;
    const auto c = net->forward(cast, b.proj, b.depth_values).depth;
    const double median_rel = ((a - c).abs() / a).median().item<double>();
    if (n == InputNormalization::kPerImageChannel) {
      EXPECT_LT(median_rel, 1e-3) << to_string(n);
    } else {
      EXPECT_GT(median_rel, 1e-2) << to_string(n) << ": the check cannot tell the two apart";
    }
  }
}

TEST(InputNormalization, NamesRoundTripAndBadNamesAreRefused) {
  for (auto n : {InputNormalization::kNone, InputNormalization::kPerImageChannel}) {
    EXPECT_EQ(input_normalization_from_string(to_string(n)), n);
  }
  EXPECT_THROW(input_normalization_from_string("zscore"), std::invalid_argument);
}

TEST(ExposureAugmentation, DarkensWholeTuplesWithinTheGainRange) {
  const std::string dir = write_room("exposure", 31, true);
  TupleConfig cfg = room_tuples(4);
  cfg.max_zoom = 1.0;
  cfg.jitter = 0.0;
  MvsFolderSource plain({dir}, cfg);
  cfg.min_gain = 0.3;
  cfg.max_gain = 0.5;
  MvsFolderSource dark({dir}, cfg);
  std::mt19937_64 rng_a(1), rng_b(1);
  for (size_t i = 0; i < 3; ++i) {
    const auto p = plain.tuple(i, &rng_a), d = dark.tuple(i, &rng_b);
    const double ratio = d.network_views[0].image.to(torch::kFloat64).mean().item<double>() /
                         p.network_views[0].image.to(torch::kFloat64).mean().item<double>();
    EXPECT_GT(ratio, 0.28);
    EXPECT_LT(ratio, 0.52);
    // One gain for the whole tuple.
    const double ratio_src = d.loss_views[1].image.to(torch::kFloat64).mean().item<double>() /
                             p.loss_views[1].image.to(torch::kFloat64).mean().item<double>();
    EXPECT_NEAR(ratio, ratio_src, 0.02);
  }
  cfg.min_gain = 0.0;
  EXPECT_THROW(cfg.validate(), std::invalid_argument);
}

}  // namespace
}  // namespace umvs
