// The one main() of every rostest executable (test/ros/test_*.cpp): gtest, then a ROS node named
// after the executable, kept up (a NodeHandle) while the tests run.
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <filesystem>

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, std::filesystem::path(argv[0]).filename().string());
  ros::NodeHandle keep_the_node_up;
  return RUN_ALL_TESTS();
}
