// `umvs train` and its run (jobs/training_run.h) on synthetic scenes with exact depth written as
// MVSNet folders: resuming bit for bit, --eval-only --against (the trainer node's verdict),
// --max-minutes, and the run's log.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "training_test_fixtures.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/io/training_data.h"
#include "unsup_mvs/jobs/fine_tune_job.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {
namespace {

using test::run;
using test::write_scene;

double checkpoint_metric(const std::string& path, const std::string& key) {
  return load_model(path, torch::kCPU).meta.metrics.at(key);
}

TEST(TrainCommand, ResumeContinuesBitForBitAndKeepsTheBestModel) {
  const std::string data = write_scene("resume", 96, 64, 5, 2);
  const std::string out = test::temp_dir("resume_out");
  const std::string common = "--data " + data + " --val " + data +
                             " --width 96 --height 64 --num-depth 8 --views-loss 3 --top-k 2 --threads 1 --save-every 2";
  ASSERT_EQ(run(common + " --out " + out + "/a --steps 4"), 0);
  ASSERT_EQ(run(common + " --out " + out + "/b --steps 2"), 0);
  ASSERT_EQ(run(common + " --out " + out + "/b --steps 4 --resume"), 0);
  auto a = load_model(out + "/a/last.pt", torch::kCPU), b = load_model(out + "/b/last.pt", torch::kCPU);
  EXPECT_EQ(a.meta.step, 4);
  EXPECT_EQ(b.meta.step, 4);
  // (The serialised Adam archives are not byte-comparable; identical weights after resumed Adam
  // steps show its moments were restored.)
  auto pa = a.model->named_parameters(), pb = b.model->named_parameters();
  ASSERT_EQ(pa.size(), pb.size());
  for (const auto& item : pa) EXPECT_TRUE(torch::equal(item.value(), pb[item.key()])) << item.key();
  auto ba = a.model->named_buffers(), bb = b.model->named_buffers();
  for (const auto& item : ba) EXPECT_TRUE(torch::equal(item.value(), bb[item.key()])) << item.key();

  // The log has one row per step (the resumed run continues it) and validation at steps 2 and 4.
  std::ifstream log(out + "/b/train_log.csv");
  std::string line;
  std::vector<std::string> lines;
  while (std::getline(log, line)) lines.push_back(line);
  ASSERT_EQ(lines.size(), 5u);
  EXPECT_EQ(lines[0].substr(0, 11), "step,total,");
  // best.pt holds the lowest validation score seen, last.pt the latest.
  const double best = checkpoint_metric(out + "/b/best.pt", "score");
  EXPECT_LE(best, checkpoint_metric(out + "/b/last.pt", "score"));
  EXPECT_DOUBLE_EQ(best, checkpoint_metric(out + "/b/last.pt", "best_score"));
  const auto png = read_image_rgb8(out + "/b/loss_curve.png");
  EXPECT_GT((png != 255).any(2).sum().item<int64_t>(), 500);  // something was drawn

  // --steps 0 writes the initial model (a baseline) and its validation.
  ASSERT_EQ(run(common + " --out " + out + "/c --steps 0"), 0);
  EXPECT_EQ(load_model(out + "/c/best.pt", torch::kCPU).meta.step, 0);
  EXPECT_TRUE(std::filesystem::exists(out + "/c/last.pt"));
  // --eval-only reports the held-out loss of a checkpoint.
  ASSERT_EQ(run("--data " + data + " --width 96 --height 64 --num-depth 8 --views-loss 3 --threads 1 --eval-only " +
                out + "/a/last.pt --out " + out + "/e"),
            0);
  EXPECT_TRUE(std::filesystem::exists(out + "/e/eval.csv"));
  // Bad input: unknown loss, top-K above M, resume without a checkpoint. Nothing is overwritten.
  EXPECT_NE(run(common + " --out " + out + "/a --steps 4 --loss fancy"), 0);
  EXPECT_NE(run(common + " --out " + out + "/a --steps 4 --top-k 5"), 0);
  EXPECT_NE(run(common + " --out " + out + "/d --steps 4 --resume"), 0);
  EXPECT_EQ(load_model(out + "/a/last.pt", torch::kCPU).meta.step, 4);
}

// `umvs train ARGS`'s line that starts with `prefix` ("" when none).
std::string train_output_line(const std::string& args, const std::string& prefix) {
  const std::string log = test::temp_dir("train_stdout") + "/stdout.txt";
  const std::string cmd = test::umvs_binary() + " train " + args + " > " + log + " 2>/dev/null";
  if (std::system(cmd.c_str()) != 0) return "";
  std::ifstream in(log);
  for (std::string line; std::getline(in, line);)
    if (line.rfind(prefix, 0) == 0) return line;
  return "";
}

TEST(TrainCommand, EvalOnlyAgainstAServedModelGivesTheTrainerNodesVerdict) {
  const std::string data = write_scene("against", 160, 128, 5, 3);
  const std::string out = test::temp_dir("against_out");
  const std::string common =
      "--data " + data + " --width 160 --height 128 --num-depth 32 --views-loss 3 --top-k 2 --threads 1";
  ASSERT_EQ(run(common + " --out " + out + "/random --steps 0"), 0);  // random weights
  const std::string shipped = std::string(UMVS_SOURCE_DIR) + "/models/unsup_mvsnet.pt";
  const std::string random = out + "/random/last.pt";
  auto verdict = [&](const std::string& candidate, const std::string& served, const std::string& dir) {
    return train_output_line(common + " --eval-only " + candidate + " --against " + served + " --out " + out + "/" + dir,
                             "trainer rule: ");
  };
  EXPECT_THAT(verdict(shipped, random, "a"), testing::StartsWith("trainer rule: reload " + shipped + " ("));
  EXPECT_THAT(verdict(random, shipped, "b"), testing::StartsWith("trainer rule: keep " + shipped + " ("));
  // The same scores are no evidence.
  EXPECT_THAT(verdict(shipped, shipped, "c"), testing::StartsWith("trainer rule: keep " + shipped + " ("));

  // eval.csv: the served model's row, then the candidate's, which the trainer node reads.
  const auto rows = read_csv_rows(out + "/a/eval.csv");
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(eval_row(rows[0]).checkpoint, random);
  EXPECT_EQ(eval_row(rows[1]).checkpoint, shipped);
  EvalScores last;
  ASSERT_TRUE(read_eval_scores(out + "/a/eval.csv", &last));
  EXPECT_DOUBLE_EQ(last.photometric, *eval_row(rows[1]).photometric);
  EXPECT_DOUBLE_EQ(last.consistent, *eval_row(rows[1]).consistent);

  // A missing checkpoint on either side is refused before anything is evaluated or written.
  EXPECT_NE(run(common + " --eval-only " + out + "/missing.pt --against " + shipped + " --out " + out + "/e"), 0);
  EXPECT_NE(run(common + " --eval-only " + shipped + " --against " + out + "/missing.pt --out " + out + "/e"), 0);
  EXPECT_FALSE(std::filesystem::exists(out + "/e"));
  // --against means nothing without --eval-only: refused before anything is written.
  EXPECT_NE(run(common + " --out " + out + "/d --steps 1 --against " + shipped), 0);
  EXPECT_FALSE(std::filesystem::exists(out + "/d"));
}

TEST(TrainCommand, MaxMinutesStopsWithACheckpointThatResumes) {
  const std::string data = write_scene("max_minutes", 96, 64, 5, 2);
  const std::string out = test::temp_dir("max_minutes_out");
  const std::string common = "--data " + data + " --width 96 --height 64 --num-depth 8 --views-loss 3 --top-k 2" +
                             " --threads 1 --save-every 1000 --out " + out + "/run";
  // 6 ms of wall time: the run stops after its first step, far before --steps.
  ASSERT_EQ(run(common + " --steps 1000 --max-minutes 0.0001"), 0);
  const int64_t stopped = load_model(out + "/run/last.pt", torch::kCPU).meta.step;
  EXPECT_GE(stopped, 1);
  EXPECT_LT(stopped, 1000);
  // --resume continues from there (--max-minutes may change on resume).
  ASSERT_EQ(run(common + " --steps " + std::to_string(stopped + 2) + " --resume"), 0);
  EXPECT_EQ(load_model(out + "/run/last.pt", torch::kCPU).meta.step, stopped + 2);
  EXPECT_NE(run(common + "2 --steps 3 --max-minutes -1"), 0);
  EXPECT_FALSE(std::filesystem::exists(out + "/run2"));
}

TEST(TrainingRun, LogsEveryStepResumesAndRefusesAnOccupiedFolderBeforeReadingData) {
  const std::string data = write_scene("training_run", 96, 64, 5, 2);
  const std::string out = test::temp_dir("training_run_out") + "/run";
  TrainingRunConfig config;
  config.out = out;
  config.trainer.loss = LossConfig::paper();
  config.trainer.loss.top_k = 2;
  config.trainer.num_depth = 8;
  config.data.width = 96;
  config.data.height = 64;
  config.data.num_depth = 8;
  config.data.views_loss = 3;
  config.steps = 3;
  config.save_every = 2;
  config.options = {{"steps", 3}, {"data", data}};
  config.may_change_on_resume = {"steps"};
  int opened = 0;
  auto open_data = [&] {
    ++opened;
    TrainingData d;
    d.train = std::make_unique<MvsFolderSource>(std::vector<std::string>{data}, config.data);
    d.held_out = std::make_unique<MvsFolderSource>(std::vector<std::string>{data}, config.data);
    return d;
  };
  std::ostringstream messages;
  std::vector<TrainLogRow> seen;
  {
    TrainingRun run(config, open_data, messages);
    const auto result = run.run([&](const TrainLogRow& row, int64_t done, int64_t to_do) {
      seen.push_back(row);
      EXPECT_EQ(done, row.step);
      EXPECT_EQ(to_do, 3);
    });
    EXPECT_EQ(result.step, 3);
    EXPECT_EQ(result.best_metric, "val_abs_err");  // the held-out scene has depth_gt/
    EXPECT_FALSE(result.out_of_time);
  }
  ASSERT_EQ(seen.size(), 3u);
  EXPECT_FALSE(seen[0].val_total.has_value());  // validated at steps 2 and 3 (save_every, the end)
  ASSERT_TRUE(seen[1].val_total.has_value());
  ASSERT_TRUE(seen[2].val_total.has_value());
  EXPECT_TRUE(seen[2].val_abs_err.has_value());
  // The log is the rows the callback saw, through the one table definition.
  const auto logged = read_csv_rows(out + "/train_log.csv");
  ASSERT_EQ(logged.size(), 3u);
  for (size_t i = 0; i < 3; ++i) {
    const TrainLogRow row = train_log_row(logged[i]);
    EXPECT_EQ(row.step, static_cast<int64_t>(i + 1));
    EXPECT_NEAR(*row.total, *seen[i].total, 1e-6 * std::abs(*seen[i].total));
  }
  EXPECT_NEAR(checkpoint_metric(out + "/last.pt", "val_total"), *seen[2].val_total, 1e-9);

  // The folder holds a run: a new one is refused before any data is opened.
  EXPECT_THAT([&] { TrainingRun(config, open_data, messages); },
              testing::ThrowsMessage<std::invalid_argument>(testing::HasSubstr("--resume")));
  EXPECT_EQ(opened, 1);
  // A resume continues the log from the checkpoint.
  config.start = RunStart::kResume;
  config.steps = 4;
  config.options["steps"] = 4;
  TrainingRun resumed(config, open_data, messages);
  EXPECT_EQ(resumed.step(), 3);
  EXPECT_EQ(resumed.run().step, 4);
  EXPECT_EQ(read_csv_rows(out + "/train_log.csv").size(), 4u);
  EXPECT_EQ(load_model(out + "/last.pt", torch::kCPU).meta.step, 4);
}

}  // namespace
}  // namespace umvs
