// PLY point clouds.
#pragma once

#include <string>

#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

// Binary little-endian PLY: x y z float, red green blue uchar (when the cloud has colours),
// confidence float and views uchar (when present). Written atomically: an existing file is only
// replaced by a complete new one.
void write_ply(const std::string& path, const PointCloud& cloud);

// Reads ASCII or binary little-endian PLY vertices: x y z (float or double), red green blue
// (uchar) and our confidence/views when present; other properties are skipped. Faces are ignored.
// Throws std::runtime_error naming the file and the problem.
PointCloud read_ply(const std::string& path);

}  // namespace umvs
