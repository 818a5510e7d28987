// Fault injection against `umvs train` (docs/reliability.md, "Command line"): run folders that
// must not be replaced, resumes with other options, and arguments checked before anything is
// written. Each test checks the error a user sees and that nothing they had changed.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/run_folder.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using test::contains;
using test::file_bytes;
using test::kTrainFlags;
using test::Result;
using test::run_umvs;
using test::scene;
using test::snapshot;
using test::write_bytes;

using test::recorded;

// ---------------------------------------------------------------------------------------------
// umvs train: run folders and arguments

TEST(TrainRunFolder, ANonEmptyFolderIsOnlyReplacedWithOverwrite) {
  const std::string data = scene("rf_data");
  const std::string out = test::temp_dir("rf_out") + "/run";
  const std::string common = "train --data " + data + " --val " + data + kTrainFlags + " --out " + out;
  ASSERT_EQ(run_umvs(common + " --steps 2").status, 0);
  const auto before = snapshot(out);
  ASSERT_TRUE(before.count(out + "/best.pt") && before.count(out + "/train_log.csv") && before.count(out + "/run_config.json"));

  // The same command again, without --resume: refused, naming the way out; nothing changed.
  Result again = run_umvs(common + " --steps 4 --seed 7");
  EXPECT_EQ(again.status, 2) << again.output;
  EXPECT_TRUE(contains(again.output, "is not empty") && contains(again.output, "--overwrite")) << again.output;
  EXPECT_EQ(snapshot(out), before);

  // A folder with the user's own files is refused the same way and keeps them.
  const std::string mine = test::temp_dir("rf_mine");
  write_bytes(mine + "/notes.txt", "mine");
  Result other = run_umvs("train --data " + data + kTrainFlags + " --steps 2 --out " + mine);
  EXPECT_EQ(other.status, 2) << other.output;
  EXPECT_TRUE(contains(other.output, "notes.txt")) << other.output;
  EXPECT_EQ(file_bytes(mine + "/notes.txt"), "mine");
  EXPECT_FALSE(fs::exists(mine + "/last.pt"));

  // --overwrite replaces the run: a fresh log with one row per step of the new run.
  ASSERT_EQ(run_umvs(common + " --steps 4 --seed 7 --overwrite").status, 0);
  EXPECT_EQ(load_model(out + "/last.pt", torch::kCPU).meta.step, 4);
  std::ifstream log(out + "/train_log.csv");
  int lines = 0;
  for (std::string l; std::getline(log, l);) ++lines;
  EXPECT_EQ(lines, 5);
  EXPECT_EQ(recorded(out).at("seed"), 7);
  EXPECT_EQ(run_umvs(common + " --steps 4 --resume --overwrite").status, 2);
}

TEST(TrainRunFolder, RefusedArgumentsTouchNothing) {
  const std::string data = scene("ra_data");
  const std::string out = test::temp_dir("ra_out") + "/run";
  const std::string common = "train --data " + data + kTrainFlags + " --out " + out;
  ASSERT_EQ(run_umvs(common + " --steps 2").status, 0);
  const auto before = snapshot(out);
  for (const std::string bad : {" --steps -1", " --steps -1 --resume", " --batch 0 --resume", " --save-every 0 --resume",
                                " --val-tuples -3 --resume", " --augment 2 --resume", " --depth-sampling log --resume"}) {
    Result r = run_umvs(common + bad);
    EXPECT_EQ(r.status, 2) << bad << ": " << r.output;
    EXPECT_EQ(snapshot(out), before) << bad << " changed the run folder";
  }
  // A refused call on a new folder does not create it.
  const std::string fresh = test::temp_dir("ra_fresh") + "/never";
  EXPECT_EQ(run_umvs("train --data " + data + kTrainFlags + " --steps -1 --out " + fresh).status, 2);
  EXPECT_FALSE(fs::exists(fresh));
}

