// Training pieces (core/training.h) on synthetic scenes with exact depth (core/synth.h) written
// as MVSNet folders: trainer steps, the volume terms, the learning rate schedule and the loss
// curve (the tuples the trainer reads: test_training_data.cpp). `umvs train` and jobs/training_run.h: test_train_command.cpp.
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

TEST(Training, ABrokenBatchLeavesTheModelUntouched) {
  // A NaN weight in the first convolution makes the forward pass NaN. The step must report a
  // non-finite loss and change neither the weights nor the BatchNorm running statistics (which
  // the forward pass updates in training mode: NaN there would ruin every later evaluation).
  const std::string dir = write_scene("broken", 64, 64, 5, 3);
  TupleConfig dcfg;
  dcfg.views_in = 3;
  dcfg.views_loss = 2;
  dcfg.width = 64;
  dcfg.height = 64;
  MvsFolderSource source({dir}, dcfg);
  torch::manual_seed(0);
  MvsNetConfig mcfg;
  mcfg.num_depth = 8;
  MvsNet model(mcfg);
  TrainerConfig tcfg;
  tcfg.num_depth = 8;
  tcfg.loss.top_k = 2;
  Trainer trainer(model, torch::kCPU, tcfg);
  auto first = model->parameters()[0];
  const auto first_good = first.clone();
  {
    torch::NoGradGuard no_grad;
    first.view({-1})[0] = NAN;
  }
  std::vector<torch::Tensor> before;
  for (const auto& t : model->parameters()) before.push_back(t.clone());
  std::vector<torch::Tensor> buffers_before;
  for (const auto& t : model->buffers()) buffers_before.push_back(t.clone());
  ASSERT_FALSE(buffers_before.empty());
  const auto v = trainer.step({source.tuple(0, nullptr)});
  EXPECT_FALSE(std::isfinite(v.total));
  const auto buffers = model->buffers();
  for (size_t i = 0; i < buffers.size(); ++i) EXPECT_TRUE(torch::equal(buffers_before[i], buffers[i])) << "buffer " << i;
  const auto params = model->parameters();
  for (size_t i = 1; i < params.size(); ++i) EXPECT_TRUE(torch::equal(before[i], params[i])) << "parameter " << i;
  // Repaired, the same batch trains.
  {
    torch::NoGradGuard no_grad;
    first.copy_(first_good);
  }
  EXPECT_TRUE(std::isfinite(trainer.step({source.tuple(0, nullptr)}).total));
  EXPECT_FALSE(torch::equal(before[1], model->parameters()[1]));
}

TEST(Training, FrozenBatchNormNormalisesAsAtInferenceKeepsItsStatisticsAndStillLearns) {
  // --batchnorm frozen: a step's forward pass normalises with the running statistics (so its loss
  // is the evaluation's loss of the same tuple), leaves them unchanged, and still updates every
  // weight, BatchNorm's scale and shift included. The default ("train") does neither of the first
  // two. The shipped model: its statistics are a trained model's (a random network's frozen at
  // their initial values saturate the softmax and no gradient reaches the layers).
  const std::string dir = write_scene("frozen_bn", 96, 64, 5, 3);
  TupleConfig dcfg;
  dcfg.views_in = 3;
  dcfg.views_loss = 2;
  dcfg.width = 96;
  dcfg.height = 64;
  MvsFolderSource source({dir}, dcfg);
  const auto tuple = source.tuple(0, nullptr);
  for (const bool frozen : {false, true}) {
    SCOPED_TRACE(frozen ? "frozen" : "train");
    MvsNet model = load_model(std::string(UMVS_SOURCE_DIR) + "/models/unsup_mvsnet.pt", torch::kCPU).model;
    TrainerConfig tcfg;
    tcfg.num_depth = 16;
    tcfg.loss.top_k = 2;
    tcfg.freeze_batchnorm = frozen;
    Trainer trainer(model, torch::kCPU, tcfg);
    const double evaluated = trainer.evaluate({tuple}).loss.total;
    std::vector<torch::Tensor> buffers_before, params_before;
    for (const auto& t : model->buffers()) buffers_before.push_back(t.clone());
    for (const auto& t : model->parameters()) params_before.push_back(t.clone());
    const double stepped = trainer.step({tuple}).total;
    ASSERT_TRUE(std::isfinite(stepped));
    if (frozen) {
      EXPECT_NEAR(stepped, evaluated, 1e-5 * std::abs(evaluated));
    } else {
      EXPECT_GT(std::abs(stepped - evaluated), 1e-3 * std::abs(evaluated));
    }
    int changed_buffers = 0;
    const auto buffers = model->buffers();
    for (size_t i = 0; i < buffers.size(); ++i) changed_buffers += !torch::equal(buffers_before[i], buffers[i]);
    EXPECT_EQ(changed_buffers == 0, frozen) << changed_buffers << " of " << buffers.size() << " buffers changed";
    int changed_params = 0;
    const auto params = model->parameters();
    for (size_t i = 0; i < params.size(); ++i) changed_params += !torch::equal(params_before[i], params[i]);
    EXPECT_EQ(changed_params, static_cast<int>(params.size()));
  }
}

