// Point-cloud files chosen by extension: .ply (our binary PLY, io/ply.h) and .pcd (PCL's binary
// compressed PCD, through pcl::io). Both keep x y z, colour, confidence and agreeing views.
#pragma once

#include <string>

#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

enum class CloudFileFormat { kPly, kPcd };

// The format `path`'s extension names (case-insensitive). Throws std::invalid_argument naming the
// path and the extension when it is neither .ply nor .pcd.
CloudFileFormat cloud_file_format(const std::string& path);

// Writes atomically (a temporary file beside `path`, then renamed; see io/atomic_file.h): on any
// failure an existing file at `path` is left untouched. Throws std::invalid_argument for a wrong
// extension (before anything is written) and std::runtime_error naming the path otherwise.
void write_cloud(const std::string& path, const PointCloud& cloud);

// Reads a .ply (read_ply: ASCII or binary, e.g. MVSNet's reference clouds) or a .pcd (any PCD
// with x y z; rgb, confidence and views when present). Throws naming the file and the problem.
PointCloud read_cloud(const std::string& path);

}  // namespace umvs
