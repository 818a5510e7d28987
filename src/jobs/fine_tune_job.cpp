#include "unsup_mvs/jobs/fine_tune_job.h"

#include <unistd.h>

#include <algorithm>
#include <ctime>
#include <filesystem>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/run_folder.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

std::string number(double v) {
  std::ostringstream s;
  s.precision(17);  // round-trips every double
  s << v;
  return s.str();
}

}  // namespace

std::vector<std::string> keyframe_stream_train_args(const KeyframeStreamConfig& stream) {
  const KeyframeConfig& k = stream.keyframes;
  return {"--rectified",      stream.rectified ? "1" : "0",
          "--min-translation", number(k.min_translation),
          "--min-rotation-deg", number(k.min_rotation_deg),
          "--min-pose-distance", number(k.min_pose_distance),
          "--keyframe-buffer", std::to_string(k.buffer_size),
          "--min-view-score",  number(k.min_score),
          "--view-score-grid", std::to_string(k.score_grid),
          "--depth-min",       number(stream.depth_min),
          "--depth-max",       number(stream.depth_max)};
}

void FineTuneConfig::validate() const {
  if (umvs_path.empty() || umvs_path.front() != '/') {
    throw std::invalid_argument("umvs_path must be an absolute path, got '" + umvs_path + "'");
  }
  if (output_dir.empty()) throw std::invalid_argument("output_dir must not be empty");
  if (image_topic.empty()) throw std::invalid_argument("image_topic must not be empty");
  if (camera_info_topic.empty()) throw std::invalid_argument("camera_info_topic must not be empty");
  if (world_frame.empty()) throw std::invalid_argument("world_frame must not be empty");
  if (default_steps < 1) {
    throw std::invalid_argument("default_steps (~steps) must be >= 1, got " + std::to_string(default_steps));
  }
  if (local_ranks < 1) {
    throw std::invalid_argument("local_ranks must be >= 1, got " + std::to_string(local_ranks));
  }
  if (!(fine_tuned_share > 0 && fine_tuned_share <= 1)) {
    throw std::invalid_argument("fine_tuned_share must be in (0, 1] (1 = no blend), got " + number(fine_tuned_share));
  }
  parse_device(device);  // throws naming the device
  // The job sets these itself for every training and evaluation run.
  for (const char* reserved : {"--bag", "--data", "--init", "--steps", "--out", "--eval-only", "--fine-tuned-share", "--device"}) {
    if (std::find(train_args.begin(), train_args.end(), reserved) != train_args.end()) {
      throw std::invalid_argument(std::string("train_args must not set ") + reserved + ": every job sets it");
    }
  }
  // A job is one machine's ranks; their number is local_ranks, so that evaluations stay one process.
  for (const char* reserved : {"--nproc", "--world-size", "--rank", "--master"}) {
    if (std::find(train_args.begin(), train_args.end(), reserved) != train_args.end()) {
      throw std::invalid_argument(std::string("train_args must not set ") + reserved + ": set local_ranks instead");
    }
  }
  try {
    keyframes.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("keyframes: ") + e.what());
  }
}

std::vector<std::string> FineTuneConfig::keyframe_args_overridden() const {
  std::vector<std::string> overridden;
  const auto stream_args = keyframe_stream_train_args(keyframes);
  for (size_t i = 0; i < stream_args.size(); i += 2) {
    if (std::find(train_args.begin(), train_args.end(), stream_args[i]) != train_args.end()) {
      overridden.push_back(stream_args[i]);
    }
  }
  return overridden;
}

std::optional<EvalScores> eval_scores(const EvalRow& row) {
  if (!row.photometric || !row.consistent) return std::nullopt;
  return EvalScores{*row.photometric, *row.consistent};
}

bool read_eval_scores(const std::string& eval_csv, EvalScores* scores) {
  CsvRow row;
  if (!read_last_csv_row(eval_csv, &row)) return false;
  const auto read = eval_scores(eval_row(row));
  if (!read) return false;
  *scores = *read;
  return true;
}