TEST(TrainRunFolder, ResumeWithOtherOptionsIsRefusedNamingTheOption) {
  const std::string data = scene("rc_data");
  const std::string out = test::temp_dir("rc_out") + "/run";
  const std::string common = "train --data " + data + " --val " + data + kTrainFlags + " --out " + out;
  ASSERT_EQ(run_umvs(common + " --steps 2").status, 0);
  const auto before = snapshot(out);
  const RunOptions stored = recorded(out);
  EXPECT_EQ(stored.at("width"), 96);
  EXPECT_EQ(stored.at("data"), RunOptions::array({fs::absolute(data).lexically_normal().string()}));

  struct Change {
    std::string flags, option;
  };
  // Switched resolution, learning rate, loss, and no validation data at all.
  const std::string no_val = "train --data " + data + kTrainFlags + " --out " + out;
  for (const auto& c : {Change{common + " --width 128", "--width"}, Change{common + " --lr 0.01", "--lr"},
                        Change{common + " --loss naive", "--loss"}, Change{no_val, "--val"}}) {
    Result r = run_umvs(c.flags + " --steps 4 --resume");
    EXPECT_EQ(r.status, 2) << c.flags << ": " << r.output;
    EXPECT_TRUE(contains(r.output, c.option + ": the run in this folder has")) << r.output;
    EXPECT_EQ(snapshot(out), before) << c.flags;
  }
  // More steps, other threads: the same run continues.
  ASSERT_EQ(run_umvs(common + " --steps 4 --threads 2 --resume").status, 0);
  EXPECT_EQ(load_model(out + "/last.pt", torch::kCPU).meta.step, 4);
}

TEST(TrainRunFolder, BestModelIsNeverComparedUnderAnotherMetric) {
  // A run validated on ground truth (best.pt chosen by depth error), written before runs recorded
  // their options (run_config.json removed here), resumed without --val: its training loss must
  // not replace best.pt.
  const std::string data = scene("bm_data");
  const std::string out = test::temp_dir("bm_out") + "/run";
  ASSERT_EQ(run_umvs("train --data " + data + " --val " + data + kTrainFlags + " --steps 2 --out " + out).status, 0);
  ASSERT_TRUE(load_model(out + "/best.pt", torch::kCPU).meta.metrics.count("val_abs_err"));
  fs::remove(out + "/run_config.json");
  const auto before = snapshot(out);
  Result r = run_umvs("train --data " + data + kTrainFlags + " --steps 4 --resume --out " + out);
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_TRUE(contains(r.output, "chosen by val_abs_err") && contains(r.output, "train_total")) << r.output;
  EXPECT_EQ(snapshot(out), before);
}

// `umvs train` sweeps as many planes as infer would at its --width (the count the shipped model
// was trained with at each size); a --resume keeps the run's own count.
TEST(TrainArguments, PlaneCountFollowsTheWidthAndAResumeKeepsTheRuns) {
  const std::string data = scene("train_planes_data");  // 96x64
  const std::string dir = test::temp_dir("train_planes");
  const std::string flags = " --width 96 --height 64 --views-loss 3 --top-k 2 --threads 1 --save-every 2";
  Result by_default = run_umvs("train --data " + data + flags + " --steps 2 --out " + dir + "/default");
  ASSERT_EQ(by_default.status, 0) << by_default.output;
  EXPECT_TRUE(contains(by_default.output, "depth planes: 16 (default for 96 wide")) << by_default.output;
  EXPECT_EQ(recorded(dir + "/default").at("num-depth"), 16);
  EXPECT_EQ(load_model(dir + "/default/last.pt", torch::kCPU).model->config().num_depth, 16);

  // Scoring a checkpoint follows the width the same way.
  Result scored = run_umvs("train --data " + data + flags + " --eval-only " + dir + "/default/last.pt");
  ASSERT_EQ(scored.status, 0) << scored.output;
  EXPECT_TRUE(contains(scored.output, "depth planes: 16 (default for 96 wide")) << scored.output;

  // A run made with 8 planes (or under the old default of 128) resumes with its own count when
  // --num-depth is not given, and is refused, naming the option, when another one is.
  ASSERT_EQ(run_umvs("train --data " + data + flags + " --num-depth 8 --steps 2 --out " + dir + "/eight").status, 0);
  Result resumed = run_umvs("train --data " + data + flags + " --steps 4 --resume --out " + dir + "/eight");
  ASSERT_EQ(resumed.status, 0) << resumed.output;
  EXPECT_TRUE(contains(resumed.output, "depth planes: 8 (as the run in --out was made)")) << resumed.output;
  EXPECT_EQ(load_model(dir + "/eight/last.pt", torch::kCPU).meta.step, 4);
  const auto before = snapshot(dir + "/eight");
  Result other = run_umvs("train --data " + data + flags + " --num-depth 16 --steps 6 --resume --out " + dir + "/eight");
  EXPECT_EQ(other.status, 2) << other.output;
  EXPECT_TRUE(contains(other.output, "--num-depth: the run in this folder has")) << other.output;
  EXPECT_EQ(snapshot(dir + "/eight"), before);

  // With --width 0 (each image's own size) there is no width to follow: refused before anything is written.
  Result own_size = run_umvs("train --data " + data + " --width 0 --height 0 --views-loss 3 --top-k 2 --threads 1 "
                             "--steps 2 --out " + dir + "/own_size");
  EXPECT_EQ(own_size.status, 2) << own_size.output;
  EXPECT_TRUE(contains(own_size.output, "with --width 0 (each image's own size) give --num-depth")) << own_size.output;
  EXPECT_FALSE(fs::exists(dir + "/own_size"));
}

