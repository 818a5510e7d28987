// A coloured point cloud with per-point fusion attributes. Eigen only.
#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <vector>

namespace umvs {

struct PointCloud {
  std::vector<Eigen::Vector3f> points;         // world coordinates
  std::vector<std::array<uint8_t, 3>> colors;  // RGB; empty or one per point
  std::vector<float> confidence;               // empty or one per point
  std::vector<uint8_t> num_views;              // agreeing views; empty or one per point

  size_t size() const { return points.size(); }
  bool empty() const { return points.empty(); }
  bool has_colors() const { return !colors.empty(); }
  // Appends `other`; attributes present in only one of the clouds are dropped.
  void append(const PointCloud& other);
  // Removes the points whose entry in `remove` (one per point) is non-zero, keeping the order of
  // the others. Returns how many were removed.
  size_t erase(const std::vector<uint8_t>& remove);
  void clear();
};

}  // namespace umvs