ReloadVerdict decide_reload(const EvalScores& candidate, const EvalScores& served) {
  ReloadVerdict v;
  std::ostringstream cmp;
  cmp.precision(5);
  cmp << "held-out photometric loss: new " << candidate.photometric << ", served " << served.photometric
      << "; multi-view consistent depth: new " << 100.0 * candidate.consistent << "%, served "
      << 100.0 * served.consistent << "%";
  v.comparison = cmp.str();
  v.reload = candidate.photometric < (1.0 - kMinPhotometricGain) * served.photometric &&
             candidate.consistent >= served.consistent + kMinConsistentGain;
  return v;
}

namespace {

bool readable_file(const std::string& path) {
  return fs::is_regular_file(path) && ::access(path.c_str(), R_OK) == 0;
}

// ft-YYYYmmdd-HHMMSS (UTC), with a suffix when a job of the same second already has a folder.
std::string make_job_id(const std::string& output_dir) {
  char buf[32];
  const std::time_t now = std::time(nullptr);
  std::strftime(buf, sizeof(buf), "ft-%Y%m%d-%H%M%S", std::gmtime(&now));
  std::string id = buf;
  for (int n = 2; fs::exists(output_dir + "/" + id); ++n) id = std::string(buf) + "-" + std::to_string(n);
  return id;
}

}  // namespace

FineTuneJob::FineTuneJob(FineTuneConfig config) : config_(std::move(config)) {
  config_.validate();
  std::error_code ec;
  fs::create_directories(config_.output_dir, ec);
  if (ec) setup_errors_.push_back("cannot create output_dir '" + config_.output_dir + "': " + ec.message());
  // A trainer killed mid-job left at most temporary files behind (its training process died with
  // it, see ChildProcess): no writer is active in output_dir now, so they can go.
  if (!ec) removed_temp_files_ = remove_stale_temp_files(config_.output_dir);
  if (::access(config_.umvs_path.c_str(), X_OK) != 0) {
    setup_errors_.push_back("umvs_path '" + config_.umvs_path + "' is not an executable; fine-tuning requests will fail");
  }
}

std::vector<std::string> FineTuneJob::data_args() const {
  std::vector<std::string> args;
  for (const auto& b : bags_) {
    args.push_back("--bag");
    args.push_back(b);
  }
  args.insert(args.end(), {"--image-topic", config_.image_topic, "--camera-info-topic", config_.camera_info_topic,
                           "--world-frame", config_.world_frame, "--device", config_.device});
  const auto stream_args = keyframe_stream_train_args(config_.keyframes);
  args.insert(args.end(), stream_args.begin(), stream_args.end());
  args.insert(args.end(), config_.train_args.begin(), config_.train_args.end());
  return args;
}

