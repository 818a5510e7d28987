#include "unsup_mvs/io/import.h"

#include <torch/torch.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/view_selection.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/input_limits.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "import_common.h"

namespace umvs {

namespace fs = std::filesystem;
using namespace import_detail;

bool parse_middlebury_bbox(const std::string& text, Eigen::Vector3d* min, Eigen::Vector3d* max) {
  static const std::regex triple(R"(\(\s*([-+0-9.eE]+)\s+([-+0-9.eE]+)\s+([-+0-9.eE]+)\s*\))");
  std::vector<Eigen::Vector3d> found;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), triple); it != std::sregex_iterator() && found.size() < 2; ++it) {
    found.emplace_back(std::stod((*it)[1]), std::stod((*it)[2]), std::stod((*it)[3]));
  }
  if (found.size() < 2) return false;
  *min = found[0].cwiseMin(found[1]);
  *max = found[0].cwiseMax(found[1]);
  return true;
}

ImportSummary import_middlebury(const MiddleburyImportConfig& config) {
  check_import_folders(config.data_dir, config.out_dir, config.depth_num, config.num_sources);
  std::string par = config.par_file;
  if (par.empty()) {
    for (const auto& e : fs::directory_iterator(config.data_dir)) {
      const std::string name = e.path().filename().string();
      if (name.size() > 8 && name.substr(name.size() - 8) == "_par.txt") {
        if (!par.empty()) throw std::runtime_error("several *_par.txt in " + config.data_dir + ": choose one (--par)");
        par = e.path().string();
      }
    }
    if (par.empty()) throw std::runtime_error("no *_par.txt calibration file in " + config.data_dir);
  }
  Eigen::Vector3d bmin = config.bbox_min, bmax = config.bbox_max;
  if (!config.bbox_given) {
    const std::string readme = config.data_dir + "/README.txt";
    if (!fs::exists(readme) || !parse_middlebury_bbox(read_file_bytes(readme), &bmin, &bmax)) {
      throw std::runtime_error("no bounding box: " + readme + " has none; give it (--bbox xmin,ymin,zmin,xmax,ymax,zmax)");
    }
  }
  if (!(bmax.array() > bmin.array()).all()) throw std::runtime_error("empty bounding box");

  checked_file_size(par, kMaxTextFileBytes, "calibration file");  // a FIFO would block the read
  std::ifstream in(par);
  if (!in) throw std::runtime_error("cannot open " + par);
  int count = 0;
  if (!(in >> count) || count <= 0) throw std::runtime_error(par + ": first line must be the number of images");
  ImportSummary summary;
  summary.depth_min = std::numeric_limits<double>::infinity();
  std::vector<ImportedView> views;
  std::vector<std::string> images;
  for (int line = 0; line < count; ++line) {
    std::string name;
    double v[21];
    if (!(in >> name)) throw std::runtime_error(par + ": expected " + std::to_string(count) + " camera lines, found " + std::to_string(line));
    for (double& x : v) {
      if (!(in >> x) || !std::isfinite(x)) throw std::runtime_error(par + ": malformed or non-finite number in the line of " + name);
    }
    const std::string image = config.data_dir + "/" + name;
    if (!fs::exists(image)) {
      ++summary.skipped;
      continue;
    }
    ImportedView iv;
    iv.id = id_from_name(name);
    if (iv.id < 0) iv.id = line;
    Camera& cam = iv.cam.camera;
    cam.K << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) cam.T_cam_world(r, c) = v[9 + 3 * r + c];
      cam.T_cam_world(r, 3) = v[18 + r];
    }
    const auto pixels = read_image_rgb8(image);  // the size is needed to rank neighbours
    cam.width = static_cast<int>(pixels.size(1));
    cam.height = static_cast<int>(pixels.size(0));
    try {
      cam.validate(par + " (" + name + ")");
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(e.what());
    }
    double zmin = std::numeric_limits<double>::infinity(), zmax = -zmin;
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3d corner((k & 1) ? bmax.x() : bmin.x(), (k & 2) ? bmax.y() : bmin.y(), (k & 4) ? bmax.z() : bmin.z());
      const double z = (cam.R() * corner + cam.t()).z();
      zmin = std::min(zmin, z);
      zmax = std::max(zmax, z);
    }
    if (zmin <= 0) throw std::runtime_error(par + " (" + name + "): the bounding box is not entirely in front of the camera");
    // (set_depth_range keeps the near end positive)
    set_depth_range(iv.cam, zmin, zmax, config.depth_margin, config.depth_num, par + " (" + name + ")");
    summary.depth_min = std::min(summary.depth_min, iv.cam.depth_min);
    summary.depth_max = std::max(summary.depth_max, iv.cam.depth_max);
    for (const auto& other : views) {
      if (other.id == iv.id) throw std::runtime_error(par + ": two images map to view id " + std::to_string(iv.id));
    }
    views.push_back(iv);
    images.push_back(image);
  }
  if (views.empty()) throw std::runtime_error(par + ": none of the listed images is in " + config.data_dir);

  for (const char* sub : {"images", "cams"}) make_directories(config.out_dir + "/" + sub);
  // Points on a grid in the box stand in for the surface when ranking neighbours.
  std::vector<Eigen::Vector3d> grid;
  const int n = 8;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k)
        grid.push_back(bmin + (bmax - bmin).cwiseProduct(Eigen::Vector3d(i + 0.5, j + 0.5, k + 0.5) / n));
  for (size_t i = 0; i < views.size(); ++i) {
    const std::string stem = view_file_stem(views[i].id);
    const auto ext = fs::path(images[i]).extension().string();
    copy_atomically(images[i], config.out_dir + "/images/" + stem + ext);
    write_cam_file(config.out_dir + "/cams/" + stem + "_cam.txt", views[i].cam);
  }
  write_pairs(config.out_dir + "/pair.txt", views, std::vector<std::vector<Eigen::Vector3d>>(views.size(), grid), config.num_sources);
  summary.views = static_cast<int>(views.size());
  return summary;
}

}  // namespace umvs
