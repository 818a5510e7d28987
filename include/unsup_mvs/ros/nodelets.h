// The package's nodelets (plugin names unsup_mvs/KeyframeSelector, unsup_mvs/Inference,
// unsup_mvs/Fusion; see nodelet_plugins.xml). The factories let the standalone *_node
// executables run them through nodelet::Loader without a pluginlib lookup.
#pragma once

#include <nodelet/nodelet.h>

#include <boost/shared_ptr.hpp>
#include <string>

namespace umvs_ros {

boost::shared_ptr<nodelet::Nodelet> make_keyframe_selector_nodelet();
boost::shared_ptr<nodelet::Nodelet> make_inference_nodelet();
boost::shared_ptr<nodelet::Nodelet> make_fusion_nodelet();

// Runs one nodelet as this process's node (private parameters and remappings of the node apply).
int run_standalone(int argc, char** argv, const std::string& default_name,
                   boost::shared_ptr<nodelet::Nodelet> (*factory)());

}  // namespace umvs_ros