// A short run from random weights on one rendered room without lighting change (robust loss,
// top-K 2): the mean loss of the first and last 16 steps, and the evaluations before and after.
struct ShortRun {
  double first_loss = 0, last_loss = 0;
  Evaluation before, after;
};
ShortRun short_run_from_random_weights(const std::string& name, int width, int height, TrainerConfig tcfg, int steps) {
  const std::string dir = write_scene(name, width, height, 8, 4);
  TupleConfig dcfg;
  dcfg.views_in = 3;
  dcfg.views_loss = 4;
  dcfg.width = width;
  dcfg.height = height;
  dcfg.max_zoom = 1.0;
  dcfg.jitter = 0.0;
  MvsFolderSource source({dir}, dcfg);
  std::vector<TrainingTuple> eval_tuples;
  for (size_t i = 0; i < source.size(); ++i) eval_tuples.push_back(source.tuple(i, nullptr));
  torch::manual_seed(0);
  MvsNetConfig mcfg;
  mcfg.num_depth = tcfg.num_depth;
  tcfg.loss.top_k = 2;
  Trainer trainer(MvsNet(mcfg), torch::kCPU, tcfg);
  ShortRun run;
  // The untrained network (eval mode, as the trained one is evaluated) predicts a nearly
  // uniform distribution, i.e. depths near the middle of the range.
  run.before = trainer.evaluate(eval_tuples);
  TupleSampler sampler(source, 1);
  for (int s = 0; s < steps; ++s) {
    const auto v = trainer.step({sampler.next(false)});
    if (!std::isfinite(v.total)) throw std::runtime_error("short run: step " + std::to_string(s) + " is not finite");
    if (s < 16) run.first_loss += v.total / 16;
    if (s >= steps - 16) run.last_loss += v.total / 16;
  }
  run.after = trainer.evaluate(eval_tuples);
  std::cout << name << ": training loss " << run.first_loss << " -> " << run.last_loss << "; depth |err| "
            << run.before.depth.mean_abs << " -> " << run.after.depth.mean_abs << " m; within 1% "
            << run.before.depth.within_1pct << " -> " << run.after.depth.within_1pct << "\n";
  return run;
}

TEST(Training, ShortRunFromRandomWeightsReducesDepthError) {
  // 160x128 input, 32 planes.
  TrainerConfig tcfg;
  tcfg.num_depth = 32;
  const ShortRun run = short_run_from_random_weights("learn", 160, 128, tcfg, 150);
  ASSERT_GT(run.after.depth.pixels, 1000);
  EXPECT_LT(run.last_loss, 0.8 * run.first_loss);
  EXPECT_LT(run.after.depth.mean_abs, 0.6 * run.before.depth.mean_abs);
  EXPECT_LT(run.after.loss.photometric, run.before.loss.photometric);
}

