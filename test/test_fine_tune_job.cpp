// FineTuneJob (jobs/fine_tune_job.h), the trainer node's job logic, driven with a fake `umvs`: a shell
// script that copies the train_log.csv / eval.csv the test prepared into the job's folders, writes
// best.pt and exits with the status the test asks for. Conditions are awaited by polling the job
// with a deadline.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>

#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <thread>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/jobs/fine_tune_job.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using testing::HasSubstr;
using testing::ThrowsMessage;

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

std::vector<std::string> lines_of(const std::string& path) {
  std::vector<std::string> lines;
  std::ifstream in(path);
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

std::string join(const std::vector<std::string>& words) {
  std::string s;
  for (const auto& w : words) s += (s.empty() ? "" : " ") + w;
  return s;
}

// The fake umvs: `train ... --out DIR` copies FAKE/train_log.csv to DIR (when prepared), writes
// DIR/best.pt (and DIR/blended.pt with --fine-tuned-share), waits while FAKE/hold exists, prints
// "step 100 done" and exits with FAKE/train_status (default 0); `train ... --eval-only CKPT --out
// DIR` copies FAKE/eval_new.csv (CKPT ends in best.pt or blended.pt) or FAKE/eval_served.csv to
// DIR/eval.csv. Each call appends its arguments to FAKE/calls.
constexpr char kFakeUmvs[] = R"(#!/bin/sh
F=$(dirname "$0")
echo "$*" >> "$F/calls"
out=""; ckpt=""; share=""
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out="$2"; shift ;;
    --eval-only) ckpt="$2"; shift ;;
    --fine-tuned-share) share="$2"; shift ;;
  esac
  shift
done
mkdir -p "$out"
if [ -z "$ckpt" ]; then
  echo $$ > "$F/train.pid"
  if [ -f "$F/train_log.csv" ]; then cp "$F/train_log.csv" "$out/.log" && mv "$out/.log" "$out/train_log.csv"; fi
  echo "new model" > "$out/best.pt"
  if [ -n "$share" ]; then echo "blend of $share" > "$out/blended.pt"; fi
  while [ -f "$F/hold" ]; do sleep 0.02; done
  echo "step 100 done"
  exit $(cat "$F/train_status" 2>/dev/null || echo 0)
fi
case "$ckpt" in
  */best.pt|*/blended.pt) cp "$F/eval_new.csv" "$out/eval.csv" ;;
  *) cp "$F/eval_served.csv" "$out/eval.csv" ;;
esac
echo "evaluated $ckpt"
)";

std::string eval_csv(double photometric, double consistent) {
  EvalRow row;
  row.checkpoint = "model.pt";
  row.tuples = 4;
  row.photometric = photometric;
  row.total = photometric;
  row.consistent = consistent;
  return csv_header(eval_columns()) + "\n" + format_csv_row(row) + "\n";
}

TrainLogRow log_row(int64_t step, double total, double photometric, double ssim, double smoothness) {
  TrainLogRow row;
  row.step = step;
  row.total = total;
  row.photometric = photometric;
  row.ssim = ssim;
  row.smoothness = smoothness;
  return row;
}

// "held-out photometric loss: new 0.1, served 0.12; ..." for the scores the tests use most.
constexpr char kBetterComparison[] =
    "held-out photometric loss: new 0.1, served 0.12; multi-view consistent depth: new 30%, served 25%";

class FineTuneJobTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = test::temp_dir(std::string("fine_tune_job_") + testing::UnitTest::GetInstance()->current_test_info()->name());
    fake_ = dir_ + "/fake";
    fs::create_directories(fake_);
    write_text(fake_ + "/umvs", kFakeUmvs);
    fs::permissions(fake_ + "/umvs", fs::perms::owner_all);
    bag_ = dir_ + "/scene.bag";
    write_text(bag_, "a bag");
    served_ = dir_ + "/served.pt";
    write_text(served_, "served model");
    models_ = dir_ + "/models";
    config_.umvs_path = fake_ + "/umvs";
    config_.output_dir = models_;
    config_.train_args = {"--width", "128"};
  }
  void TearDown() override { fs::remove_all(dir_); }

  FineTuneRequest request(int steps = 100, const std::string& output = "") const {
    FineTuneRequest r;
    r.bags = {bag_};
    r.steps = steps;
    r.output = output;
    return r;
  }

  void prepare_evals(double new_photometric, double new_consistent, double served_photometric,
                     double served_consistent) const {
    write_text(fake_ + "/eval_new.csv", eval_csv(new_photometric, new_consistent));
    write_text(fake_ + "/eval_served.csv", eval_csv(served_photometric, served_consistent));
  }

  // Polls `job` until `done` holds (true) or 20 s pass (false); every reported state is recorded.
  template <typename Done>
  bool poll_until(FineTuneJob& job, Done done) {
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < deadline) {
      if (const auto p = job.poll()) {
        if (states_.empty() || states_.back() != p->state) states_.push_back(p->state);
      }
      if (done()) return true;
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    return false;
  }
  bool poll_until_idle_or_ready(FineTuneJob& job) {
    return poll_until(job, [&] { return job.phase() == FineTuneJob::Phase::kIdle ||
                                        job.phase() == FineTuneJob::Phase::kReadyToReload; });
  }

  std::string dir_, fake_, bag_, served_, models_;
  FineTuneConfig config_;
  std::vector<std::string> states_;  // the distinct states poll() reported, in order
};

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