FineTuneAnswer FineTuneJob::start(const FineTuneRequest& req, const std::string& served) {
  FineTuneAnswer refused;
  auto refuse = [&](const std::string& why) {
    refused.message = why;
    return refused;
  };
  const std::string& output_dir = config_.output_dir;
  if (busy()) return refuse("job " + progress_.job_id + " is still running; cancel it first");
  if (req.bags.empty()) return refuse("no bag given");
  for (const auto& b : req.bags) {
    if (!fs::exists(b)) return refuse("bag '" + b + "' does not exist");
    if (!readable_file(b)) return refuse("bag '" + b + "' is not a readable file");
  }
  const std::string init = req.init_checkpoint.empty() ? served : req.init_checkpoint;
  if (init.empty()) return refuse("no init_checkpoint given and no ~served_checkpoint known");
  if (!readable_file(init)) return refuse("checkpoint '" + init + "' is missing or unreadable");
  if (served.empty() || !readable_file(served)) {
    return refuse("the served model ~served_checkpoint '" + served + "' is unreadable: nothing to compare with");
  }
  if (req.steps < 0) return refuse("steps must not be negative");
  const std::string job_id = make_job_id(output_dir);
  const std::string output = req.output.empty() ? output_dir + "/" + job_id + ".pt" : req.output;
  if (!path_inside(output, output_dir)) {
    return refuse("output '" + output + "' is outside the allowed folder " + output_dir);
  }
  std::error_code ec;
  if (fs::exists(fs::symlink_status(output, ec))) {
    return refuse("output '" + output + "' already exists; a fine-tuned model is only written under a new name");
  }

  const std::string job_dir = output_dir + "/" + job_id;
  bags_ = req.bags;
  std::vector<std::string> argv = {config_.umvs_path, "train"};
  const auto data = data_args();
  argv.insert(argv.end(), data.begin(), data.end());
  const int steps = req.steps > 0 ? req.steps : config_.default_steps;
  argv.insert(argv.end(), {"--init", init, "--steps", std::to_string(steps), "--out", job_dir});
  if (config_.local_ranks > 1) argv.insert(argv.end(), {"--nproc", std::to_string(config_.local_ranks)});
  if (config_.fine_tuned_share < 1) argv.insert(argv.end(), {"--fine-tuned-share", number(config_.fine_tuned_share)});
  try {
    fs::create_directories(job_dir);
    child_.start(argv);
  } catch (const std::exception& e) {
    return refuse(std::string("cannot start training: ") + e.what());
  }
  job_dir_ = job_dir;
  output_path_ = output;
  served_checkpoint_ = served;
  comparison_.clear();
  started_ = std::chrono::steady_clock::now();
  phase_ = Phase::kTraining;
  progress_ = FineTuneProgress();
  progress_.job_id = job_id;
  progress_.total_steps = steps;
  progress_.eta_seconds = -1.f;
  FineTuneAnswer accepted;
  accepted.ok = true;
  accepted.job_id = job_id;
  accepted.message = "training " + std::to_string(steps) + " steps from " + init + " in " + job_dir_;
  report("training", accepted.message);
  return accepted;
}

FineTuneAnswer FineTuneJob::cancel() {
  FineTuneAnswer answer;
  if (!busy()) {
    answer.message = "no job is running";
    return answer;
  }
  child_.stop();
  if (phase_ == Phase::kReadyToReload) {
    std::error_code ec;
    fs::remove(output_path_, ec);
  }
  phase_ = Phase::kIdle;
  remove_stale_temp_files(job_dir_);
  answer.ok = true;
  answer.job_id = progress_.job_id;
  answer.message = "job " + progress_.job_id + " cancelled; the served model is unchanged";
  report("cancelled", answer.message);
  return answer;
}

void FineTuneJob::read_training_log() {
  CsvRow csv;
  if (!read_last_csv_row(job_dir_ + "/train_log.csv", &csv)) return;
  TrainLogRow row;
  try {
    row = train_log_row(csv);
  } catch (const std::runtime_error&) {
    return;  // a row being written
  }
  FineTuneProgress& p = progress_;
  p.step = static_cast<int>(row.step);
  p.loss = static_cast<float>(row.total.value_or(p.loss));
  p.photometric = static_cast<float>(row.photometric.value_or(p.photometric));
  p.ssim = static_cast<float>(row.ssim.value_or(p.ssim));
  p.smoothness = static_cast<float>(row.smoothness.value_or(p.smoothness));
  const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - started_).count();
  p.eta_seconds = p.step > 0 ? static_cast<float>(elapsed / p.step * (p.total_steps - p.step)) : -1.f;
}

std::string FineTuneJob::candidate_path() const {
  return job_dir_ + (config_.fine_tuned_share < 1 ? "/blended.pt" : "/best.pt");
}

void FineTuneJob::start_evaluation(const std::string& checkpoint, const std::string& out_dir, Phase phase) {
  std::vector<std::string> argv = {config_.umvs_path, "train"};
  const auto data = data_args();
  argv.insert(argv.end(), data.begin(), data.end());
  argv.insert(argv.end(), {"--eval-only", checkpoint, "--out", out_dir});
  child_.start(argv);
  phase_ = phase;
}

