// `umvs train --self-training-every` on a robot's unlabelled images: it reads no ground truth,
// keeps its start model's depth where no view confirms (anchored), and resumes within a round
// exactly. The pseudo-labels themselves: test_self_training.cpp.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "cli_test_util.h"
#include "training_test_fixtures.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/training_data.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {
namespace {

using test::default_model;
using test::file_bytes;
using test::write_room;

using test::recorded;

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
  ASSERT_EQ(train(anchored + " --steps 4 --out " + out + "/whole"), 0) << file_bytes(log);
  EXPECT_NE(file_bytes(log).find("anchored self-training"), std::string::npos) << file_bytes(log);
  // Stopped at step 2, inside the round that began at step 0, and resumed: the anchors come from
  // anchor.pt, and the run ends where the uninterrupted one did.
  ASSERT_EQ(train(anchored + " --steps 2 --out " + out + "/resumed"), 0) << file_bytes(log);
  ASSERT_EQ(train(anchored + " --steps 4 --resume --out " + out + "/resumed"), 0) << file_bytes(log);
  // Each round says what the unconfirmed pixels get, and how to leave them free.
  EXPECT_NE(file_bytes(log).find("keep the start model's depth (anchored; --anchor-unconfirmed 0"), std::string::npos)
      << file_bytes(log);
  ASSERT_EQ(train("--self-training-every 3 --anchor-unconfirmed 0 --steps 4 --out " + out + "/plain"), 0)
      << file_bytes(log);
  EXPECT_EQ(file_bytes(log).find("keep the start model's depth"), std::string::npos) << file_bytes(log);
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
  EXPECT_NE(file_bytes(log).find("--anchor-unconfirmed: the run in this folder has '0', now '1'"), std::string::npos)
      << file_bytes(log);
  // One refusal names every option that differs (the default floor comes with the default anchoring).
  EXPECT_NE(file_bytes(log).find("--anchor-min-confidence: the run in this folder has '0', now '0.5'; "
                                "--anchor-unconfirmed"),
            std::string::npos)
      << file_bytes(log);
  EXPECT_EQ(train("--self-training-every 3 --anchor-unconfirmed 0 --steps 6 --resume --out " + out + "/plain"), 0)
      << file_bytes(log);
  // A run that replaces it in its folder takes its anchor (and its round's labeller) away.
  ASSERT_EQ(train("--steps 1 --overwrite --out " + out + "/whole"), 0) << file_bytes(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/whole/anchor.pt"));
  EXPECT_FALSE(std::filesystem::exists(out + "/whole/round_start.pt"));
  EXPECT_EQ(recorded(out + "/whole").at("anchor-unconfirmed"), false);
  // Without self-training there is nothing to anchor; a resume that lost anchor.pt is refused.
  EXPECT_NE(train("--anchor-unconfirmed 1 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_bytes(log).find("--self-training-every"), std::string::npos) << file_bytes(log);
  EXPECT_NE(train(anchored + " --anchor-unconfirmed 2 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_bytes(log).find("--anchor-unconfirmed must be 0 or 1"), std::string::npos)
      << file_bytes(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/refused"));
  // A confidence floor for the anchors: only with anchoring, within [0, 1], recorded when above 0.
  EXPECT_NE(train("--self-training-every 3 --anchor-unconfirmed 0 --anchor-min-confidence 0.5 --steps 2 --out " + out +
                  "/refused"),
            0);
  EXPECT_NE(file_bytes(log).find("--anchor-min-confidence chooses"), std::string::npos) << file_bytes(log);
  EXPECT_NE(train(anchored + " --anchor-min-confidence 1.5 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_bytes(log).find("--anchor-min-confidence must be in [0, 1]"), std::string::npos)
      << file_bytes(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/refused"));
  ASSERT_EQ(train(anchored + " --anchor-min-confidence 0.7 --steps 1 --out " + out + "/confident"), 0)
      << file_bytes(log);
  EXPECT_NE(file_bytes(log).find("where its confidence is at least 0.7"), std::string::npos)
      << file_bytes(log);
  EXPECT_EQ(recorded(out + "/confident").at("anchor-min-confidence"), 0.7);
  EXPECT_EQ(recorded(out + "/whole").at("anchor-min-confidence"), 0.0)
      << "a run without self-training has no anchors to floor";
  // --anchor-unseen adds to a floor's anchors: refused without one, recorded as on only with one.
  EXPECT_NE(train(anchored + " --anchor-min-confidence 0 --anchor-unseen 1 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_bytes(log).find("--anchor-unseen adds pixels"), std::string::npos) << file_bytes(log);
  EXPECT_NE(train(anchored + " --anchor-unseen 2 --steps 2 --out " + out + "/refused"), 0);
  EXPECT_NE(file_bytes(log).find("--anchor-unseen must be 0 or 1"), std::string::npos) << file_bytes(log);
  EXPECT_FALSE(std::filesystem::exists(out + "/refused"));
  ASSERT_EQ(train(anchored + " --anchor-unseen 1 --steps 1 --out " + out + "/unseen"), 0) << file_bytes(log);
  EXPECT_NE(file_bytes(log).find("where its confidence is at least 0.5 or no loss view sees them"), std::string::npos)
      << file_bytes(log);
  EXPECT_EQ(recorded(out + "/unseen").at("anchor-unseen"), true);
  EXPECT_EQ(recorded(out + "/confident").at("anchor-unseen"), false);
  // An anchored run without a recorded floor (0, as every anchored run before the 0.5 default)
  // resumed without the option continues with its own floor and ends where it would have.
  const std::string every_pixel = anchored + " --anchor-min-confidence 0";
  ASSERT_EQ(train(every_pixel + " --steps 4 --out " + out + "/every_whole"), 0) << file_bytes(log);
  EXPECT_EQ(recorded(out + "/every_whole").at("anchor-min-confidence"), 0.0);
  ASSERT_EQ(train(every_pixel + " --steps 2 --out " + out + "/every_resumed"), 0) << file_bytes(log);
  EXPECT_NE(train(anchored + " --anchor-min-confidence 0.5 --steps 4 --resume --out " + out + "/every_resumed"), 0)
      << "a floor the run was not made with is refused";
  EXPECT_NE(file_bytes(log).find("--anchor-min-confidence: the run in this folder has '0', now '0.5'"),
            std::string::npos)
      << file_bytes(log);
  ASSERT_EQ(train(anchored + " --steps 4 --resume --out " + out + "/every_resumed"), 0) << file_bytes(log);
  EXPECT_NE(file_bytes(log).find("anchors every unconfirmed pixel"), std::string::npos) << file_bytes(log);
  const auto every_whole = load_model(out + "/every_whole/last.pt", torch::kCPU).model;
  auto every_resumed = load_model(out + "/every_resumed/last.pt", torch::kCPU).model->named_parameters();
  for (const auto& p : every_whole->named_parameters()) {
    EXPECT_TRUE(torch::equal(p.value(), every_resumed[p.key()])) << p.key();
  }
  ASSERT_EQ(train(anchored + " --steps 2 --out " + out + "/lost"), 0) << file_bytes(log);
  std::filesystem::remove(out + "/lost/anchor.pt");
  EXPECT_NE(train(anchored + " --steps 4 --resume --out " + out + "/lost"), 0);
  EXPECT_NE(file_bytes(log).find("anchor.pt"), std::string::npos) << file_bytes(log);
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
      << file_bytes(log_a);
  ASSERT_EQ(std::system((test::umvs_binary() + " train --data " + without + " --out " + out_b + common +
                         " > /dev/null 2>&1").c_str()),
            0);
  EXPECT_NE(file_bytes(log_a).find("self-training round at step 2"), std::string::npos) << file_bytes(log_a);
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
  EXPECT_NE(file_bytes(log_c).find("reads no ground truth of the training images"), std::string::npos)
      << file_bytes(log_c);
  // ... but rendered scenes with exact depth share the labelled draws with the model's own labels
  // (rehearsal), and change what it learns.
  const std::string out_c = test::temp_dir("self_train_run_c");
  std::filesystem::remove_all(out_c);
  ASSERT_EQ(std::system((test::umvs_binary() + " train --data " + without + " --supervised-data " + with_gt +
                         " --supervised-share 0.9 --out " + out_c + common + " > " + log_c + " 2>&1").c_str()),
            0)
      << file_bytes(log_c);
  EXPECT_NE(file_bytes(log_c).find("self-training labels drawn with: 6 pseudo-labelled training tuples and 6 tuples from 1 folder(s), supervised"),
            std::string::npos)
      << file_bytes(log_c);
  const auto c = load_model(out_c + "/last.pt", torch::kCPU).model;
  double rehearsal_differs = 0;
  for (const auto& p : c->named_parameters()) rehearsal_differs += (p.value() - pb[p.key()]).abs().sum().item<double>();
  EXPECT_GT(rehearsal_differs, 0.0);
}

}  // namespace
}  // namespace umvs