TEST(TrainArguments, ZoomRangeIsCheckedFirstAndRecorded) {
  const std::string data = scene("train_zoom_data");  // 96x64
  const std::string dir = test::temp_dir("train_zoom");
  const std::string flags = " --width 64 --height 32 --num-depth 8 --views-loss 3 --top-k 2 --threads 1 --save-every 2";
  Result inverted = run_umvs("train --data " + data + flags + " --min-zoom 2 --max-zoom 1.5 --steps 2 --out " + dir + "/inverted");
  EXPECT_EQ(inverted.status, 2) << inverted.output;
  EXPECT_TRUE(contains(inverted.output, "1 <= --min-zoom <= --max-zoom, got [2.0")) << inverted.output;
  EXPECT_FALSE(fs::exists(dir + "/inverted"));
  Result no_augment = run_umvs("train --data " + data + flags + " --augment 0 --min-zoom 1.5 --steps 2 --out " + dir + "/plain");
  EXPECT_EQ(no_augment.status, 2) << no_augment.output;
  EXPECT_TRUE(contains(no_augment.output, "--augment 0 crops nothing")) << no_augment.output;
  EXPECT_FALSE(fs::exists(dir + "/plain"));

  // The range is recorded (a resume must keep it); runs of versions that recorded only a range
  // other than 1-1.25 resume with that default (TrainRunConfig tests).
  ASSERT_EQ(run_umvs("train --data " + data + flags + " --min-zoom 1.5 --max-zoom 1.5 --steps 2 --out " + dir + "/crops").status, 0);
  EXPECT_EQ(recorded(dir + "/crops").at("min-zoom"), 1.5);
  Result changed = run_umvs("train --data " + data + flags + " --steps 4 --resume --out " + dir + "/crops");
  EXPECT_EQ(changed.status, 2) << changed.output;
  EXPECT_TRUE(contains(changed.output, "--min-zoom: the run in this folder has '1.5', now '1'")) << changed.output;
  ASSERT_EQ(run_umvs("train --data " + data + flags + " --steps 2 --out " + dir + "/default").status, 0);
  EXPECT_EQ(recorded(dir + "/default").at("min-zoom"), 1.0);
  EXPECT_EQ(recorded(dir + "/default").at("max-zoom"), 1.25);
}

