// The live-tunable subset of each node's settings, as the dynamic_reconfigure configs generated
// from cfg/*.cfg, both ways. to_reconfigure(settings) gives what a node's reconfigure server
// starts with; with_reconfigure(settings, request) what the node validates and runs with after a
// request (fields outside the cfg are kept). The cfg defaults equal to_reconfigure of the structs'
// defaults (tested in test/ros/test_dynamic_reconfigure.cpp).
#pragma once

#include "unsup_mvs/FusionConfig.h"
#include "unsup_mvs/InferenceConfig.h"
#include "unsup_mvs/KeyframeSelectorConfig.h"
#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/ros/params.h"

namespace umvs_ros {

unsup_mvs::FusionConfig to_reconfigure(const FusionNodeConfig& node);
FusionNodeConfig with_reconfigure(FusionNodeConfig node, const unsup_mvs::FusionConfig& request);

unsup_mvs::InferenceConfig to_reconfigure(const InferenceNodeConfig& node);
InferenceNodeConfig with_reconfigure(InferenceNodeConfig node, const unsup_mvs::InferenceConfig& request);

unsup_mvs::KeyframeSelectorConfig to_reconfigure(const umvs::KeyframeStreamConfig& stream);
umvs::KeyframeStreamConfig with_reconfigure(umvs::KeyframeStreamConfig stream,
                                            const unsup_mvs::KeyframeSelectorConfig& request);

}  // namespace umvs_ros
