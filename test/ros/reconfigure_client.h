// Live tuning from a test: a dynamic_reconfigure request built field by field and sent to a
// node's set_parameters service.
#pragma once

#include <dynamic_reconfigure/Config.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <string>

namespace umvs_test {

struct Request {
  dynamic_reconfigure::Config config;
  Request& set(const std::string& name, double value) {
    dynamic_reconfigure::DoubleParameter p;
    p.name = name;
    p.value = value;
    config.doubles.push_back(p);
    return *this;
  }
  Request& set(const std::string& name, int value) {
    dynamic_reconfigure::IntParameter p;
    p.name = name;
    p.value = value;
    config.ints.push_back(p);
    return *this;
  }
};

// Calls <node>/set_parameters and returns the config the node reports back (an empty request
// just reads it).
inline dynamic_reconfigure::Config reconfigure(const std::string& node, const Request& request = {}) {
  ros::NodeHandle nh;
  ros::ServiceClient client = nh.serviceClient<dynamic_reconfigure::Reconfigure>(node + "/set_parameters");
  EXPECT_TRUE(client.waitForExistence(ros::Duration(30.0))) << node << " offers no set_parameters";
  dynamic_reconfigure::Reconfigure srv;
  srv.request.config = request.config;
  EXPECT_TRUE(client.call(srv)) << node << "/set_parameters failed";
  return srv.response.config;
}

}  // namespace umvs_test
