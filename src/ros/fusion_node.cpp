// Standalone fusion node: the fusion nodelet in its own process (same parameters and topics).
#include "unsup_mvs/ros/nodelets.h"

int main(int argc, char** argv) { return umvs_ros::run_standalone(argc, argv, "fusion", &umvs_ros::make_fusion_nodelet); }
