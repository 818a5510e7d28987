// What `umvs fuse` reads: the depth maps of a scene with their confidences, cameras (rescaled to
// the depth maps), colours and neighbours. Either a folder written by `umvs infer` (depth_est/,
// confidence/, cams/, images/, pair.txt; DATA only for what it lacks) or a folder of
// XXXXXXXX.pfm depth maps such as DATA/depth_gt, with cams/, images/ and pair.txt from DATA.
#pragma once

#include <array>
#include <iosfwd>
#include <string>
#include <vector>

#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/point_cloud.h"
#include "unsup_mvs/io/occupancy_map.h"

namespace umvs {

struct FusionInput {
  std::vector<FusionView> views;
  std::vector<std::vector<int>> sources;  // per view: indices into `views` from pair.txt, best first
  std::string depth_dir;                  // where the depth maps came from
};

// The views `ids` (empty = every view of pair.txt with a depth map). Throws naming the missing
// folder or file.
FusionInput load_fusion_input(const std::string& depth, const std::string& data, const std::vector<int>& ids = {});

// Fuses the input: DepthFusion over pair.txt's neighbours, or with `stream` a StreamingFusion of
// `window` recent estimates fed in pair.txt order. One line per view to `log`.
PointCloud fuse_input(const FusionInput& input, const FusionConfig& config, bool stream, int window,
                      const torch::Device& device, std::ostream& log);

// Casts every confident pixel of the input into `map` as a ray from its camera (no consistency
// test); views whose camera is outside the map's extent are left out, counted in the result.
struct InputIntegration {
  int64_t rays = 0;
  int64_t cameras_outside = 0;
};
InputIntegration integrate_input(OccupancyMap& map, const FusionInput& input);

// An axis-aligned box xmin,ymin,zmin,xmax,ymax,zmax; `option` names it in the error.
using BoundingBox = std::array<double, 6>;
BoundingBox parse_box(const std::string& text, const std::string& option);
size_t points_inside(const PointCloud& cloud, const BoundingBox& box);

}  // namespace umvs
