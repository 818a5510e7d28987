#include "unsup_mvs/io/cloud_filter.h"

#include <array>
#include <chrono>
#include <cmath>
#include <map>
#include <stdexcept>

#ifdef UMVS_HAVE_PCL
#include <pcl/filters/radius_outlier_removal.h>
#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/filters/voxel_grid.h>
// VoxelGrid for our own point type (averages every field, colours per channel): PCL compiles its
// templates only for its own point types.
#include <pcl/filters/impl/voxel_grid.hpp>
#include <pcl/impl/pcl_base.hpp>

#include "unsup_mvs/io/pcl_cloud.h"
#endif

namespace umvs {

void CloudFilterConfig::validate() const {
  auto bad = [](const std::string& what) { throw std::invalid_argument("cloud filter: " + what); };
  if (sor_mean_k < 0) bad("sor_mean_k must be >= 0 (0 = off), got " + std::to_string(sor_mean_k));
  if (sor_mean_k > 0 && !(sor_std_mul > 0)) bad("sor_std_mul must be > 0, got " + std::to_string(sor_std_mul));
  if (!(radius >= 0)) bad("radius must be >= 0 (0 = off), got " + std::to_string(radius));
  if (radius > 0 && radius_min_neighbors < 1) {
    bad("radius_min_neighbors must be >= 1, got " + std::to_string(radius_min_neighbors));
  }
  if (!(voxel_leaf >= 0)) bad("voxel_leaf must be >= 0 (0 = off), got " + std::to_string(voxel_leaf));
#ifndef UMVS_HAVE_PCL
  if (any()) bad("this build has no PCL: outlier removal and the voxel grid are unavailable");
#endif
}

#ifdef UMVS_HAVE_PCL
namespace {

pcl::PointCloud<pcl::PointXYZ>::Ptr xyz_of(const PointCloud& cloud) {
  auto out = pcl::make_shared<pcl::PointCloud<pcl::PointXYZ>>();
  out->resize(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) (*out)[i].getVector3fMap() = cloud.points[i];
  return out;
}

PointCloud select(const PointCloud& cloud, const pcl::Indices& kept) {
  PointCloud out;
  for (const auto i : kept) {
    out.points.push_back(cloud.points[i]);
    if (cloud.colors.size() == cloud.size()) out.colors.push_back(cloud.colors[i]);
    if (cloud.confidence.size() == cloud.size()) out.confidence.push_back(cloud.confidence[i]);
    if (cloud.num_views.size() == cloud.size()) out.num_views.push_back(cloud.num_views[i]);
  }
  return out;
}

// pcl::VoxelGrid averages only the fields PCL knows (xyz, rgb, normals, ...) and leaves ours at
// zero: average confidence and views of the input points of each output voxel here. A voxel is
// found by its cell index, computed as VoxelGrid does (floor(coordinate * 1 / leaf)); a centroid
// lies in its points' cell.
void average_fields_per_voxel(const pcl::PointCloud<FusedPoint>& input, float leaf, pcl::PointCloud<FusedPoint>& out) {
  const float inverse = 1.0f / leaf;
  auto cell = [&](const FusedPoint& p) {
    return std::array<int64_t, 3>{static_cast<int64_t>(std::floor(p.x * inverse)),
                                  static_cast<int64_t>(std::floor(p.y * inverse)),
                                  static_cast<int64_t>(std::floor(p.z * inverse))};
  };
  std::map<std::array<int64_t, 3>, size_t> voxel_of_cell;
  for (size_t k = 0; k < out.size(); ++k) voxel_of_cell.emplace(cell(out[k]), k);
  std::vector<double> confidence(out.size(), 0.0), views(out.size(), 0.0);
  std::vector<int> count(out.size(), 0);
  for (const FusedPoint& p : input) {
    const auto it = voxel_of_cell.find(cell(p));
    if (it == voxel_of_cell.end()) continue;  // a point on a cell border rounded the other way
    confidence[it->second] += p.confidence;
    views[it->second] += p.views;
    ++count[it->second];
  }
  for (size_t k = 0; k < out.size(); ++k) {
    if (count[k] == 0) continue;
    out[k].confidence = static_cast<float>(confidence[k] / count[k]);
    out[k].views = static_cast<std::uint8_t>(std::lround(views[k] / count[k]));
  }
}

}  // namespace

PointCloud filter_cloud(const PointCloud& cloud, const CloudFilterConfig& config, std::vector<CloudFilterStep>* steps) {
  config.validate();
  PointCloud current = cloud;
  auto run = [&](const char* name, auto&& stage) {
    if (current.empty()) return;
    const auto t0 = std::chrono::steady_clock::now();
    const size_t before = current.size();
    current = stage(current);
    if (steps) {
      steps->push_back({name, before, current.size(),
                        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()});
    }
  };
  // Outlier removal decides on positions only, then keeps the chosen points with all attributes.
  if (config.sor_mean_k > 0) {
    run("statistical", [&](const PointCloud& c) {
      pcl::StatisticalOutlierRemoval<pcl::PointXYZ> sor;
      sor.setInputCloud(xyz_of(c));
      sor.setMeanK(config.sor_mean_k);
      sor.setStddevMulThresh(config.sor_std_mul);
      pcl::Indices kept;
      sor.filter(kept);
      return select(c, kept);
    });
  }
  if (config.radius > 0) {
    run("radius", [&](const PointCloud& c) {
      pcl::RadiusOutlierRemoval<pcl::PointXYZ> ror;
      ror.setInputCloud(xyz_of(c));
      ror.setRadiusSearch(config.radius);
      ror.setMinNeighborsInRadius(config.radius_min_neighbors);
      pcl::Indices kept;
      ror.filter(kept);
      return select(c, kept);
    });
  }
  if (config.voxel_leaf > 0) {
    run("voxel", [&](const PointCloud& c) {
      const auto input = pcl::make_shared<pcl::PointCloud<FusedPoint>>(to_pcl(c));
      pcl::VoxelGrid<FusedPoint> grid;
      grid.setInputCloud(input);
      const float leaf = static_cast<float>(config.voxel_leaf);
      grid.setLeafSize(leaf, leaf, leaf);
      pcl::PointCloud<FusedPoint> out;
      grid.filter(out);  // centroids and mean colours
      average_fields_per_voxel(*input, leaf, out);
      return from_pcl(out, c.colors.size() == c.size(), c.confidence.size() == c.size(), c.num_views.size() == c.size());
    });
  }
  return current;
}

#else

PointCloud filter_cloud(const PointCloud& cloud, const CloudFilterConfig& config, std::vector<CloudFilterStep>*) {
  config.validate();  // refuses any enabled stage
  return cloud;
}

#endif  // UMVS_HAVE_PCL

}  // namespace umvs
