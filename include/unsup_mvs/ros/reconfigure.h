// Live tuning: a dynamic_reconfigure server (cfg/*.cfg) on a node's private namespace that hands
// each request to the node, which validates it as at start-up and applies it or refuses it. A
// refused request changes nothing: the server reports (and answers with) the values in use.
// See docs/ros.md, "Live tuning".
#pragma once

#include <dynamic_reconfigure/Config.h>
#include <dynamic_reconfigure/server.h>
#include <ros/console.h>

#include <boost/thread/recursive_mutex.hpp>
#include <functional>
#include <iomanip>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>

namespace umvs_ros {

inline std::string parameter_text(double v) {
  std::ostringstream s;
  s << std::setprecision(12) << v;
  return s.str();
}
inline std::string parameter_text(int v) { return std::to_string(v); }
inline std::string parameter_text(bool v) { return v ? "true" : "false"; }
inline std::string parameter_text(const std::string& v) { return "'" + v + "'"; }

// "name old -> new" for each parameter that differs (all types of a dynamic_reconfigure Config).
inline std::string describe_changes(const dynamic_reconfigure::Config& from, const dynamic_reconfigure::Config& to) {
  auto values = [](const dynamic_reconfigure::Config& c) {
    std::map<std::string, std::string> v;
    for (const auto& p : c.doubles) v[p.name] = parameter_text(static_cast<double>(p.value));
    for (const auto& p : c.ints) v[p.name] = parameter_text(static_cast<int>(p.value));
    for (const auto& p : c.bools) v[p.name] = parameter_text(static_cast<bool>(p.value));
    for (const auto& p : c.strs) v[p.name] = parameter_text(p.value);
    return v;
  };
  const auto old_values = values(from);
  std::string out;
  for (const auto& [name, value] : values(to)) {
    const auto it = old_values.find(name);
    if (it != old_values.end() && it->second == value) continue;
    out += (out.empty() ? "" : ", ") + name + " " + (it == old_values.end() ? "?" : it->second) + " -> " + value;
  }
  return out;
}

// `DynConfig` is a generated <Name>Config. `apply` validates a request with the node's start-up
// validation and puts it into effect, or throws std::invalid_argument naming the parameter (and
// then must have changed nothing).
template <class DynConfig>
class ReconfigureServer {
 public:
  using Apply = std::function<void(const DynConfig&)>;

  // `current`: the values the node runs with (from its rosparams); the server starts with them
  // as they are (dynamic_reconfigure would clamp them to the cfg ranges and fill missing ones
  // with the cfg defaults).
  ReconfigureServer(const ros::NodeHandle& pnh, const std::string& node_name, const DynConfig& current, Apply apply)
      : name_(node_name), current_(current), apply_(std::move(apply)), server_(mutex_, pnh) {
    server_.updateConfig(current_);
    server_.setCallback([this](DynConfig& requested, uint32_t) { onRequest(requested); });
  }

 private:
  // Called by the server with its mutex held. After this returns the server publishes and answers
  // with `requested`, so a refusal writes the old values into it (server_.updateConfig here would
  // be overwritten by the server right after).
  void onRequest(DynConfig& requested) {
    dynamic_reconfigure::Config before, after;
    current_.__toMessage__(before);
    requested.__toMessage__(after);
    const std::string changes = describe_changes(before, after);
    if (changes.empty()) return;  // the start-up call, or nothing changed
    try {
      apply_(requested);
      current_ = requested;
      ROS_INFO("%s: reconfigured: %s", name_.c_str(), changes.c_str());
    } catch (const std::exception& e) {
      ROS_WARN("%s: reconfigure refused (%s): %s; keeping the old values", name_.c_str(), changes.c_str(), e.what());
      requested = current_;
    }
  }

  std::string name_;
  DynConfig current_;
  Apply apply_;
  boost::recursive_mutex mutex_;  // ours, so that updateConfig() cannot deadlock with a request
  dynamic_reconfigure::Server<DynConfig> server_;
};

}  // namespace umvs_ros