TEST_F(FineTuneJobTest, BadRequestsAreRefusedWithTheReasonAndStartNothing) {
  FineTuneJob job(config_);
  EXPECT_TRUE(fs::is_directory(models_)) << "the job creates output_dir";
  EXPECT_TRUE(job.setup_errors().empty());
  auto refused = [&](FineTuneRequest r, const std::string& served = "") {
    const FineTuneAnswer a = job.start(r, served.empty() ? served_ : served);
    EXPECT_FALSE(a.ok);
    EXPECT_TRUE(a.job_id.empty());
    return a.message;
  };
  FineTuneRequest r = request();
  r.bags = {dir_ + "/missing.bag"};
  EXPECT_EQ(refused(r), "bag '" + dir_ + "/missing.bag' does not exist");
  r.bags = {dir_};
  EXPECT_EQ(refused(r), "bag '" + dir_ + "' is not a readable file");
  r.bags.clear();
  EXPECT_EQ(refused(r), "no bag given");
  for (const std::string& outside : {dir_ + "/elsewhere/model.pt", models_ + "/../served.pt", std::string("/tmp/x.pt")}) {
    EXPECT_EQ(refused(request(100, outside)), "output '" + outside + "' is outside the allowed folder " + models_);
  }
  write_text(models_ + "/taken.pt", "an earlier model");
  EXPECT_EQ(refused(request(100, models_ + "/taken.pt")),
            "output '" + models_ + "/taken.pt' already exists; a fine-tuned model is only written under a new name");
  fs::create_symlink(dir_ + "/nowhere.pt", models_ + "/planted.pt");  // a dangling link is a name too
  EXPECT_EQ(refused(request(100, models_ + "/planted.pt")),
            "output '" + models_ + "/planted.pt' already exists; a fine-tuned model is only written under a new name");
  EXPECT_FALSE(fs::exists(dir_ + "/nowhere.pt"));
  EXPECT_EQ(refused(request(-1)), "steps must not be negative");
  r = request();
  r.init_checkpoint = dir_ + "/no_such_model.pt";
  EXPECT_EQ(refused(r), "checkpoint '" + dir_ + "/no_such_model.pt' is missing or unreadable");
  EXPECT_EQ(refused(request(), dir_ + "/gone.pt"), "checkpoint '" + dir_ + "/gone.pt' is missing or unreadable");
  r.init_checkpoint = served_;
  EXPECT_EQ(refused(r, dir_ + "/gone.pt"),
            "the served model ~served_checkpoint '" + dir_ + "/gone.pt' is unreadable: nothing to compare with");

  EXPECT_FALSE(job.busy());
  EXPECT_FALSE(fs::exists(fake_ + "/calls")) << "a refused request started umvs";
  EXPECT_EQ(job.describe(), "no job yet: idle, step 0/0; ");
  EXPECT_EQ(read_text(served_), "served model");
}

