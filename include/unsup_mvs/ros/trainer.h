// The trainer node: fine-tunes the network on recorded bags without ground truth, on request.
//
// FineTune (~fine_tune) validates the request (bags exist and are readable, output inside
// ~output_dir and not an existing name, one job at a time) and runs `umvs train --bag ...` as a child process (an argument
// list, never a shell). While it runs, ~progress (TrainingProgress) reports step, loss terms and
// ETA from the job's train_log.csv. When training ends, the new and the served model are both
// evaluated on the same held-out keyframes (`umvs train --eval-only`); only if the new model's
// photometric loss is lower is it copied to the (new) output path and the inference nodelet's
// reload_model service called; if inference refuses it, the copy is removed again. A crash or kill
// of the child touches neither inference nor fusion; a kill of the node kills the child, and a
// restarted node removes the temporary files left in ~output_dir.
#pragma once

#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <memory>
#include <string>
#include <vector>

#include "unsup_mvs/FineTune.h"
#include "unsup_mvs/TrainingProgress.h"
#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/io/child_process.h"

namespace umvs_ros {

// What the trainer compares between a fine-tuned and the served model (label-free).
struct EvalScores {
  double photometric = 0.0;  // held-out photometric loss (lower is better)
  double consistent = 0.0;   // share of held-out depth confirmed by other views (higher is better)
};

class Trainer {
 public:
  Trainer(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  enum class Phase { kIdle, kTraining, kEvaluatingNew, kEvaluatingServed };

  bool on_fine_tune(unsup_mvs::FineTune::Request& req, unsup_mvs::FineTune::Response& res);
  bool on_cancel(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool on_status(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void on_timer(const ros::WallTimerEvent&);

  std::vector<std::string> data_args() const;  // --bag ... and the topic/size options
  void start_evaluation(const std::string& checkpoint, const std::string& out_dir, Phase phase);
  void finish_job();
  void publish(const std::string& state, const std::string& message);
  void read_training_log();

  ros::NodeHandle nh_, pnh_;
  ros::ServiceServer fine_tune_srv_, cancel_srv_, status_srv_;
  ros::Publisher progress_pub_;
  ros::WallTimer timer_;  // wall time: jobs must progress when /clock stops (bag replay ended)

  // parameters
  std::string umvs_path_, output_dir_, served_checkpoint_, reload_service_;
  std::string image_topic_, camera_info_topic_, world_frame_;
  int default_steps_ = 500;
  std::vector<std::string> extra_train_args_;
  umvs::KeyframeStreamConfig keyframe_stream_;  // ~keyframes/: how umvs train reads the bags

  // the current job
  Phase phase_ = Phase::kIdle;
  umvs::ChildProcess child_;
  std::string job_id_, job_dir_, output_path_, init_checkpoint_;
  std::vector<std::string> bags_;
  unsup_mvs::TrainingProgress last_;
  EvalScores new_scores_;
  ros::WallTime started_;
};

// Reads the held-out photometric loss and multi-view consistency from an eval.csv written by
// `umvs train --eval-only ... --out DIR`. Returns false when the file is missing or malformed.
bool read_eval_scores(const std::string& eval_csv, EvalScores* scores);

}  // namespace umvs_ros
