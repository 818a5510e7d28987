#include "unsup_mvs/core/point_cloud.h"

#include <stdexcept>

namespace umvs {

namespace {
// An attribute survives when both clouds have it; an empty cloud takes the other's attributes.
template <typename T>
void append_attribute(std::vector<T>& mine, const std::vector<T>& theirs, size_t n, size_t m) {
  if (m == 0) return;
  if (n == 0) {
    mine = theirs;
  } else if (mine.size() == n && theirs.size() == m) {
    mine.insert(mine.end(), theirs.begin(), theirs.end());
  } else {
    mine.clear();
  }
}
}  // namespace

void PointCloud::append(const PointCloud& other) {
  const size_t n = size(), m = other.size();
  append_attribute(colors, other.colors, n, m);
  append_attribute(confidence, other.confidence, n, m);
  append_attribute(num_views, other.num_views, n, m);
  points.insert(points.end(), other.points.begin(), other.points.end());
}

size_t PointCloud::erase(const std::vector<uint8_t>& remove) {
  const size_t n = size();
  if (remove.size() != n) throw std::invalid_argument("PointCloud::erase: one entry per point expected");
  auto compact = [&](auto& attribute) {
    if (attribute.size() != n) return;
    size_t kept = 0;
    for (size_t i = 0; i < n; ++i) {
      if (!remove[i]) attribute[kept++] = attribute[i];
    }
    attribute.resize(kept);
  };
  compact(colors);
  compact(confidence);
  compact(num_views);
  compact(points);
  return n - points.size();
}

void PointCloud::clear() {
  points.clear();
  colors.clear();
  confidence.clear();
  num_views.clear();
}

}  // namespace umvs
