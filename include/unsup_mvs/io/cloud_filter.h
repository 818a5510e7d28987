// Optional clean-up of a fused cloud with PCL filters, in this order: statistical outlier removal,
// radius outlier removal, voxel grid. Every stage is off by default. Used by `umvs fuse` and by
// the fusion node on the map it publishes and saves (docs/fusion.md has measurements).
#pragma once

#include <string>
#include <vector>

#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

struct CloudFilterConfig {
  // pcl::StatisticalOutlierRemoval: drops points whose mean distance to their `sor_mean_k`
  // nearest neighbours exceeds the cloud's mean of that distance + sor_std_mul standard deviations.
  int sor_mean_k = 0;  // 0 = off
  double sor_std_mul = 2.0;
  // pcl::RadiusOutlierRemoval: drops points with fewer than `radius_min_neighbors` others within
  // `radius` (scene units).
  double radius = 0.0;  // 0 = off
  int radius_min_neighbors = 2;
  // pcl::VoxelGrid: one point per cube of edge `voxel_leaf` (scene units), the centroid of its
  // points with their mean colour, confidence and view count.
  double voxel_leaf = 0.0;  // 0 = off

  bool any() const { return sor_mean_k > 0 || radius > 0 || voxel_leaf > 0; }
  void validate() const;  // throws std::invalid_argument naming the bad field
};

struct CloudFilterStep {
  std::string name;  // "statistical", "radius", "voxel"
  size_t points_before = 0, points_after = 0;
  double seconds = 0;
};

// The cloud after the enabled stages; `steps`, when given, receives one entry per stage run.
// Outlier removal keeps the surviving points' attributes exactly.
PointCloud filter_cloud(const PointCloud& cloud, const CloudFilterConfig& config,
                        std::vector<CloudFilterStep>* steps = nullptr);

}  // namespace umvs
