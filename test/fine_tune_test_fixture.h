// The fixture of the FineTuneJob tests (jobs/fine_tune_job.h): a fake `umvs` (a shell script that
// copies the train_log.csv / eval.csv the test prepared into the job's folders, writes best.pt and
// exits with the status the test asks for), the files it reads, and polling with a deadline.
#pragma once

#include <gtest/gtest.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <thread>
#include <vector>

#include "test_util.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/jobs/fine_tune_job.h"

namespace umvs::fine_tune_test {

namespace fs = std::filesystem;

inline std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

inline void write_text(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

inline std::vector<std::string> lines_of(const std::string& path) {
  std::vector<std::string> lines;
  std::ifstream in(path);
  for (std::string l; std::getline(in, l);) lines.push_back(l);
  return lines;
}

inline std::string join(const std::vector<std::string>& words) {
  std::string s;
  for (const auto& w : words) s += (s.empty() ? "" : " ") + w;
  return s;
}

// The fake umvs: `train ... --out DIR` copies FAKE/train_log.csv to DIR (when prepared), writes
// DIR/best.pt (and DIR/blended.pt with --fine-tuned-share), waits while FAKE/hold exists, prints
// "step 100 done" and exits with FAKE/train_status (default 0); `train ... --eval-only CKPT --out
// DIR` copies FAKE/eval_new.csv (CKPT ends in best.pt or blended.pt) or FAKE/eval_served.csv to
// DIR/eval.csv. Each call appends its arguments to FAKE/calls.
inline constexpr char kFakeUmvs[] = R"(#!/bin/sh
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

inline std::string eval_csv(double photometric, double consistent) {
  EvalRow row;
  row.checkpoint = "model.pt";
  row.tuples = 4;
  row.photometric = photometric;
  row.total = photometric;
  row.consistent = consistent;
  return csv_header(eval_columns()) + "\n" + format_csv_row(row) + "\n";
}

inline TrainLogRow log_row(int64_t step, double total, double photometric, double ssim, double smoothness) {
  TrainLogRow row;
  row.step = step;
  row.total = total;
  row.photometric = photometric;
  row.ssim = ssim;
  row.smoothness = smoothness;
  return row;
}

// "held-out photometric loss: new 0.1, served 0.12; ..." for the scores the tests use most.
inline constexpr char kBetterComparison[] =
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

}  // namespace umvs::fine_tune_test
