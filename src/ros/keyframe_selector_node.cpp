// Standalone keyframe_selector node: the keyframe_selector nodelet in its own process (same parameters and topics).
#include "unsup_mvs/ros/nodelets.h"

int main(int argc, char** argv) { return umvs_ros::run_standalone(argc, argv, "keyframe_selector", &umvs_ros::make_keyframe_selector_nodelet); }
