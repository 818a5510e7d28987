#include "unsup_mvs/ros/trainer.h"

#include "unsup_mvs/ReloadModel.h"
#include "unsup_mvs/TrainingProgress.h"
#include "unsup_mvs/ros/params.h"

namespace umvs_ros {

Trainer::Trainer(ros::NodeHandle nh, ros::NodeHandle pnh) : Trainer(nh, pnh, trainer_node_config_from_ros(pnh)) {}

Trainer::Trainer(ros::NodeHandle nh, ros::NodeHandle pnh, const TrainerNodeConfig& config)
    : nh_(nh),
      pnh_(pnh),
      served_checkpoint_(config.served_checkpoint),
      reload_service_(config.reload_service),
      job_(config.job) {
  for (const auto& arg : job_.config().keyframe_args_overridden()) {
    ROS_WARN("trainer: ~train_args sets %s, which overrides ~keyframes/ (the keyframe_selector's settings): "
             "live and offline keyframes may then differ",
             arg.c_str());
  }
  for (const auto& error : job_.setup_errors()) ROS_ERROR("trainer: %s", error.c_str());
  if (const int stale = job_.removed_temp_files()) {
    ROS_WARN("trainer: removed %d temporary file(s) that interrupted writes left in %s", stale,
             job_.config().output_dir.c_str());
  }
  progress_pub_ = pnh_.advertise<unsup_mvs::TrainingProgress>("progress", 10, true);
  fine_tune_srv_ = pnh_.advertiseService("fine_tune", &Trainer::on_fine_tune, this);
  cancel_srv_ = pnh_.advertiseService("cancel", &Trainer::on_cancel, this);
  status_srv_ = pnh_.advertiseService("status", &Trainer::on_status, this);
  timer_ = nh_.createWallTimer(ros::WallDuration(config.poll_period), &Trainer::on_timer, this);
  ROS_INFO("trainer: ready (umvs %s, models into %s, serving %s)", job_.config().umvs_path.c_str(),
           job_.config().output_dir.c_str(),
           served_checkpoint_.empty() ? "<unknown>" : served_checkpoint_.c_str());
}

bool Trainer::on_fine_tune(unsup_mvs::FineTune::Request& req, unsup_mvs::FineTune::Response& res) {
  umvs::FineTuneRequest request;
  request.bags = req.bags;
  request.init_checkpoint = req.init_checkpoint;
  request.steps = req.steps;
  request.output = req.output;
  const umvs::FineTuneAnswer answer = job_.start(request, served_checkpoint_);
  res.accepted = answer.ok;
  res.job_id = answer.job_id;
  res.message = answer.message;
  if (!answer.ok) {
    ROS_WARN("trainer: fine-tuning request refused: %s", answer.message.c_str());
    return true;
  }
  ROS_INFO("trainer: job %s: %s", answer.job_id.c_str(), answer.message.c_str());
  publish(job_.progress());
  return true;
}

bool Trainer::on_cancel(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  const umvs::FineTuneAnswer answer = job_.cancel();
  res.success = answer.ok;
  res.message = answer.message;
  if (answer.ok) publish(job_.progress());
  return true;
}

bool Trainer::on_status(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
  res.success = job_.busy();
  res.message = job_.describe() + "; serving " + served_checkpoint_;
  return true;
}

void Trainer::on_timer(const ros::WallTimerEvent&) {
  auto progress = job_.poll([](const std::string& line) { ROS_DEBUG_NAMED("umvs", "%s", line.c_str()); });
  if (!progress) return;
  if (job_.phase() == umvs::FineTuneJob::Phase::kReadyToReload) progress = reload();
  const std::string& job = progress->job_id;
  if (progress->state == "failed") ROS_ERROR("trainer: job %s failed: %s", job.c_str(), progress->message.c_str());
  if (progress->state == "kept") ROS_WARN("trainer: job %s: %s", job.c_str(), progress->message.c_str());
  if (progress->state == "reloaded") ROS_INFO("trainer: job %s: %s", job.c_str(), progress->message.c_str());
  publish(*progress);
}

const umvs::FineTuneProgress& Trainer::reload() {
  unsup_mvs::ReloadModel srv;
  srv.request.checkpoint = job_.reload_checkpoint();
  const std::string& service = reload_service_;
  if (!ros::service::waitForService(service, ros::Duration(5.0)) || !ros::service::call(service, srv)) {
    return job_.reload_unreachable(service);
  }
  if (srv.response.success) {
    served_checkpoint_ = job_.reload_checkpoint();
    pnh_.setParam("served_checkpoint", served_checkpoint_);
  }
  return job_.reload_result(srv.response.success, srv.response.message);
}

void Trainer::publish(const umvs::FineTuneProgress& p) {
  unsup_mvs::TrainingProgress msg;
  msg.header.stamp = ros::Time::now();
  msg.job_id = p.job_id;
  msg.state = p.state;
  msg.step = p.step;
  msg.total_steps = p.total_steps;
  msg.loss = p.loss;
  msg.photometric = p.photometric;
  msg.ssim = p.ssim;
  msg.smoothness = p.smoothness;
  msg.eta_seconds = p.eta_seconds;
  msg.message = p.message;
  progress_pub_.publish(msg);
}

}  // namespace umvs_ros