TEST(Training, CoarseToFineRunFromRandomWeightsReducesDepthError) {
  // Both passes: the first on the images at half size with 16 planes, the map at 1/2 of the input
  // from a fine pass; the loss on both passes' depth.
  TrainerConfig tcfg;
  tcfg.num_depth = 16;
  tcfg.fine.planes = 8;
  tcfg.fine.resolution_divisor = 2;
  tcfg.fine.first_pass_downscale = 2;
  const ShortRun run = short_run_from_random_weights("learn_c2f", 192, 128, tcfg, 100);
  ASSERT_GT(run.after.depth.pixels, 4 * 1000);  // on the 96x64 grid of the map
  EXPECT_LT(run.last_loss, 0.8 * run.first_loss);
  EXPECT_LT(run.after.depth.mean_abs, 0.6 * run.before.depth.mean_abs);
  // Refused with the volume terms, which read a probability volume over the first pass's planes.
  TrainerConfig bad = tcfg;
  bad.entropy_weight = 0.01;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

// The probability volumes of the shipped model after 12 steps of fine-tuning on a small rendered
// room, the same start, data and steps whatever the loss (a random network's volumes are flat and
// barely move in a few steps), scored on the training tuples.
struct VolumeScores {
  double entropy = 0, confidence = 0;  // means of the tuples
  double plane_loss = 0;               // expected_plane_loss above its floor, mean of the tuples
  double logged_entropy = 0, logged_plane_loss = 0;    // what the last step reported
};
VolumeScores fine_tuned_volumes(double entropy_weight, double plane_loss_weight) {
  static const std::string dir = write_scene("volume_terms", 96, 64, 5, 5);
  TupleConfig dcfg;
  dcfg.views_in = 3;
  dcfg.views_loss = 2;
  dcfg.width = 96;
  dcfg.height = 64;
  dcfg.max_zoom = 1.0;
  dcfg.jitter = 0.0;
  MvsFolderSource source({dir}, dcfg);
  std::vector<TrainingTuple> tuples;
  for (size_t i = 0; i < source.size(); ++i) tuples.push_back(source.tuple(i, nullptr));
  torch::manual_seed(0);
  TrainerConfig tcfg;
  tcfg.num_depth = 16;
  tcfg.loss.top_k = 2;
  tcfg.entropy_weight = entropy_weight;
  tcfg.plane_loss_weight = plane_loss_weight;
  Trainer trainer(load_model(std::string(UMVS_SOURCE_DIR) + "/models/unsup_mvsnet.pt", torch::kCPU).model, torch::kCPU,
                  tcfg);
  VolumeScores scores;
  for (int s = 0; s < 12; ++s) {
    const auto v = trainer.step({tuples[s % tuples.size()]});
    EXPECT_TRUE(std::isfinite(v.total));
    scores.logged_entropy = v.entropy;
    scores.logged_plane_loss = v.plane_loss;
  }
  torch::NoGradGuard no_grad;
  trainer.model()->eval();
  const double n = static_cast<double>(tuples.size());
  for (const auto& t : tuples) {
    const auto b = make_training_batch({t}, 16, trainer.model()->config().depth_sampling, torch::kCPU);
    const auto out = trainer.model()->forward(b.images, b.proj, b.depth_values, /*keep_prob_volume=*/true);
    scores.entropy += normalized_plane_entropy(out.prob_volume).mean().item<double>() / n;
    scores.confidence += out.confidence.mean().item<double>() / n;
    const auto planes = plane_photometric_losses(b.loss_ref, b.loss_src, b.K_ref, b.K_src, b.T_src_ref, b.depth_values,
                                                 tcfg.loss);
    // Above its floor: all the probability on each pixel's best plane.
    const auto best = torch::one_hot(std::get<1>(planes.loss.min(1)), planes.loss.size(1)).permute({0, 3, 1, 2});
    scores.plane_loss += (expected_plane_loss(out.prob_volume, planes) -
                          expected_plane_loss(best.to(planes.loss.dtype()), planes)).item<double>() / n;
  }
  return scores;
}

TEST(Training, TheVolumeTermsTeachTheProbabilityVolumeWhatThePhotometricLossAloneDoesNot) {
  const VolumeScores paper = fine_tuned_volumes(0, 0);
  const VolumeScores entropy = fine_tuned_volumes(0.5, 0);
  const VolumeScores planes = fine_tuned_volumes(0, 3.0);
  std::cout << "entropy " << paper.entropy << " -> " << entropy.entropy << ", confidence " << paper.confidence
            << " -> " << entropy.confidence << "; expected plane loss above its floor " << paper.plane_loss << " -> "
            << planes.plane_loss << "\n";
  // Each step reports the terms it weighs, and only those.
  EXPECT_EQ(paper.logged_entropy, 0);
  EXPECT_EQ(paper.logged_plane_loss, 0);
  EXPECT_GT(entropy.logged_entropy, 0);
  EXPECT_EQ(entropy.logged_plane_loss, 0);
  EXPECT_GT(planes.logged_plane_loss, 0);
  // The entropy term makes the volumes more peaked and the network more confident.
  EXPECT_LT(entropy.entropy, paper.entropy - 0.02);
  EXPECT_GT(entropy.confidence, paper.confidence);
  // The plane term puts the probability where the views agree: a lower expected plane loss.
  EXPECT_LT(planes.plane_loss, paper.plane_loss * 0.97);
  TrainerConfig bad;
  bad.entropy_weight = -1;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
  bad.entropy_weight = 0;
  bad.plane_loss_weight = NAN;
  EXPECT_THROW(bad.validate(), std::invalid_argument);
}

TEST(Training, CosineScheduleDecaysFromLrToLrMinAndTheRunUsesIt) {
  TrainerConfig cfg;
  cfg.lr = 1e-3;
  cfg.lr_min = 1e-5;
  EXPECT_DOUBLE_EQ(learning_rate_at(cfg, 7, 100), 1e-3);  // constant by default
  cfg.lr_schedule = parse_lr_schedule("cosine");
  EXPECT_DOUBLE_EQ(learning_rate_at(cfg, 0, 101), 1e-3);
  EXPECT_NEAR(learning_rate_at(cfg, 50, 101), 0.5 * (1e-3 + 1e-5), 1e-12);  // half way: the mean
  EXPECT_NEAR(learning_rate_at(cfg, 100, 101), 1e-5, 1e-15);
  for (int s = 1; s < 101; ++s) EXPECT_LT(learning_rate_at(cfg, s, 101), learning_rate_at(cfg, s - 1, 101));
  EXPECT_THROW(parse_lr_schedule("step"), std::invalid_argument);
  cfg.lr_min = 2e-3;  // above lr
  EXPECT_THROW(cfg.validate(), std::invalid_argument);

  // The trainer applies the rate it is given: at 0 a step leaves every weight as it was.
  const std::string data = write_scene("cosine", 96, 64, 5, 2);
  TupleConfig dcfg;
  dcfg.views_in = 3;
  dcfg.views_loss = 2;
  dcfg.width = 96;
  dcfg.height = 64;
  MvsFolderSource source({data}, dcfg);
  MvsNetConfig mcfg;
  mcfg.num_depth = 8;
  TrainerConfig tcfg;
  tcfg.num_depth = 8;
  tcfg.loss.top_k = 2;
  MvsNet model(mcfg);
  Trainer trainer(model, torch::kCPU, tcfg);
  trainer.set_learning_rate(0.0);
  EXPECT_EQ(trainer.learning_rate(), 0.0);
  std::vector<torch::Tensor> before;
  for (const auto& p : model->parameters()) before.push_back(p.clone());
  ASSERT_TRUE(std::isfinite(trainer.step({source.tuple(0, nullptr)}).total));
  for (size_t i = 0; i < before.size(); ++i) EXPECT_TRUE(torch::equal(before[i], model->parameters()[i])) << i;
  trainer.set_learning_rate(1e-3);
  trainer.step({source.tuple(0, nullptr)});
  EXPECT_FALSE(torch::equal(before[0], model->parameters()[0]));

  // `umvs train --lr-schedule cosine`: the log's lr column follows the schedule.
  const std::string out = test::temp_dir("cosine_out");
  const std::string common = "--data " + data + " --width 96 --height 64 --num-depth 8 --views-loss 3 --top-k 2" +
                             " --threads 1 --lr 1e-3 --lr-schedule cosine --lr-min 0 --save-every 3";
  ASSERT_EQ(run(common + " --steps 3 --out " + out + "/run"), 0);
  const auto rows = read_csv_rows(out + "/run/train_log.csv");
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_NEAR(*train_log_row(rows[0]).lr, 1e-3, 1e-12);
  EXPECT_NEAR(*train_log_row(rows[1]).lr, 5e-4, 1e-12);
  EXPECT_NEAR(*train_log_row(rows[2]).lr, 0.0, 1e-12);
  EXPECT_NE(run(common + " --steps 3 --lr-schedule step --out " + out + "/bad"), 0);
  EXPECT_NE(run(common + " --steps 3 --lr-min 0.01 --out " + out + "/bad"), 0);
  EXPECT_FALSE(std::filesystem::exists(out + "/bad/last.pt"));
}

TEST(Training, LossCurveAndDepthErrors) {
  CurveSeries s;
  for (int i = 0; i < 100; ++i) s.x.push_back(i), s.y.push_back(1.0 / (1 + i));
  s.r = 255;
  const auto img = render_curves({s}, 200, 100);
  ASSERT_EQ(img.sizes(), (std::vector<int64_t>{100, 200, 3}));
  // Red pixels from the curve: high on the left, low on the right.
  auto red = (img.select(2, 0) == 255) & (img.select(2, 1) == 0);
  EXPECT_GT(red.sum().item<int64_t>(), 100);
  auto rows = torch::arange(100).view({100, 1}).expand({100, 200});
  const double left = rows.slice(1, 60, 80).masked_select(red.slice(1, 60, 80)).to(torch::kFloat64).mean().item<double>();
  const double right = rows.slice(1, 170, 190).masked_select(red.slice(1, 170, 190)).to(torch::kFloat64).mean().item<double>();
  EXPECT_LT(left, right);

  const auto e = depth_errors(torch::tensor({{1.0f, 2.0f, 3.0f, 5.0f}}), torch::tensor({{1.005f, 2.5f, 0.0f, 4.0f}}));
  EXPECT_EQ(e.pixels, 3);
  EXPECT_NEAR(e.mean_abs, (0.005 + 0.5 + 1.0) / 3, 1e-6);
  EXPECT_NEAR(e.within_1pct, 1.0 / 3, 1e-9);
}

}  // namespace
}  // namespace umvs
