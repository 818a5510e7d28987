// Standalone inference node: the inference nodelet in its own process (same parameters and topics).
#include "unsup_mvs/ros/nodelets.h"

int main(int argc, char** argv) { return umvs_ros::run_standalone(argc, argv, "inference", &umvs_ros::make_inference_nodelet); }