// The probability-volume terms change what a run computes: recorded (a resume must keep them); runs
// of versions that recorded them only when on resume with them off (TrainRunConfig tests).
TEST(TrainArguments, VolumeTermsAndFrozenBatchNormAreCheckedFirstAndRecorded) {
  const std::string data = scene("train_volume_terms_data");  // 96x64
  const std::string dir = test::temp_dir("train_volume_terms");
  const std::string flags = " --width 64 --height 32 --num-depth 8 --views-loss 3 --top-k 2 --threads 1 --save-every 2";
  Result negative = run_umvs("train --data " + data + flags + " --plane-loss-weight -1 --steps 2 --out " + dir + "/negative");
  EXPECT_EQ(negative.status, 2) << negative.output;
  EXPECT_TRUE(contains(negative.output, "plane loss weight must be finite and >= 0")) << negative.output;
  EXPECT_FALSE(fs::exists(dir + "/negative"));
  Result batchnorm = run_umvs("train --data " + data + flags + " --batchnorm fixed --steps 2 --out " + dir + "/batchnorm");
  EXPECT_EQ(batchnorm.status, 2) << batchnorm.output;
  EXPECT_TRUE(contains(batchnorm.output, "--batchnorm must be train or frozen, got 'fixed'")) << batchnorm.output;
  EXPECT_FALSE(fs::exists(dir + "/batchnorm"));
  ASSERT_EQ(run_umvs("train --data " + data + flags + " --plane-loss-weight 0.3 --entropy-weight 0.01 --batchnorm frozen " +
                     "--steps 2 --out " + dir + "/terms").status, 0);
  const RunOptions stored = recorded(dir + "/terms");
  EXPECT_EQ(stored.at("plane-loss-weight"), 0.3);
  EXPECT_EQ(stored.at("entropy-weight"), 0.01);
  EXPECT_EQ(stored.at("batchnorm"), "frozen");
  const auto log = read_csv_rows(dir + "/terms/train_log.csv");
  ASSERT_FALSE(log.empty());
  EXPECT_GT(log.back().number("plane_loss").value_or(0), 0) << "the log has the term it weighs";
  Result dropped = run_umvs("train --data " + data + flags + " --entropy-weight 0.01 --batchnorm frozen --steps 4 --resume --out " +
                            dir + "/terms");
  EXPECT_EQ(dropped.status, 2) << dropped.output;
  EXPECT_TRUE(contains(dropped.output, "--plane-loss-weight: the run in this folder has '0.3', now '0'")) << dropped.output;
  ASSERT_EQ(run_umvs("train --data " + data + flags + " --steps 2 --out " + dir + "/default").status, 0);
  EXPECT_EQ(recorded(dir + "/default").at("plane-loss-weight"), 0.0);
  EXPECT_EQ(recorded(dir + "/default").at("entropy-weight"), 0.0);
  EXPECT_EQ(recorded(dir + "/default").at("batchnorm"), "train");
  EXPECT_FALSE(read_csv_rows(dir + "/default/train_log.csv").back().number("plane_loss").has_value());
}

// A half-size first pass needs sizes in multiples of 64: the options say so before anything is
// written; the images' own size (--width 0), when the first batch is built, without a backtrace.
TEST(TrainArguments, CoarseToFineSizesAreCheckedAndTheRunRecordsItsPassesAndBatchNorm) {
  const std::string data = scene("train_c2f_data", 160, 128);
  const std::string dir = test::temp_dir("train_c2f");
  const std::string flags = " --num-depth 16 --views-loss 3 --top-k 2 --threads 1 --fine-planes 8 --first-pass-downscale 2";
  Result sized = run_umvs("train --data " + data + flags + " --width 96 --height 64 --steps 2 --out " + dir + "/sized");
  EXPECT_EQ(sized.status, 2) << sized.output;
  EXPECT_TRUE(contains(sized.output, "--width and --height must be multiples of 64, got 96x64")) << sized.output;
  EXPECT_FALSE(fs::exists(dir + "/sized"));
  Result own = run_umvs("train --data " + data + flags + " --width 0 --height 0 --steps 1 --out " + dir + "/own");
  EXPECT_EQ(own.status, 1) << own.output;
  EXPECT_TRUE(contains(own.output, "multiples of 64, got 160x128")) << own.output;
  EXPECT_FALSE(contains(own.output, "Exception raised from")) << own.output;
  Result run = run_umvs("train --data " + data + flags + " --width 128 --height 128 --steps 2 --out " + dir + "/run");
  ASSERT_EQ(run.status, 0) << run.output;
  const RunOptions stored = recorded(dir + "/run");
  EXPECT_EQ(stored.at("fine-planes"), 8);
  EXPECT_EQ(stored.at("first-pass-downscale"), 2);
  EXPECT_EQ(stored.at("batchnorm"), "train");  // from random weights: no statistics to keep
  ASSERT_TRUE(fs::exists(dir + "/run/last.pt"));
  // From a model, both passes normalise with its statistics unless --batchnorm says otherwise.
  const std::string tune = flags + " --init " + dir + "/run/last.pt --width 128 --height 128 --steps 1 --out " + dir;
  Result frozen = run_umvs("train --data " + data + tune + "/frozen");
  ASSERT_EQ(frozen.status, 0) << frozen.output;
  EXPECT_EQ(recorded(dir + "/frozen").at("batchnorm"), "frozen");
  Result batch_statistics = run_umvs("train --data " + data + tune + "/train --batchnorm train");
  ASSERT_EQ(batch_statistics.status, 0) << batch_statistics.output;
  EXPECT_EQ(recorded(dir + "/train").at("batchnorm"), "train");
}

}  // namespace
}  // namespace umvs
