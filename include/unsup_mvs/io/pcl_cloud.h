// Our fused cloud as a PCL cloud: the point type every PCL user (pcl_ros, PCD files, PCL filters)
// sees, and the one conversion between it and core's PointCloud. PCL stays out of core; include
// this header only where PCL types are needed (io, the fusion nodelet, tests).
#pragma once

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/register_point_struct.h>

#include <cstdint>

#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

// x y z, rgb (PCL's packed float, read by RViz and pcl::PointXYZRGB users), the fusion confidence
// and the number of agreeing views.
struct EIGEN_ALIGN16 FusedPoint {
  PCL_ADD_POINT4D;
  PCL_ADD_RGB;
  float confidence;
  std::uint8_t views;
  PCL_MAKE_ALIGNED_OPERATOR_NEW
};

// Points without colour get this grey; missing confidence / view counts become 0.
constexpr std::uint8_t kDefaultGrey = 200;

pcl::PointCloud<FusedPoint> to_pcl(const PointCloud& cloud);

// Colours, confidences and view counts are taken when `has_*` says the source had them (a PCD file
// without the field), so that a round trip keeps an absent attribute absent.
PointCloud from_pcl(const pcl::PointCloud<FusedPoint>& cloud, bool has_color = true, bool has_confidence = true,
                    bool has_views = true);

}  // namespace umvs

POINT_CLOUD_REGISTER_POINT_STRUCT(umvs::FusedPoint,
                                  (float, x, x)(float, y, y)(float, z, z)(float, rgb, rgb)
                                  (float, confidence, confidence)(std::uint8_t, views, views))
