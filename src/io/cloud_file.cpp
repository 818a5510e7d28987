#include "unsup_mvs/io/cloud_file.h"

#include <algorithm>
#include <cctype>
#include <cstring>
#include <filesystem>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/input_limits.h"
#include "unsup_mvs/io/ply.h"

#ifdef UMVS_HAVE_PCL
#include <pcl/PCLPointCloud2.h>
#include <pcl/common/io.h>
#include <pcl/conversions.h>
#include <pcl/io/pcd_io.h>

#include "unsup_mvs/io/pcl_cloud.h"
#endif

namespace umvs {

CloudFileFormat cloud_file_format(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  if (ext == ".ply") return CloudFileFormat::kPly;
  if (ext == ".pcd") return CloudFileFormat::kPcd;
  throw std::invalid_argument("'" + path + "': unknown point-cloud extension '" + ext +
                              "' (expected .ply or .pcd)");
}

#ifdef UMVS_HAVE_PCL
namespace {

void write_pcd(const std::string& path, const PointCloud& cloud) {
  pcl::PCLPointCloud2 blob;
  pcl::toPCLPointCloud2(to_pcl(cloud), blob);
  write_file_atomically(path, [&](std::ostream& out) {
    // PCL's stream writer reports failure by its return value; throwing makes
    // write_file_atomically drop the temporary file and keep the old one.
    if (pcl::PCDWriter().writeBinaryCompressed(out, blob, Eigen::Vector4f::Zero(), Eigen::Quaternionf::Identity()) != 0) {
      throw std::runtime_error("PCL could not encode the cloud as PCD");
    }
  });
}

// One field of a PCD point, if present with the expected type and size.
const pcl::PCLPointField* find_field(const pcl::PCLPointCloud2& blob, const std::string& name, uint8_t type,
                                     const std::string& path) {
  const int i = pcl::getFieldIndex(blob, name);
  if (i < 0) return nullptr;
  const pcl::PCLPointField& f = blob.fields[i];
  const bool four_bytes = type == pcl::PCLPointField::FLOAT32 &&
                          (f.datatype == pcl::PCLPointField::UINT32 || f.datatype == pcl::PCLPointField::INT32) && name == "rgb";
  if ((f.datatype != type && !four_bytes) || f.count != 1 ||
      f.offset + pcl::getFieldSize(f.datatype) > blob.point_step) {
    throw std::runtime_error("'" + path + "': PCD field '" + name + "' has an unexpected type, count or offset");
  }
  return &f;
}

PointCloud read_pcd(const std::string& path) {
  checked_file_size(path, kMaxPlyBytes, "PCD file");
  pcl::PCLPointCloud2 blob;
  Eigen::Vector4f origin;
  Eigen::Quaternionf orientation;
  int version = 0, data_type = 0;
  unsigned int data_start = 0;
  pcl::PCDReader reader;
  // PCL 1.13's read() crashes on a file whose header has no fields or points: check the header first.
  if (reader.readHeader(path, blob, origin, orientation, version, data_type, data_start) < 0 || blob.fields.empty()) {
    throw std::runtime_error("'" + path + "': not a PCD file (no readable header with FIELDS)");
  }
  if (uint64_t{blob.width} * blob.height == 0) return PointCloud();
  if (reader.read(path, blob, origin, orientation, version) < 0) {
    throw std::runtime_error("'" + path + "': not a readable PCD file");
  }
  const uint64_t n = uint64_t{blob.width} * blob.height;
  if (blob.data.size() < n * blob.point_step) throw std::runtime_error("'" + path + "': PCD data shorter than its header says");
  const auto* fx = find_field(blob, "x", pcl::PCLPointField::FLOAT32, path);
  const auto* fy = find_field(blob, "y", pcl::PCLPointField::FLOAT32, path);
  const auto* fz = find_field(blob, "z", pcl::PCLPointField::FLOAT32, path);
  if (!fx || !fy || !fz) throw std::runtime_error("'" + path + "': PCD without float x y z fields");
  const auto* frgb = find_field(blob, "rgb", pcl::PCLPointField::FLOAT32, path);
  const auto* fconf = find_field(blob, "confidence", pcl::PCLPointField::FLOAT32, path);
  const auto* fviews = find_field(blob, "views", pcl::PCLPointField::UINT8, path);
  PointCloud cloud;
  cloud.points.reserve(n);
  auto get_float = [](const uint8_t* point, const pcl::PCLPointField* f) {
    float v;
    std::memcpy(&v, point + f->offset, 4);
    return v;
  };
  for (uint64_t i = 0; i < n; ++i) {
    const uint8_t* point = blob.data.data() + i * blob.point_step;
    cloud.points.emplace_back(get_float(point, fx), get_float(point, fy), get_float(point, fz));
    if (frgb) {
      uint32_t rgb;
      std::memcpy(&rgb, point + frgb->offset, 4);
      cloud.colors.push_back({static_cast<uint8_t>(rgb >> 16), static_cast<uint8_t>(rgb >> 8), static_cast<uint8_t>(rgb)});
    }
    if (fconf) cloud.confidence.push_back(get_float(point, fconf));
    if (fviews) cloud.num_views.push_back(point[fviews->offset]);
  }
  return cloud;
}

}  // namespace
#endif  // UMVS_HAVE_PCL

void write_cloud(const std::string& path, const PointCloud& cloud) {
  switch (cloud_file_format(path)) {
    case CloudFileFormat::kPly:
      write_ply(path, cloud);
      return;
    case CloudFileFormat::kPcd:
#ifdef UMVS_HAVE_PCL
      write_pcd(path, cloud);
      return;
#else
      throw std::runtime_error("'" + path + "': this build has no PCL, so it writes only .ply");
#endif
  }
}

PointCloud read_cloud(const std::string& path) {
  switch (cloud_file_format(path)) {
    case CloudFileFormat::kPly:
      return read_ply(path);
    case CloudFileFormat::kPcd:
#ifdef UMVS_HAVE_PCL
      return read_pcd(path);
#else
      throw std::runtime_error("'" + path + "': this build has no PCL, so it reads only .ply");
#endif
  }
  throw std::logic_error("unreachable");
}

}  // namespace umvs
