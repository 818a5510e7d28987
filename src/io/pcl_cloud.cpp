#ifdef UMVS_HAVE_PCL
#include "unsup_mvs/io/pcl_cloud.h"

namespace umvs {

pcl::PointCloud<FusedPoint> to_pcl(const PointCloud& cloud) {
  const size_t n = cloud.size();
  const bool rgb = cloud.colors.size() == n, conf = cloud.confidence.size() == n, views = cloud.num_views.size() == n;
  pcl::PointCloud<FusedPoint> out;
  out.resize(n);  // width n, height 1
  out.is_dense = true;
  for (size_t i = 0; i < n; ++i) {
    FusedPoint& p = out[i];
    p.x = cloud.points[i].x();
    p.y = cloud.points[i].y();
    p.z = cloud.points[i].z();
    const std::array<uint8_t, 3> c = rgb ? cloud.colors[i] : std::array<uint8_t, 3>{kDefaultGrey, kDefaultGrey, kDefaultGrey};
    p.r = c[0];
    p.g = c[1];
    p.b = c[2];
    p.a = 255;
    p.confidence = conf ? cloud.confidence[i] : 0.0f;
    p.views = views ? cloud.num_views[i] : 0;
  }
  return out;
}

PointCloud from_pcl(const pcl::PointCloud<FusedPoint>& cloud, bool has_color, bool has_confidence, bool has_views) {
  PointCloud out;
  out.points.reserve(cloud.size());
  for (const FusedPoint& p : cloud) {
    out.points.emplace_back(p.x, p.y, p.z);
    if (has_color) out.colors.push_back({p.r, p.g, p.b});
    if (has_confidence) out.confidence.push_back(p.confidence);
    if (has_views) out.num_views.push_back(p.views);
  }
  return out;
}

}  // namespace umvs
#endif  // UMVS_HAVE_PCL
