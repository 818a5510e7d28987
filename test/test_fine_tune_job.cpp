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

}  // namespace
}  // namespace umvs