TEST_F(FineTuneJobTest, ProgressComesFromTheLogAndABetterModelIsReadyToReload) {
  write_text(fake_ + "/train_log.csv", csv_header(train_log_columns()) + "\n" +
                                           format_csv_row(log_row(10, 0.5, 0.3, 0.15, 0.05)) + "\n" +
                                           format_csv_row(log_row(20, 0.4, 0.25, 0.125, 0.025)) + "\n");
  write_text(fake_ + "/hold", "");
  prepare_evals(0.10, 0.30, 0.12, 0.25);
  FineTuneJob job(config_);
  const auto t0 = std::chrono::steady_clock::now();
  const FineTuneAnswer a = job.start(request(), served_);
  ASSERT_TRUE(a.ok) << a.message;
  const std::string job_dir = models_ + "/" + a.job_id;
  EXPECT_EQ(a.message, "training 100 steps from " + served_ + " in " + job_dir);
  EXPECT_EQ(job.progress().state, "training");
  EXPECT_EQ(job.progress().eta_seconds, -1.f);

  ASSERT_TRUE(poll_until(job, [&] { return job.progress().step == 20; })) << job.describe();
  const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const FineTuneProgress p = job.progress();
  EXPECT_EQ(p.state, "training");
  EXPECT_EQ(p.job_id, a.job_id);
  EXPECT_EQ(p.total_steps, 100);
  EXPECT_FLOAT_EQ(p.loss, 0.4f);
  EXPECT_FLOAT_EQ(p.photometric, 0.25f);
  EXPECT_FLOAT_EQ(p.ssim, 0.125f);
  EXPECT_FLOAT_EQ(p.smoothness, 0.025f);
  // elapsed / 20 steps * 80 steps left, with 0 < elapsed <= waited
  EXPECT_GT(p.eta_seconds, 0.f);
  EXPECT_LE(p.eta_seconds, 4.0 * waited + 1e-3);
  EXPECT_EQ(p.message, a.message);
  EXPECT_EQ(job.describe(), "job " + a.job_id + ": training, step 20/100; " + a.message);
  EXPECT_EQ(job.start(request(), served_).message, "job " + a.job_id + " is still running; cancel it first");

  fs::remove(fake_ + "/hold");
  ASSERT_TRUE(poll_until_idle_or_ready(job)) << job.describe();
  EXPECT_EQ(states_, (std::vector<std::string>{"training", "evaluating", "ready to reload"}));
  ASSERT_EQ(job.phase(), FineTuneJob::Phase::kReadyToReload) << job.describe();
  EXPECT_TRUE(job.busy());
  EXPECT_EQ(job.progress().message, kBetterComparison);
  EXPECT_EQ(job.reload_checkpoint(), models_ + "/" + a.job_id + ".pt");
  EXPECT_EQ(read_text(job.reload_checkpoint()), "new model\n");
  EXPECT_FALSE(job.poll()) << "nothing happens until the node reports the reload";

  // What umvs was asked to do: train from the served model, then evaluate both on the same data.
  std::vector<std::string> data = {"train", "--bag", bag_, "--image-topic", "/camera/image_rect_color",
                                   "--camera-info-topic", "/camera/camera_info", "--world-frame", "world", "--device", "cpu"};
  const auto stream = keyframe_stream_train_args(config_.keyframes);
  data.insert(data.end(), stream.begin(), stream.end());
  data.insert(data.end(), {"--width", "128"});
  EXPECT_EQ(lines_of(fake_ + "/calls"),
            (std::vector<std::string>{
                join(data) + " --init " + served_ + " --steps 100 --out " + job_dir,
                join(data) + " --eval-only " + job_dir + "/best.pt --out " + job_dir + "/eval_new",
                join(data) + " --eval-only " + served_ + " --out " + job_dir + "/eval_served"}));

  const FineTuneProgress& done = job.reload_result(true, "");
  EXPECT_EQ(done.state, "reloaded");
  EXPECT_EQ(done.message, std::string(kBetterComparison) + "; now serving " + models_ + "/" + a.job_id + ".pt");
  EXPECT_FALSE(job.busy());
  EXPECT_TRUE(fs::exists(models_ + "/" + a.job_id + ".pt"));
  EXPECT_EQ(read_text(served_), "served model");
}

TEST_F(FineTuneJobTest, WithAFineTunedShareTheBlendIsWhatIsJudgedAndServed) {
  config_.fine_tuned_share = 0.5;
  prepare_evals(0.10, 0.30, 0.12, 0.25);
  FineTuneJob job(config_);
  const FineTuneAnswer a = job.start(request(), served_);
  ASSERT_TRUE(a.ok) << a.message;
  const std::string job_dir = models_ + "/" + a.job_id;
  ASSERT_TRUE(poll_until_idle_or_ready(job)) << job.describe();
  ASSERT_EQ(job.phase(), FineTuneJob::Phase::kReadyToReload) << job.describe();
  EXPECT_EQ(read_text(job.reload_checkpoint()), "blend of 0.5\n");
  const auto calls = lines_of(fake_ + "/calls");
  ASSERT_EQ(calls.size(), 3u);
  EXPECT_THAT(calls[0], HasSubstr(" --init " + served_ + " --steps 100 --out " + job_dir + " --fine-tuned-share 0.5"));
  EXPECT_THAT(calls[1], HasSubstr(" --eval-only " + job_dir + "/blended.pt --out " + job_dir + "/eval_new"));
  EXPECT_THAT(calls[2], HasSubstr(" --eval-only " + served_ + " --out " + job_dir + "/eval_served"));
  EXPECT_TRUE(fs::exists(job_dir + "/best.pt")) << "the fine-tuned weights as trained stay in the job's folder";
}

