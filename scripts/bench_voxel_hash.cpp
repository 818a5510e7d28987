// One-off measurement behind docs/fusion.md ("voxel hash or pcl::VoxelGrid"): times, on the same
// PCD cloud, the de-duplication the streaming fusion does (src/core/fusion.cpp voxel_key +
// voxel_filter: an unordered_set of voxel keys, first point wins; the same code, copied here since
// core keeps it private) against pcl::VoxelGrid<PointXYZRGB> (centroids), best of --runs.
// Build and run (not part of the CMake build):
//   g++ -O3 -std=c++17 scripts/bench_voxel_hash.cpp -o /tmp/bench_voxel_hash -I/usr/include/pcl-1.13 \
//     -I/usr/include/eigen3 -lpcl_common -lpcl_io -lpcl_filters
//   /tmp/bench_voxel_hash CLOUD.pcd LEAF [RUNS]
#include <pcl/filters/voxel_grid.h>
#include <pcl/io/pcd_io.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <unordered_set>

int64_t voxel_key(const Eigen::Vector3f& p, double voxel) {
  const auto cell = [&](float v) { return static_cast<int64_t>(std::floor(v / voxel)) & 0x1FFFFF; };
  return (cell(p.x()) << 42) | (cell(p.y()) << 21) | cell(p.z());
}

int main(int argc, char** argv) {
  if (argc < 3) return 2;
  const double leaf = std::atof(argv[2]);
  const int runs = argc > 3 ? std::atoi(argv[3]) : 10;
  pcl::PointCloud<pcl::PointXYZRGB>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZRGB>);
  if (pcl::io::loadPCDFile(argv[1], *cloud) != 0) return 1;
  using clock = std::chrono::steady_clock;
  double best_hash = 1e9, best_grid = 1e9;
  size_t n_hash = 0, n_grid = 0;
  for (int r = 0; r < runs; ++r) {
    auto t0 = clock::now();
    std::unordered_set<int64_t> voxels;
    pcl::PointCloud<pcl::PointXYZRGB> kept;  // first point per voxel, attributes copied as core does
    for (const auto& p : *cloud) {
      if (voxels.insert(voxel_key(p.getVector3fMap(), leaf)).second) kept.push_back(p);
    }
    best_hash = std::min(best_hash, std::chrono::duration<double>(clock::now() - t0).count());
    n_hash = kept.size();
    t0 = clock::now();
    pcl::VoxelGrid<pcl::PointXYZRGB> grid;
    grid.setInputCloud(cloud);
    grid.setLeafSize(leaf, leaf, leaf);
    pcl::PointCloud<pcl::PointXYZRGB> out;
    grid.filter(out);
    best_grid = std::min(best_grid, std::chrono::duration<double>(clock::now() - t0).count());
    n_grid = out.size();
  }
  std::printf("%zu points, leaf %g: hash %zu points in %.4f s, pcl::VoxelGrid %zu points in %.4f s (best of %d)\n",
              cloud->size(), leaf, n_hash, best_hash, n_grid, best_grid, runs);
  return 0;
}
