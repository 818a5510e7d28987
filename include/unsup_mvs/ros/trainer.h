// The trainer node: fine-tunes the network on recorded bags without ground truth, on request.
//
// The job itself lives in umvs::FineTuneJob (jobs/fine_tune_job.h, ROS-free and unit-tested in
// test/test_fine_tune_job.cpp): it checks a request (bags exist and are readable, output inside
// ~output_dir and not an existing name, one job at a time), runs `umvs train --bag ...` as a child
// process (an argument list, never a shell), reads step, loss terms and ETA from the job's
// train_log.csv, evaluates the new and the served model on the same held-out keyframes
// (`umvs train --eval-only`) and decides (decide_reload: lower photometric loss AND more depth
// confirmed by other views) whether the new model is copied to the (new) output path.
//
// This node only reads the parameters (TrainerNodeConfig, ros/params.h), offers ~fine_tune,
// ~cancel and ~status, publishes ~progress (TrainingProgress) from a wall timer every
// ~poll_period, and calls inference's reload_model when the job is ready to reload; if inference
// refuses the model, the job removes the copy again. A crash or kill of the child touches neither
// inference nor fusion; a kill of the node kills the child, and a restarted node removes the
// temporary files left in ~output_dir.
#pragma once

#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <string>

#include "unsup_mvs/FineTune.h"
#include "unsup_mvs/jobs/fine_tune_job.h"

namespace umvs_ros {

struct TrainerNodeConfig;  // ros/params.h (not included here: it brings in torch)

class Trainer {
 public:
  // Throws std::invalid_argument naming an invalid parameter.
  Trainer(ros::NodeHandle nh, ros::NodeHandle pnh);

 private:
  Trainer(ros::NodeHandle nh, ros::NodeHandle pnh, const TrainerNodeConfig& config);
  bool on_fine_tune(unsup_mvs::FineTune::Request& req, unsup_mvs::FineTune::Response& res);
  bool on_cancel(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  bool on_status(std_srvs::Trigger::Request& req, std_srvs::Trigger::Response& res);
  void on_timer(const ros::WallTimerEvent&);
  const umvs::FineTuneProgress& reload();  // calls ~reload_service with the job's new model
  void publish(const umvs::FineTuneProgress& progress);

  ros::NodeHandle nh_, pnh_;
  std::string served_checkpoint_;  // ~served_checkpoint, then each model reloaded
  std::string reload_service_;
  umvs::FineTuneJob job_;
  ros::ServiceServer fine_tune_srv_, cancel_srv_, status_srv_;
  ros::Publisher progress_pub_;
  ros::WallTimer timer_;  // wall time: jobs must progress when /clock stops (bag replay ended)
};

}  // namespace umvs_ros
