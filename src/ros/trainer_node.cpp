// trainer: fine-tunes the served network on recorded bags on request (FineTune service).
#include <ros/ros.h>

#include <exception>

#include "unsup_mvs/ros/trainer.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "trainer");
  try {
    umvs_ros::Trainer trainer(ros::NodeHandle(), ros::NodeHandle("~"));
    ros::spin();
  } catch (const std::exception& e) {
    ROS_FATAL("trainer: %s", e.what());
    return 1;
  }
  return 0;
}
