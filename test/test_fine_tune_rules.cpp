// The trainer node's rules without a job (jobs/fine_tune_job.h): FineTuneConfig's checks, the
// reload verdict, `umvs eval rule` (which gives scripts the same verdict) and the keyframe
// settings a job hands to `umvs train --bag`.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <thread>

#include "cli_test_util.h"
#include "fine_tune_test_fixture.h"
#include "test_util.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/jobs/fine_tune_job.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using testing::HasSubstr;
using testing::ThrowsMessage;
using namespace fine_tune_test;

TEST(FineTuneConfig, ValidateNamesTheBadField) {
  FineTuneConfig c;
  c.umvs_path = "/usr/bin/umvs";
  c.output_dir = "/tmp/models";
  EXPECT_NO_THROW(c.validate());
  auto bad = c;
  bad.umvs_path = "umvs";
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("umvs_path must be an absolute path, got 'umvs'")));
  bad = c;
  bad.output_dir = "";
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("output_dir must not be empty")));
  bad = c;
  bad.default_steps = 0;
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("default_steps (~steps) must be >= 1, got 0")));
  bad = c;
  bad.train_args = {"--width", "64", "--out", "/tmp/x"};
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("train_args must not set --out")));
  bad = c;
  bad.local_ranks = 0;
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("local_ranks must be >= 1, got 0")));
  bad = c;
  bad.train_args = {"--nproc", "2"};
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("train_args must not set --nproc: set local_ranks instead")));
  for (double share : {0.0, 1.5}) {
    bad = c;
    bad.fine_tuned_share = share;
    EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("fine_tuned_share must be in (0, 1]")));
  }
  bad = c;
  bad.train_args = {"--fine-tuned-share", "0.5"};
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("train_args must not set --fine-tuned-share")));
  bad = c;
  bad.train_args = {"--device", "cuda"};  // the trainer's ~device (the launch file's device) says where jobs run
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("train_args must not set --device")));
  bad = c;
  bad.world_frame = "";
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("world_frame must not be empty")));
  bad = c;
  bad.keyframes.depth_min = -1.0;
  EXPECT_THAT([&] { bad.validate(); }, ThrowsMessage<std::invalid_argument>(HasSubstr("keyframes: ")));

  c.train_args = {"--depth-min", "0.5", "--width", "64"};
  EXPECT_EQ(c.keyframe_args_overridden(), std::vector<std::string>{"--depth-min"});
}

TEST(FineTuneDecision, ReloadsOnlyWhenBothScoresAreClearlyBetter) {
  const ReloadVerdict better = decide_reload({0.10, 0.30}, {0.12, 0.25});
  EXPECT_TRUE(better.reload);
  EXPECT_EQ(better.comparison, kBetterComparison);
  EXPECT_FALSE(decide_reload({0.10, 0.20}, {0.12, 0.25}).reload) << "photometric better, consistency worse";
  EXPECT_FALSE(decide_reload({0.13, 0.30}, {0.12, 0.25}).reload) << "consistency better, photometric worse";
  EXPECT_FALSE(decide_reload({0.12, 0.30}, {0.12, 0.25}).reload) << "photometric equal";
  EXPECT_FALSE(decide_reload({0.1195, 0.30}, {0.12, 0.25}).reload) << "photometric lower by 0.4 %: within noise";
  EXPECT_TRUE(decide_reload({0.1185, 0.30}, {0.12, 0.25}).reload) << "photometric lower by 1.25 %";
  EXPECT_FALSE(decide_reload({0.10, 0.009}, {0.12, 0.0}).reload) << "under 1 % confirmed: no evidence";
  EXPECT_TRUE(decide_reload({0.10, 0.01}, {0.12, 0.0}).reload) << "one point more, from nothing";
  EXPECT_FALSE(decide_reload({0.10, 0.257}, {0.12, 0.25}).reload) << "consistency higher by 0.7 points: within noise";
  EXPECT_FALSE(decide_reload({0.10, 0.125}, {0.12, 0.118}).reload) << "the trainer test's case (depth got worse)";
  EXPECT_TRUE(decide_reload({0.10, 0.261}, {0.12, 0.25}).reload) << "consistency higher by 1.1 points";
  EXPECT_EQ(decide_reload({0.10, 0.009}, {0.12, 0.005}).comparison,
            "held-out photometric loss: new 0.1, served 0.12; multi-view consistent depth: new 0.9%, served 0.5%");
}

// `umvs eval rule` gives scripts the same verdict as the node, from two eval.csv files.
TEST(EvalRuleCommand, PrintsTheTrainerNodesVerdict) {
  const std::string dir = test::temp_dir("eval_rule");
  write_text(dir + "/served.csv", eval_csv(0.100, 0.30));
  write_text(dir + "/better.csv", eval_csv(0.098, 0.32));      // 2 % lower loss, 2 points more confirmed
  write_text(dir + "/too_close.csv", eval_csv(0.0995, 0.40));  // 0.5 % lower loss only: kept
  auto verdict = [&](const std::string& candidate) {
    const test::Result r = test::run_umvs("eval rule --served " + dir + "/served.csv --candidate " + dir + "/" + candidate);
    return std::to_string(r.status) + " " + r.output.substr(0, r.output.find('\n'));
  };
  EXPECT_EQ(verdict("better.csv"), "0 reload");
  EXPECT_EQ(verdict("too_close.csv"), "0 keep");
  EXPECT_EQ(test::run_umvs("eval rule --served " + dir + "/served.csv --candidate " + dir + "/none.csv").status, 2);
}

// Every field of the stream config survives the trip through the command line.
TEST(KeyframeStreamArgs, EveryFieldSurvivesTheTripThroughTheCommandLine) {
  KeyframeStreamConfig c;
  c.rectified = false;
  c.keyframes.min_translation = 0.123456789;
  c.keyframes.min_rotation_deg = 7.5;
  c.keyframes.min_pose_distance = 0.2;
  c.keyframes.buffer_size = 12;
  c.keyframes.min_score = 0.25;
  c.keyframes.score_grid = 9;
  c.depth_min = 0.45;
  c.depth_max = 12.5;
  const auto args = keyframe_stream_train_args(c);
  std::map<std::string, std::string> v;
  ASSERT_EQ(args.size() % 2, 0u);
  for (size_t i = 0; i < args.size(); i += 2) v[args[i]] = args[i + 1];
  EXPECT_EQ(v.at("--rectified"), "0");
  EXPECT_DOUBLE_EQ(std::stod(v.at("--min-translation")), 0.123456789);
  EXPECT_DOUBLE_EQ(std::stod(v.at("--min-rotation-deg")), 7.5);
  EXPECT_DOUBLE_EQ(std::stod(v.at("--min-pose-distance")), 0.2);
  EXPECT_EQ(v.at("--keyframe-buffer"), "12");
  EXPECT_DOUBLE_EQ(std::stod(v.at("--min-view-score")), 0.25);
  EXPECT_EQ(v.at("--view-score-grid"), "9");
  EXPECT_DOUBLE_EQ(std::stod(v.at("--depth-min")), 0.45);
  EXPECT_DOUBLE_EQ(std::stod(v.at("--depth-max")), 12.5);
  EXPECT_EQ(v.size(), 9u);
}

}  // namespace
}  // namespace umvs
