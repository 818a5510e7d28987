// FusionConfig's numeric settings, declared once (core/settings.h): `umvs fuse` binds its options
// to them, the fusion node reads its parameters by them, its dynamic_reconfigure cfg
// (cfg/Fusion.cfg) must equal them, and docs/fusion.md's table is made from them. The source rule
// (a name, not a number) is the one setting outside: `source_rule` / `--source-rule`.
#pragma once

#include <vector>

#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/settings.h"

namespace umvs {

const std::vector<Setting<FusionConfig>>& fusion_settings();

}  // namespace umvs
