// Fault injection by SIGKILL (docs/reliability.md, "Command line"): training killed at any moment
// resumes to the uninterrupted model with its whole log and no leftover temporary file; a fusion
// killed while writing keeps the previous cloud.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <torch/torch.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <thread>

#include "cli_test_util.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/ply.h"

extern char** environ;

namespace umvs {
namespace {

namespace fs = std::filesystem;
using test::file_bytes;
using test::kTrainFlags;
using test::run_umvs;
using test::scene;

// Starts `umvs ARGS...` without a shell, output discarded.
pid_t spawn_umvs(const std::vector<std::string>& args) {
  std::vector<std::string> all = {test::umvs_binary()};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  return rc == 0 ? pid : -1;
}

// Polls `ready` every millisecond while `pid` runs; SIGKILLs it once `ready` holds. True when
// the kill hit the running process (false: it had exited first).
bool kill_when(pid_t pid, const std::function<bool()>& ready) {
  int status = 0;
  while (::waitpid(pid, &status, WNOHANG) == 0) {
    if (ready()) {
      ::kill(pid, SIGKILL);
      ::waitpid(pid, &status, 0);
      return WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return false;
}

int log_rows(const std::string& path) {
  std::ifstream in(path);
  int n = -1;
  for (std::string l; std::getline(in, l);) ++n;
  return n;
}

TEST(KillFaults, TrainingKilledMidRunResumesToTheUninterruptedModel) {
  const std::string data = scene("kill_train_data");
  const std::string dir = test::temp_dir("kill_train");
  const std::vector<std::string> common = {"train", "--data", data, "--width", "96", "--height", "64", "--num-depth", "8",
                                           "--views-loss", "3", "--top-k", "2", "--threads", "1", "--save-every", "2"};
  auto with = [&](std::vector<std::string> extra) {
    std::vector<std::string> a = common;
    a.insert(a.end(), extra.begin(), extra.end());
    return a;
  };
  // Killed after its third step (a checkpoint at step 2 exists), long before its 1000 steps.
  const pid_t pid = spawn_umvs(with({"--steps", "1000", "--out", dir + "/killed"}));
  ASSERT_GT(pid, 0);
  ASSERT_TRUE(kill_when(pid, [&] { return log_rows(dir + "/killed/train_log.csv") >= 3; }));
  const int64_t at = load_model(dir + "/killed/last.pt", torch::kCPU).meta.step;
  ASSERT_GE(at, 2);
  const std::string target = std::to_string(at + 2);
  ASSERT_EQ(run_umvs("train --data " + data + kTrainFlags + " --steps " + target + " --resume --out " + dir + "/killed").status, 0);
  ASSERT_EQ(run_umvs("train --data " + data + kTrainFlags + " --steps " + target + " --out " + dir + "/straight").status, 0);
  auto a = load_model(dir + "/killed/last.pt", torch::kCPU), b = load_model(dir + "/straight/last.pt", torch::kCPU);
  EXPECT_EQ(a.meta.step, at + 2);
  for (const auto& p : b.model->named_parameters()) {
    EXPECT_TRUE(torch::equal(p.value(), a.model->named_parameters()[p.key()])) << p.key();
  }
  EXPECT_EQ(log_rows(dir + "/killed/train_log.csv"), at + 2);
}

TEST(KillFaults, TrainingKilledWhileSavingBestPtKeepsEveryLogRowAndResumesExactly) {
  // best.pt is written after last.pt at a checkpoint that improved: a kill then finds last.pt of
  // the new step saved. The log must already hold that step's row, and the resumed run must clear
  // the half-written best.pt and end where an uninterrupted run ends.
  const std::string data = scene("kill_best_data");
  const std::string dir = test::temp_dir("kill_best");
  const std::string out = dir + "/killed";
  bool during_best = false;
  for (int attempt = 0; attempt < 5 && !during_best; ++attempt) {
    fs::remove_all(out);
    const pid_t pid = spawn_umvs({"train", "--data", data, "--width", "96", "--height", "64", "--num-depth", "8",
                                  "--views-loss", "3", "--top-k", "2", "--threads", "1", "--save-every", "2", "--steps",
                                  "1000", "--out", out});
    ASSERT_GT(pid, 0);
    ASSERT_TRUE(kill_when(pid, [&] {
      std::error_code ec;
      for (const auto& e : fs::directory_iterator(out, ec)) {
        if (e.path().filename().string().rfind(std::string("best.pt") + kTempInfix, 0) == 0) return during_best = true;
      }
      return log_rows(out + "/train_log.csv") >= 30;  // no luck this time: try again
    }));
  }
  ASSERT_TRUE(during_best) << "no kill landed while best.pt was being written, in 5 runs";
  const int64_t at = load_model(out + "/last.pt", torch::kCPU).meta.step;
  EXPECT_GE(log_rows(out + "/train_log.csv"), at) << "every step up to last.pt's is in the log";
  const std::string target = std::to_string(at + 2);
  ASSERT_EQ(run_umvs("train --data " + data + kTrainFlags + " --steps " + target + " --resume --out " + out).status, 0);
  ASSERT_EQ(run_umvs("train --data " + data + kTrainFlags + " --steps " + target + " --out " + dir + "/straight").status, 0);
  for (const auto& e : fs::directory_iterator(out)) {
    EXPECT_EQ(e.path().filename().string().find(kTempInfix), std::string::npos) << e.path() << " was left behind";
  }
  EXPECT_EQ(log_rows(out + "/train_log.csv"), at + 2);
  EXPECT_EQ(file_bytes(out + "/train_log.csv").substr(0, 200), file_bytes(dir + "/straight/train_log.csv").substr(0, 200));
  auto a = load_model(out + "/last.pt", torch::kCPU), b = load_model(dir + "/straight/last.pt", torch::kCPU);
  for (const auto& p : b.model->named_parameters()) {
    EXPECT_TRUE(torch::equal(p.value(), a.model->named_parameters()[p.key()])) << p.key();
  }
}

TEST(KillFaults, FusionKilledWhileWritingKeepsThePreviousCloud) {
  // Exact depth of 6 views at 320x256 fuses to a cloud of a few MB: a kill while its temporary
  // file exists lands in the middle of writing it.
  const std::string data = scene("kill_fuse_data", 320, 256, 6);
  const std::string dir = test::temp_dir("kill_fuse");
  const std::vector<std::string> args = {"fuse", "--depth", data + "/depth_gt", "--data", data, "--min-confidence", "0",
                                         "--min-agreeing-views", "1", "--threads", "1", "--out", dir + "/cloud.ply"};
  ASSERT_EQ(run_umvs("fuse --depth " + data + "/depth_gt --data " + data +
                 " --min-confidence 0 --min-agreeing-views 1 --threads 1 --out " + dir + "/cloud.ply").status, 0);
  const std::string before = file_bytes(dir + "/cloud.ply");
  ASSERT_GT(read_ply(dir + "/cloud.ply").size(), 10000u);
  bool killed_while_writing = false;
  for (int attempt = 0; attempt < 5 && !killed_while_writing; ++attempt) {
    const pid_t pid = spawn_umvs(args);
    ASSERT_GT(pid, 0);
    // The temporary file (whatever its name) is the only other entry of the folder.
    killed_while_writing = kill_when(pid, [&] {
      for (const auto& e : fs::directory_iterator(dir)) {
        if (e.path().filename() != "cloud.ply") return true;
      }
      return false;
    });
    EXPECT_EQ(file_bytes(dir + "/cloud.ply"), before) << "attempt " << attempt;
    for (const auto& e : fs::directory_iterator(dir)) {
      if (e.path().filename() != "cloud.ply") fs::remove(e.path());  // the killed writer's leftover
    }
  }
  EXPECT_TRUE(killed_while_writing) << "the fusion finished writing before it could be killed, 5 times";
}

}  // namespace
}  // namespace umvs