TEST_F(FineTuneJobTest, AModelInferenceRefusesDoesNotStayUnderTheOutputName) {
  prepare_evals(0.10, 0.30, 0.12, 0.25);
  FineTuneJob job(config_);
  const FineTuneAnswer a = job.start(request(50, models_ + "/mine.pt"), served_);
  ASSERT_TRUE(a.ok) << a.message;
  ASSERT_TRUE(poll_until_idle_or_ready(job)) << job.describe();
  ASSERT_EQ(job.progress().state, "ready to reload") << job.progress().message;
  ASSERT_TRUE(fs::exists(models_ + "/mine.pt"));
  const FineTuneProgress& done = job.reload_result(false, "smoke test failed");
  EXPECT_EQ(done.state, "failed");
  EXPECT_EQ(done.message, std::string(kBetterComparison) + "; inference refused the new model (kept in " + models_ +
                              "/" + a.job_id + "): smoke test failed");
  EXPECT_FALSE(fs::exists(models_ + "/mine.pt"));
  EXPECT_TRUE(fs::exists(models_ + "/" + a.job_id + "/best.pt"));
  EXPECT_FALSE(job.busy());

  // Inference not reachable: the copy stays under its name.
  const FineTuneAnswer b = job.start(request(50, models_ + "/mine.pt"), served_);
  ASSERT_TRUE(b.ok) << b.message;
  EXPECT_NE(b.job_id, a.job_id);
  ASSERT_TRUE(poll_until_idle_or_ready(job)) << job.describe();
  ASSERT_EQ(job.progress().state, "ready to reload") << job.progress().message;
  const FineTuneProgress& unreachable = job.reload_unreachable("/inference/reload_model");
  EXPECT_EQ(unreachable.state, "failed");
  EXPECT_EQ(unreachable.message, std::string(kBetterComparison) + "; new model saved to " + models_ +
                                     "/mine.pt but /inference/reload_model is not reachable");
  EXPECT_TRUE(fs::exists(models_ + "/mine.pt"));
}

TEST_F(FineTuneJobTest, TheServedModelStaysWhenTheNewOneIsBetterOnOnlyOneScoreOrUnderTheFloor) {
  struct Case {
    double new_photometric, new_consistent, served_photometric, served_consistent;
    std::string comparison;
  };
  const std::vector<Case> cases = {
      {0.10, 0.20, 0.12, 0.25,
       "held-out photometric loss: new 0.1, served 0.12; multi-view consistent depth: new 20%, served 25%"},
      {0.13, 0.30, 0.12, 0.25,
       "held-out photometric loss: new 0.13, served 0.12; multi-view consistent depth: new 30%, served 25%"},
      {0.10, 0.009, 0.12, 0.005,
       "held-out photometric loss: new 0.1, served 0.12; multi-view consistent depth: new 0.9%, served 0.5%"},
  };
  FineTuneJob job(config_);
  for (const Case& c : cases) {
    SCOPED_TRACE(c.comparison);
    prepare_evals(c.new_photometric, c.new_consistent, c.served_photometric, c.served_consistent);
    const FineTuneAnswer a = job.start(request(), served_);
    ASSERT_TRUE(a.ok) << a.message;
    ASSERT_TRUE(poll_until_idle_or_ready(job)) << job.describe();
    EXPECT_EQ(job.progress().state, "kept");
    EXPECT_EQ(job.progress().message, c.comparison + ": the served model stays");
    EXPECT_FALSE(fs::exists(models_ + "/" + a.job_id + ".pt")) << "a kept model sits under the output name";
    EXPECT_TRUE(fs::exists(models_ + "/" + a.job_id + "/best.pt"));
  }
  EXPECT_EQ(read_text(served_), "served model");
}

