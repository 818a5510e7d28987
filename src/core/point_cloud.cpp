#include "unsup_mvs/core/point_cloud.h"

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

void PointCloud::clear() {
  points.clear();
  colors.clear();
  confidence.clear();
  num_views.clear();
}

}  // namespace umvs