std::optional<FineTuneProgress> FineTuneJob::poll(const std::function<void(const std::string&)>& on_line) {
  if (phase_ == Phase::kIdle || phase_ == Phase::kReadyToReload) return std::nullopt;
  std::string last_line;
  const bool alive = child_.poll([&](const std::string& line) {
    if (on_line) on_line(line);
    last_line = line;
  });
  if (!last_line.empty()) progress_.message = last_line;
  if (alive) {
    if (phase_ != Phase::kTraining) return std::nullopt;
    read_training_log();
    return report("training", progress_.message);
  }
  const int status = child_.exit_status();
  try {
    if (status != 0) {
      std::ostringstream s;
      s << "umvs train " << (phase_ == Phase::kTraining ? "" : "--eval-only ") << "exited with status " << status
        << " (" << progress_.message << "); the served model is unchanged";
      phase_ = Phase::kIdle;
      remove_stale_temp_files(job_dir_);  // what the killed or failed process was writing
      return report("failed", s.str());
    }
    if (phase_ == Phase::kTraining) {
      read_training_log();
      start_evaluation(candidate_path(), job_dir_ + "/eval_new", Phase::kEvaluatingNew);
      return report("evaluating", "training done; comparing with the served model on held-out keyframes");
    }
    if (phase_ == Phase::kEvaluatingNew) {
      if (!read_eval_scores(job_dir_ + "/eval_new/eval.csv", &new_scores_)) {
        throw std::runtime_error("no evaluation of the new model");
      }
      start_evaluation(served_checkpoint_, job_dir_ + "/eval_served", Phase::kEvaluatingServed);
      return std::nullopt;
    }
    return finish();
  } catch (const std::exception& e) {
    phase_ = Phase::kIdle;
    return report("failed", std::string(e.what()) + "; the served model is unchanged");
  }
}

FineTuneProgress FineTuneJob::finish() {
  phase_ = Phase::kIdle;
  EvalScores served;
  if (!read_eval_scores(job_dir_ + "/eval_served/eval.csv", &served)) {
    throw std::runtime_error("no evaluation of the served model");
  }
  const ReloadVerdict verdict = decide_reload(new_scores_, served);
  comparison_ = verdict.comparison;
  if (!verdict.reload) return report("kept", comparison_ + ": the served model stays");
  // Publish under the new name only (never replacing anything, not through a planted link), then
  // let inference check it; a model inference refuses does not stay under the output name.
  try {
    copy_file_to_new_name(candidate_path(), output_path_);
  } catch (const std::exception& e) {
    return report("failed", comparison_ + "; the new model stays in " + job_dir_ + ": " + e.what());
  }
  phase_ = Phase::kReadyToReload;
  return report("ready to reload", comparison_);
}

const FineTuneProgress& FineTuneJob::reload_result(bool ok, const std::string& message) {
  if (phase_ != Phase::kReadyToReload) throw std::logic_error("reload_result: the job is not ready to reload");
  phase_ = Phase::kIdle;
  if (!ok) {
    std::error_code ec;
    fs::remove(output_path_, ec);
    return report("failed", comparison_ + "; inference refused the new model (kept in " + job_dir_ + "): " + message);
  }
  return report("reloaded", comparison_ + "; now serving " + output_path_);
}

const FineTuneProgress& FineTuneJob::reload_unreachable(const std::string& service) {
  if (phase_ != Phase::kReadyToReload) throw std::logic_error("reload_unreachable: the job is not ready to reload");
  phase_ = Phase::kIdle;
  return report("failed", comparison_ + "; new model saved to " + output_path_ + " but " + service + " is not reachable");
}

const FineTuneProgress& FineTuneJob::report(const std::string& state, const std::string& message) {
  progress_.state = state;
  progress_.message = message;
  return progress_;
}

std::string FineTuneJob::describe() const {
  std::ostringstream s;
  s << (progress_.job_id.empty() ? "no job yet" : "job " + progress_.job_id) << ": "
    << (progress_.state.empty() ? "idle" : progress_.state) << ", step " << progress_.step << "/"
    << progress_.total_steps << "; " << progress_.message;
  return s.str();
}

}  // namespace umvs