TEST_F(FineTuneJobTest, WithLocalRanksTheTrainingRunsAsThatManyRanksAndTheEvaluationsAsOneProcess) {
  config_.local_ranks = 2;
  prepare_evals(0.10, 0.30, 0.12, 0.25);
  FineTuneJob job(config_);
  const FineTuneAnswer a = job.start(request(40), served_);
  ASSERT_TRUE(a.ok) << a.message;
  ASSERT_TRUE(poll_until_idle_or_ready(job)) << job.describe();
  const auto calls = lines_of(fake_ + "/calls");
  ASSERT_EQ(calls.size(), 3u);
  EXPECT_THAT(calls[0], HasSubstr(" --steps 40 --out " + models_ + "/" + a.job_id + " --nproc 2"));
  EXPECT_THAT(calls[1], testing::Not(HasSubstr("--nproc")));
  EXPECT_THAT(calls[2], testing::Not(HasSubstr("--nproc")));
  EXPECT_EQ(job.phase(), FineTuneJob::Phase::kReadyToReload) << job.describe();
}

TEST_F(FineTuneJobTest, CancelStopsTheChildAndLeavesTheServedModel) {
  write_text(fake_ + "/hold", "");
  FineTuneJob job(config_);
  const FineTuneAnswer a = job.start(request(), served_);
  ASSERT_TRUE(a.ok) << a.message;
  ASSERT_TRUE(poll_until(job, [&] { return fs::exists(fake_ + "/train.pid") && !read_text(fake_ + "/train.pid").empty(); }));
  const pid_t pid = std::stoi(read_text(fake_ + "/train.pid"));
  EXPECT_EQ(::kill(pid, 0), 0) << "the fake training is running";

  const FineTuneAnswer c = job.cancel();
  EXPECT_TRUE(c.ok);
  EXPECT_EQ(c.message, "job " + a.job_id + " cancelled; the served model is unchanged");
  EXPECT_EQ(job.progress().state, "cancelled");
  EXPECT_EQ(job.progress().message, c.message);
  EXPECT_FALSE(job.busy());
  errno = 0;
  EXPECT_EQ(::kill(pid, 0), -1) << "the training process survived the cancel";
  EXPECT_EQ(errno, ESRCH);
  EXPECT_FALSE(job.poll());
  EXPECT_EQ(lines_of(fake_ + "/calls").size(), 1u) << "no evaluation after a cancel";
  EXPECT_EQ(read_text(served_), "served model");
  EXPECT_FALSE(fs::exists(models_ + "/" + a.job_id + ".pt"));

  const FineTuneAnswer again = job.cancel();
  EXPECT_FALSE(again.ok);
  EXPECT_EQ(again.message, "no job is running");
}

TEST_F(FineTuneJobTest, AFailedChildFailsTheJobWithItsExitStatus) {
  write_text(fake_ + "/train_status", "3\n");
  FineTuneJob job(config_);
  const FineTuneAnswer a = job.start(request(), served_);
  ASSERT_TRUE(a.ok) << a.message;
  ASSERT_TRUE(poll_until(job, [&] { return !job.busy(); })) << job.describe();
  EXPECT_EQ(job.progress().state, "failed");
  EXPECT_EQ(job.progress().message, "umvs train exited with status 3 (step 100 done); the served model is unchanged");
  EXPECT_EQ(lines_of(fake_ + "/calls").size(), 1u) << "no evaluation after a failed training";
  EXPECT_FALSE(fs::exists(models_ + "/" + a.job_id + ".pt"));

  // Training succeeds but the evaluation writes no eval.csv: failed too, with the reason.
  fs::remove(fake_ + "/train_status");
  const FineTuneAnswer b = job.start(request(), served_);
  ASSERT_TRUE(b.ok) << b.message;
  ASSERT_TRUE(poll_until(job, [&] { return !job.busy(); })) << job.describe();
  EXPECT_EQ(job.progress().state, "failed");
  EXPECT_EQ(job.progress().message, "no evaluation of the new model; the served model is unchanged");
  EXPECT_EQ(read_text(served_), "served model");
}

TEST_F(FineTuneJobTest, AMissingUmvsIsASetupErrorAndRequestsFailWithTheReason) {
  config_.umvs_path = dir_ + "/no/umvs";
  FineTuneJob job(config_);
  ASSERT_EQ(job.setup_errors().size(), 1u);
  EXPECT_EQ(job.setup_errors()[0], "umvs_path '" + dir_ + "/no/umvs' is not an executable; fine-tuning requests will fail");
  const FineTuneAnswer a = job.start(request(), served_);
  EXPECT_FALSE(a.ok);
  EXPECT_THAT(a.message, HasSubstr("cannot start training: "));
  EXPECT_FALSE(job.busy());
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

}  // namespace
}  // namespace umvs
