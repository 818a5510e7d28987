// trainer: fine-tunes the served network on recorded bags on request (FineTune service).
#include <ros/ros.h>

#include "unsup_mvs/ros/trainer.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "trainer");
  umvs_ros::Trainer trainer(ros::NodeHandle(), ros::NodeHandle("~"));
  ros::spin();
  return 0;
}
