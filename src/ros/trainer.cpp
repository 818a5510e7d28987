#include "unsup_mvs/ros/trainer.h"

#include <unistd.h>

#include <algorithm>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "unsup_mvs/ReloadModel.h"
#include "unsup_mvs/io/ros/bag_training_data.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/ros/params.h"

namespace umvs_ros {

namespace fs = std::filesystem;

bool read_eval_scores(const std::string& eval_csv, EvalScores* scores) {
  umvs::CsvRow row;
  if (!umvs::read_last_csv_row(eval_csv, &row)) return false;
  const umvs::EvalRow eval = umvs::eval_row(row);
  if (!eval.photometric || !eval.consistent) return false;
  scores->photometric = *eval.photometric;
  scores->consistent = *eval.consistent;
  return true;
}

namespace {

std::string default_umvs_path() {
  // The tool is built next to this node's executable (devel/lib/unsup_mvs/).
  std::error_code ec;
  const fs::path self = fs::read_symlink("/proc/self/exe", ec);
  return ec ? std::string() : (self.parent_path() / "umvs").string();
}

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

Trainer::Trainer(ros::NodeHandle nh, ros::NodeHandle pnh) : nh_(nh), pnh_(pnh) {
  umvs_path_ = pnh_.param<std::string>("umvs_path", default_umvs_path());
  output_dir_ = pnh_.param<std::string>("output_dir", "");
  if (output_dir_.empty()) {
    output_dir_ = std::string(std::getenv("HOME") ? std::getenv("HOME") : "/tmp") + "/.ros/unsup_mvs_models";
  }
  served_checkpoint_ = pnh_.param<std::string>("served_checkpoint", "");
  reload_service_ = pnh_.param<std::string>("reload_service", "/unsup_mvs/inference/reload_model");
  image_topic_ = pnh_.param<std::string>("image_topic", "/camera/image_rect_color");
  camera_info_topic_ = pnh_.param<std::string>("camera_info_topic", "/camera/camera_info");
  world_frame_ = pnh_.param<std::string>("world_frame", "world");
  default_steps_ = pnh_.param("steps", 500);
  pnh_.getParam("train_args", extra_train_args_);
  // The bags are read as the keyframe_selector reads the live stream: the launch files load its
  // YAML (and ~rectified) into ~keyframes/ too.
  try {
    keyframe_stream_ = keyframe_stream_config_from_ros(ros::NodeHandle(pnh_, "keyframes"));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("invalid ~keyframes/ parameters: ") + e.what());
  }
  const auto stream_args = umvs::keyframe_stream_train_args(keyframe_stream_);
  for (size_t i = 0; i < stream_args.size(); i += 2) {
    if (std::find(extra_train_args_.begin(), extra_train_args_.end(), stream_args[i]) != extra_train_args_.end()) {
      ROS_WARN("trainer: ~train_args sets %s, which overrides ~keyframes/ (the keyframe_selector's settings): "
               "live and offline keyframes may then differ",
               stream_args[i].c_str());
    }
  }
  std::error_code ec;
  fs::create_directories(output_dir_, ec);
  if (ec) ROS_ERROR("trainer: cannot create ~output_dir '%s': %s", output_dir_.c_str(), ec.message().c_str());
  // A trainer killed mid-job left at most temporary files behind (its training process died with
  // it, see ChildProcess): no writer is active in ~output_dir now, so they can go.
  if (const int stale = umvs::remove_stale_temp_files(output_dir_)) {
    ROS_WARN("trainer: removed %d temporary file(s) that interrupted writes left in %s", stale, output_dir_.c_str());
  }
  if (::access(umvs_path_.c_str(), X_OK) != 0) {
    ROS_ERROR("trainer: ~umvs_path '%s' is not an executable; fine-tuning requests will fail", umvs_path_.c_str());
  }
  progress_pub_ = pnh_.advertise<unsup_mvs::TrainingProgress>("progress", 10, true);
  fine_tune_srv_ = pnh_.advertiseService("fine_tune", &Trainer::on_fine_tune, this);
  cancel_srv_ = pnh_.advertiseService("cancel", &Trainer::on_cancel, this);
  status_srv_ = pnh_.advertiseService("status", &Trainer::on_status, this);
  timer_ = nh_.createWallTimer(ros::WallDuration(pnh_.param("poll_period", 0.5)), &Trainer::on_timer, this);
  ROS_INFO("trainer: ready (umvs %s, models into %s, serving %s)", umvs_path_.c_str(), output_dir_.c_str(),
           served_checkpoint_.empty() ? "<unknown>" : served_checkpoint_.c_str());
}

std::vector<std::string> Trainer::data_args() const {
  std::vector<std::string> args;
  for (const auto& b : bags_) {
    args.push_back("--bag");
    args.push_back(b);
  }
  args.insert(args.end(), {"--image-topic", image_topic_, "--camera-info-topic", camera_info_topic_, "--world-frame",
                           world_frame_});
  const auto stream_args = umvs::keyframe_stream_train_args(keyframe_stream_);
  args.insert(args.end(), stream_args.begin(), stream_args.end());
  args.insert(args.end(), extra_train_args_.begin(), extra_train_args_.end());
  return args;
}

bool Trainer::on_fine_tune(unsup_mvs::FineTune::Request& req, unsup_mvs::FineTune::Response& res) {
  res.accepted = false;
  auto refuse = [&](const std::string& why) {
    res.message = why;
    ROS_WARN("trainer: fine-tuning request refused: %s", why.c_str());
    return true;
  };
  if (phase_ != Phase::kIdle) return refuse("job " + job_id_ + " is still running; cancel it first");
  if (req.bags.empty()) return refuse("no bag given");
  for (const auto& b : req.bags) {
    if (!fs::exists(b)) return refuse("bag '" + b + "' does not exist");
    if (!readable_file(b)) return refuse("bag '" + b + "' is not a readable file");
  }
  const std::string init = req.init_checkpoint.empty() ? served_checkpoint_ : req.init_checkpoint;
  if (init.empty()) return refuse("no init_checkpoint given and no ~served_checkpoint known");
  if (!readable_file(init)) return refuse("checkpoint '" + init + "' is missing or unreadable");
  if (served_checkpoint_.empty() || !readable_file(served_checkpoint_)) {
    return refuse("the served model ~served_checkpoint '" + served_checkpoint_ + "' is unreadable: nothing to compare with");
  }
  if (req.steps < 0) return refuse("steps must not be negative");
  const std::string job_id = make_job_id(output_dir_);
  const std::string output = req.output.empty() ? output_dir_ + "/" + job_id + ".pt" : req.output;
  if (!umvs::path_inside(output, output_dir_)) {
    return refuse("output '" + output + "' is outside the allowed folder " + output_dir_);
  }
  std::error_code ec;
  if (fs::exists(fs::symlink_status(output, ec))) {
    return refuse("output '" + output + "' already exists; a fine-tuned model is only written under a new name");
  }

  job_id_ = job_id;
  job_dir_ = output_dir_ + "/" + job_id_;
  output_path_ = output;
  init_checkpoint_ = init;
  bags_ = req.bags;
  std::vector<std::string> argv = {umvs_path_, "train"};
  const auto data = data_args();
  argv.insert(argv.end(), data.begin(), data.end());
  const int steps = req.steps > 0 ? req.steps : default_steps_;
  argv.insert(argv.end(), {"--init", init, "--steps", std::to_string(steps), "--out", job_dir_});
  try {
    fs::create_directories(job_dir_);
    child_.start(argv);
  } catch (const std::exception& e) {
    return refuse(std::string("cannot start training: ") + e.what());
  }
  started_ = ros::WallTime::now();
  phase_ = Phase::kTraining;
  last_ = unsup_mvs::TrainingProgress();
  last_.total_steps = steps;
  last_.eta_seconds = -1;
  res.accepted = true;
  res.job_id = job_id_;
  res.message = "training " + std::to_string(steps) + " steps from " + init + " in " + job_dir_;
  ROS_INFO("trainer: job %s: %s", job_id_.c_str(), res.message.c_str());
  publish("training", res.message);
  return true;
}

bool Trainer::on_cancel(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  if (phase_ == Phase::kIdle) {
    res.success = false;
    res.message = "no job is running";
    return true;
  }
  child_.stop();
  phase_ = Phase::kIdle;
  umvs::remove_stale_temp_files(job_dir_);
  res.success = true;
  res.message = "job " + job_id_ + " cancelled; the served model is unchanged";
  publish("cancelled", res.message);
  return true;
}

bool Trainer::on_status(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  res.success = phase_ != Phase::kIdle;
  std::ostringstream s;
  s << (job_id_.empty() ? "no job yet" : "job " + job_id_) << ": " << (last_.state.empty() ? "idle" : last_.state)
    << ", step " << last_.step << "/" << last_.total_steps << "; " << last_.message << "; serving "
    << served_checkpoint_;
  res.message = s.str();
  return true;
}

void Trainer::read_training_log() {
  umvs::CsvRow csv;
  if (!umvs::read_last_csv_row(job_dir_ + "/train_log.csv", &csv)) return;
  umvs::TrainLogRow row;
  try {
    row = umvs::train_log_row(csv);
  } catch (const std::runtime_error&) {
    return;  // a row being written
  }
  last_.step = static_cast<int>(row.step);
  last_.loss = static_cast<float>(row.total.value_or(last_.loss));
  last_.photometric = static_cast<float>(row.photometric.value_or(last_.photometric));
  last_.ssim = static_cast<float>(row.ssim.value_or(last_.ssim));
  last_.smoothness = static_cast<float>(row.smoothness.value_or(last_.smoothness));
  const double elapsed = (ros::WallTime::now() - started_).toSec();
  last_.eta_seconds = last_.step > 0 ? static_cast<float>(elapsed / last_.step * (last_.total_steps - last_.step)) : -1.f;
}

void Trainer::start_evaluation(const std::string& checkpoint, const std::string& out_dir, Phase phase) {
  std::vector<std::string> argv = {umvs_path_, "train"};
  const auto data = data_args();
  argv.insert(argv.end(), data.begin(), data.end());
  argv.insert(argv.end(), {"--eval-only", checkpoint, "--out", out_dir});
  child_.start(argv);
  phase_ = phase;
}

void Trainer::on_timer(const ros::WallTimerEvent&) {
  if (phase_ == Phase::kIdle) return;
  std::string last_line;
  const bool alive = child_.poll([&](const std::string& line) {
    ROS_DEBUG_NAMED("umvs", "%s", line.c_str());
    last_line = line;
  });
  if (!last_line.empty()) last_.message = last_line;
  if (alive) {
    if (phase_ == Phase::kTraining) {
      read_training_log();
      publish("training", last_.message);
    }
    return;
  }
  const int status = child_.exit_status();
  try {
    if (status != 0) {
      std::ostringstream s;
      s << "umvs train " << (phase_ == Phase::kTraining ? "" : "--eval-only ") << "exited with status " << status
        << " (" << last_.message << "); the served model is unchanged";
      phase_ = Phase::kIdle;
      umvs::remove_stale_temp_files(job_dir_);  // what the killed or failed process was writing
      ROS_ERROR("trainer: job %s failed: %s", job_id_.c_str(), s.str().c_str());
      publish("failed", s.str());
      return;
    }
    if (phase_ == Phase::kTraining) {
      read_training_log();
      publish("evaluating", "training done; comparing with the served model on held-out keyframes");
      start_evaluation(job_dir_ + "/best.pt", job_dir_ + "/eval_new", Phase::kEvaluatingNew);
    } else if (phase_ == Phase::kEvaluatingNew) {
      if (!read_eval_scores(job_dir_ + "/eval_new/eval.csv", &new_scores_)) throw std::runtime_error("no evaluation of the new model");
      start_evaluation(served_checkpoint_, job_dir_ + "/eval_served", Phase::kEvaluatingServed);
    } else {
      finish_job();
    }
  } catch (const std::exception& e) {
    phase_ = Phase::kIdle;
    publish("failed", std::string(e.what()) + "; the served model is unchanged");
  }
}

void Trainer::finish_job() {
  phase_ = Phase::kIdle;
  EvalScores served;
  if (!read_eval_scores(job_dir_ + "/eval_served/eval.csv", &served)) {
    throw std::runtime_error("no evaluation of the served model");
  }
  std::ostringstream cmp;
  cmp.precision(5);
  cmp << "held-out photometric loss: new " << new_scores_.photometric << ", served " << served.photometric
      << "; multi-view consistent depth: new " << 100.0 * new_scores_.consistent << "%, served "
      << 100.0 * served.consistent << "%";
  // A lower photometric loss alone does not mean better depth (it can fall while depth gets
  // worse): the new model must also have more depth that other views confirm.
  // Too little confirmed depth (< 1 % of the held-out pixels) is no evidence either way: keep.
  constexpr double kMinConsistentShare = 0.01;
  if (!(new_scores_.photometric < served.photometric && new_scores_.consistent > served.consistent &&
        new_scores_.consistent >= kMinConsistentShare)) {
    publish("kept", cmp.str() + ": the served model stays");
    ROS_WARN("trainer: job %s: %s: the served model stays", job_id_.c_str(), cmp.str().c_str());
    return;
  }
  // Publish under the new name only (never replacing anything, not through a planted link), then
  // let inference check it; a model inference refuses does not stay under the output name.
  try {
    umvs::copy_file_to_new_name(job_dir_ + "/best.pt", output_path_);
  } catch (const std::exception& e) {
    publish("failed", cmp.str() + "; the new model stays in " + job_dir_ + ": " + e.what());
    return;
  }
  unsup_mvs::ReloadModel srv;
  srv.request.checkpoint = output_path_;
  if (!ros::service::waitForService(reload_service_, ros::Duration(5.0)) || !ros::service::call(reload_service_, srv)) {
    publish("failed", cmp.str() + "; new model saved to " + output_path_ + " but " + reload_service_ + " is not reachable");
    return;
  }
  if (!srv.response.success) {
    std::error_code ec;
    fs::remove(output_path_, ec);
    publish("failed", cmp.str() + "; inference refused the new model (kept in " + job_dir_ + "): " + srv.response.message);
    return;
  }
  served_checkpoint_ = output_path_;
  pnh_.setParam("served_checkpoint", served_checkpoint_);
  publish("reloaded", cmp.str() + "; now serving " + output_path_);
  ROS_INFO("trainer: job %s: %s; now serving %s", job_id_.c_str(), cmp.str().c_str(), output_path_.c_str());
}

void Trainer::publish(const std::string& state, const std::string& message) {
  last_.header.stamp = ros::Time::now();
  last_.job_id = job_id_;
  last_.state = state;
  last_.message = message;
  progress_pub_.publish(last_);
}

}  // namespace umvs_ros
