// Self-training on a robot's unlabelled images (core/training.h pseudo_labelled_tuples,
// reference_depths, seen_by_loss_views): the pseudo-labels and their anchors, and `umvs train
// --self-training-every`, which reads no ground truth and resumes within a round exactly.
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

std::string file_text(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

// The options recorded in run folder `out` (its run_config.json).
RunOptions recorded(const std::string& out) { return read_run_record(out).value().options; }

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

TEST(SelfTraining, AnchoredRunKeepsItsStartModelAndResumesWithinARoundExactly) {
  const std::string data = write_room("anchored_run", 52, false);
  const std::string out = test::temp_dir("anchored_run_out");  // fresh and empty
  const std::string log = out + "/umvs.log";  // inside the scratch folder, so that it goes with it
  const std::string common = " --data " + data + " --init " + default_model() +
                             " --width 64 --height 64 --num-depth 16 --views-loss 4 --top-k 2"
                             " --save-every 2 --threads 1 --seed 3";
  const std::string anchored = "--self-training-every 3";  // anchored by default
  const auto train = [&](const std::string& args) {
    return std::system((test::umvs_binary() + " train" + common + " " + args + " > " + log + " 2>&1").c_str());
  };
  ASSERT_EQ(train(anchored + " --steps 4 --out " + out + "/whole"), 0) << file_text(log);
  EXPECT_NE(file_text(log).find("anchored self-training"), std::string::npos) << file_text(log);
  // Stopped at step 2, inside the round that began at step 0, and resumed: the anchors come from
  // anchor.pt, and the run ends where the uninterrupted one did.
  ASSERT_EQ(train(anchored + " --steps 2 --out " + out + "/resumed"), 0) << file_text(log);
  ASSERT_EQ(train(anchored + " --steps 4 --resume --out " + out + "/resumed"), 0) << file_text(log);
  // Each round says what the unconfirmed pixels get, and how to leave them free.
  EXPECT_NE(file_text(log).find("keep the start model's depth (anchored; --anchor-unconfirmed 0"), std::string::npos)
      << file_text(log);
  ASSERT_EQ(train("--self-training-every 3 --anchor-unconfirmed 0 --steps 4 --out " + out + "/plain"), 0)
      << file_text(log);
  EXPECT_EQ(file_text(log).find("keep the start model's depth"), std::string::npos) << file_text(log);
  const auto whole = load_model(out + "/whole/last.pt", torch::kCPU).model;
  const auto resumed = load_model(out + "/resumed/last.pt", torch::kCPU).model;
  const auto plain = load_model(out + "/plain/last.pt", torch::kCPU).model;
  const auto anchor = load_model(out + "/whole/anchor.pt", torch::kCPU).model;
  const auto init = load_model(default_model(), torch::kCPU).model;
  auto pr = resumed->named_parameters(), pp = plain->named_parameters(), pa = anchor->named_parameters();
  double plain_differs = 0;
  for (const auto& p : whole->named_parameters()) {
    EXPECT_TRUE(torch::equal(p.value(), pr[p.key()])) << p.key();
    plain_differs += (p.value() - pp[p.key()]).abs().sum().item<double>();
  }
  EXPECT_GT(plain_differs, 0.0) << "the anchors changed nothing";
  for (const auto& p : init->named_parameters()) EXPECT_TRUE(torch::equal(p.value(), pa[p.key()])) << p.key();
  EXPECT_FALSE(std::filesystem::exists(out + "/plain/anchor.pt"));
  // Recorded as what the run does: anchored or not (not for plain self-training, nor for runs
  // without self-training), and the anchors' confidence floor (0.5 by default; 0 when not anchored).
  EXPECT_EQ(recorded(out + "/whole").at("anchor-unconfirmed"), true);
  EXPECT_EQ(recorded(out + "/plain").at("anchor-unconfirmed"), false);
  EXPECT_EQ(recorded(out + "/whole").at("anchor-min-confidence"), 0.5);
  EXPECT_EQ(recorded(out + "/plain").at("anchor-min-confidence"), 0.0);
  // So a plain run (or a run of an older version, upgraded alike) resumes as it was made, and the
  // default does not turn it into an anchored one unasked.
  EXPECT_NE(train("--self-training-every 3 --steps 6 --resume --out " + out + "/plain"), 0);
  EXPECT_NE(file_text(log).find("--anchor-unconfirmed: the run in this folder has '0', now '1'"), std::string::npos)
      << file_text(log);
  // One refusal names every option that differs (the default floor comes with the default anchoring).
  EXPECT_NE(file_text(log).find("--anchor-min-confidence: the run in this folder has '0', now '0.5'; "
                                "--anchor-unconfirmed"),
            std::string::npos)
      << file_text(log);
  EXPECT_EQ(train("--self-training-every 3 --anchor-unconfirmed 0 --steps 6 --resume --out " + out + "/plain"), 0)
      << file_text(log);
  // A run that replaces it in its folder takes its anchor (and its round's labeller) away.
  ASSERT_EQ(train("--steps 1 --overwrite --out " + out + "/whole"), 0) << file_text(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/whole/anchor.pt"));
  EXPECT_FALSE(std::filesystem::exists(out + "/whole/round_start.pt"));
  EXPECT_EQ(recorded(out + "/whole").at("anchor-unconfirmed"), false);
  // Without self-training there is nothing to anchor; a resume that lost anchor.pt is refused.
  EXPECT_NE(train("--anchor-unconfirmed 1 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_text(log).find("--self-training-every"), std::string::npos) << file_text(log);
  EXPECT_NE(train(anchored + " --anchor-unconfirmed 2 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_text(log).find("--anchor-unconfirmed must be 0 or 1"), std::string::npos)
      << file_text(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/refused"));
  // A confidence floor for the anchors: only with anchoring, within [0, 1], recorded when above 0.
  EXPECT_NE(train("--self-training-every 3 --anchor-unconfirmed 0 --anchor-min-confidence 0.5 --steps 2 --out " + out +
                  "/refused"),
            0);
  EXPECT_NE(file_text(log).find("--anchor-min-confidence chooses"), std::string::npos) << file_text(log);
  EXPECT_NE(train(anchored + " --anchor-min-confidence 1.5 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_text(log).find("--anchor-min-confidence must be in [0, 1]"), std::string::npos)
      << file_text(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/refused"));
  ASSERT_EQ(train(anchored + " --anchor-min-confidence 0.7 --steps 1 --out " + out + "/confident"), 0)
      << file_text(log);
  EXPECT_NE(file_text(log).find("where its confidence is at least 0.7"), std::string::npos)
      << file_text(log);
  EXPECT_EQ(recorded(out + "/confident").at("anchor-min-confidence"), 0.7);
  EXPECT_EQ(recorded(out + "/whole").at("anchor-min-confidence"), 0.0)
      << "a run without self-training has no anchors to floor";
  // --anchor-unseen adds to a floor's anchors: refused without one, recorded as on only with one.
  EXPECT_NE(train(anchored + " --anchor-min-confidence 0 --anchor-unseen 1 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_text(log).find("--anchor-unseen adds pixels"), std::string::npos) << file_text(log);
  EXPECT_NE(train(anchored + " --anchor-unseen 2 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_text(log).find("--anchor-unseen must be 0 or 1"), std::string::npos) << file_text(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/refused"));
  ASSERT_EQ(train(anchored + " --anchor-unseen 1 --steps 1 --out " + out + "/unseen"), 0) << file_text(log);
  EXPECT_NE(file_text(log).find("where its confidence is at least 0.5 or no loss view sees them"), std::string::npos)
      << file_text(log);
  EXPECT_EQ(recorded(out + "/unseen").at("anchor-unseen"), true);
  EXPECT_EQ(recorded(out + "/confident").at("anchor-unseen"), false);
  // An anchored run without a recorded floor (0, as every anchored run before the 0.5 default)
  // resumed without the option continues with its own floor and ends where it would have.
  const std::string every_pixel = anchored + " --anchor-min-confidence 0";
  ASSERT_EQ(train(every_pixel + " --steps 4 --out " + out + "/every_whole"), 0) << file_text(log);
  EXPECT_EQ(recorded(out + "/every_whole").at("anchor-min-confidence"), 0.0);
  ASSERT_EQ(train(every_pixel + " --steps 2 --out " + out + "/every_resumed"), 0) << file_text(log);
  EXPECT_NE(train(anchored + " --anchor-min-confidence 0.5 --steps 4 --resume --out " + out + "/every_resumed"), 0)
      << "a floor the run was not made with is refused";
  EXPECT_NE(file_text(log).find("--anchor-min-confidence: the run in this folder has '0', now '0.5'"),
            std::string::npos)
      << file_text(log);
  ASSERT_EQ(train(anchored + " --steps 4 --resume --out " + out + "/every_resumed"), 0) << file_text(log);
  EXPECT_NE(file_text(log).find("anchors every unconfirmed pixel"), std::string::npos) << file_text(log);
  const auto every_whole = load_model(out + "/every_whole/last.pt", torch::kCPU).model;
  auto every_resumed = load_model(out + "/every_resumed/last.pt", torch::kCPU).model->named_parameters();
  for (const auto& p : every_whole->named_parameters()) {
    EXPECT_TRUE(torch::equal(p.value(), every_resumed[p.key()])) << p.key();
  }
  ASSERT_EQ(train(anchored + " --steps 2 --out " + out + "/lost"), 0) << file_text(log);
  std::filesystem::remove(out + "/lost/anchor.pt");
  EXPECT_NE(train(anchored + " --steps 4 --resume --out " + out + "/lost"), 0);
  EXPECT_NE(file_text(log).find("anchor.pt"), std::string::npos) << file_text(log);
}

TEST(SelfTraining, UmvsTrainReadsNoGroundTruth) {
  // The same self-training run on a folder with depth_gt/ and on a copy without gives the same
  // weights: nothing in it reads ground truth.
  const std::string with_gt = write_room("self_train_gt", 51, true);
  const std::string without = test::temp_dir("self_train_no_gt");
  std::filesystem::remove_all(without);
  std::filesystem::copy(with_gt, without, std::filesystem::copy_options::recursive);
  std::filesystem::remove_all(without + "/depth_gt");
  const std::string common = " --init " + default_model() +
                             " --width 64 --height 64 --num-depth 16 --views-loss 4 --top-k 2 --steps 4"
                             " --self-training-every 2 --save-every 2 --threads 1 --seed 3";
  const std::string out_a = test::temp_dir("self_train_run_a"), out_b = test::temp_dir("self_train_run_b");
  std::filesystem::remove_all(out_a);
  std::filesystem::remove_all(out_b);
  const std::string log_a = test::temp_dir("self_train_logs") + "/run_a.log";
  ASSERT_EQ(std::system((test::umvs_binary() + " train --data " + with_gt + " --out " + out_a + common + " > " +
                         log_a + " 2>&1").c_str()),
            0)
      << file_text(log_a);
  ASSERT_EQ(std::system((test::umvs_binary() + " train --data " + without + " --out " + out_b + common +
                         " > /dev/null 2>&1").c_str()),
            0);
  EXPECT_NE(file_text(log_a).find("self-training round at step 2"), std::string::npos) << file_text(log_a);
  const auto a = load_model(out_a + "/last.pt", torch::kCPU).model, b = load_model(out_b + "/last.pt", torch::kCPU).model;
  const auto pa = a->named_parameters(), pb = b->named_parameters();
  for (const auto& p : pa) EXPECT_TRUE(torch::equal(p.value(), pb[p.key()])) << p.key();
  // And it did train: the weights moved away from the initial model.
  const auto init = load_model(default_model(), torch::kCPU).model;
  double moved = 0;
  for (const auto& p : init->named_parameters()) moved += (p.value() - pa[p.key()]).abs().sum().item<double>();
  EXPECT_GT(moved, 0.0);
  // The training images' own ground truth cannot be combined with self-training ...
  const std::string log_c = test::temp_dir("self_train_logs") + "/run_c.log";
  EXPECT_NE(std::system((test::umvs_binary() + " train --data " + with_gt + " --loss supervised --out " +
                         test::temp_dir("self_train_refused") + common + " > " + log_c + " 2>&1").c_str()),
            0);
  EXPECT_NE(file_text(log_c).find("reads no ground truth of the training images"), std::string::npos)
      << file_text(log_c);
  // ... but rendered scenes with exact depth share the labelled draws with the model's own labels
  // (rehearsal), and change what it learns.
  const std::string out_c = test::temp_dir("self_train_run_c");
  std::filesystem::remove_all(out_c);
  ASSERT_EQ(std::system((test::umvs_binary() + " train --data " + without + " --supervised-data " + with_gt +
                         " --supervised-share 0.9 --out " + out_c + common + " > " + log_c + " 2>&1").c_str()),
            0)
      << file_text(log_c);
  EXPECT_NE(file_text(log_c).find("self-training labels drawn with: 6 pseudo-labelled training tuples and 6 tuples from 1 folder(s), supervised"),
            std::string::npos)
      << file_text(log_c);
  const auto c = load_model(out_c + "/last.pt", torch::kCPU).model;
  double rehearsal_differs = 0;
  for (const auto& p : c->named_parameters()) rehearsal_differs += (p.value() - pb[p.key()]).abs().sum().item<double>();
  EXPECT_GT(rehearsal_differs, 0.0);
}

}  // namespace
}  // namespace umvs
