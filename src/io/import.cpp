#include "unsup_mvs/io/import.h"

#include <torch/torch.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/view_selection.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/input_limits.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

// The last run of digits in a file name's stem ("templeR0013" -> 13); -1 when there is none.
int id_from_name(const std::string& name) {
  const std::string stem = fs::path(name).stem().string();
  int end = static_cast<int>(stem.size());
  while (end > 0 && !std::isdigit(static_cast<unsigned char>(stem[end - 1]))) --end;
  int begin = end;
  while (begin > 0 && std::isdigit(static_cast<unsigned char>(stem[begin - 1]))) --begin;
  if (begin == end) return -1;
  return std::stoi(stem.substr(begin, end - begin));
}

void copy_atomically(const std::string& from, const std::string& to) {
  const std::string bytes = read_file_bytes(from);
  write_file_atomically(to, [&](std::ostream& out) { out.write(bytes.data(), static_cast<std::streamsize>(bytes.size())); });
}

struct ImportedView {
  int id = 0;
  MvsCam cam;
};

// pair.txt: every view against all others, ranked by the view-selection score on `points`.
void write_pairs(const std::string& path, const std::vector<ImportedView>& views,
                 const std::vector<std::vector<Eigen::Vector3d>>& points_per_view, int num_sources) {
  std::vector<Camera> cams;
  for (const auto& v : views) cams.push_back(v.cam.camera);
  std::vector<ViewPair> pairs;
  for (size_t i = 0; i < views.size(); ++i) {
    std::vector<Camera> others;
    std::vector<int> ids;
    for (size_t j = 0; j < views.size(); ++j) {
      if (j == i) continue;
      others.push_back(cams[j]);
      ids.push_back(views[j].id);
    }
    ViewPair p;
    p.ref = views[i].id;
    for (const auto& s : rank_source_views(points_per_view[i], cams[i], others)) {
      if (static_cast<int>(p.sources.size()) >= num_sources) break;
      p.sources.push_back(ids[s.index]);
      p.scores.push_back(s.score);
    }
    pairs.push_back(p);
  }
  write_pair_file(path, pairs);
}

void set_depth_range(MvsCam& cam, double zmin, double zmax, double margin, int depth_num, const std::string& what) {
  if (!(zmin > 0.0) || !std::isfinite(zmin) || !std::isfinite(zmax) || zmax < zmin) {
    throw std::runtime_error(what + ": impossible depth range [" + std::to_string(zmin) + ", " + std::to_string(zmax) + "]");
  }
  // A flat scene (a wall) still needs a range to sweep: at least 5% of the depth.
  const double extra = margin * std::max(zmax - zmin, 0.05 * zmax);
  cam.depth_min = std::max(zmin - extra, 1e-3 * zmax);
  cam.depth_max = zmax + extra;
  cam.depth_num = depth_num;
  cam.depth_interval = (cam.depth_max - cam.depth_min) / (depth_num - 1);
}

// The depth image of a colour frame: the same stem in depth/, whatever the format (RGB-D
// sequences pair colour JPEGs or PNGs with 16-bit PNG or PGM depth).
std::string depth_image_for(const std::string& depth_dir, const std::string& color_path) {
  const std::string stem = fs::path(color_path).stem().string();
  for (const char* ext : {".png", ".pgm", ".tif", ".tiff"}) {
    const fs::path candidate = fs::path(depth_dir) / (stem + ext);
    if (fs::is_regular_file(candidate)) return candidate.string();
  }
  throw std::runtime_error("no depth image " + depth_dir + "/" + stem + ".{png,pgm,tif,tiff} for " + color_path);
}
}  // namespace

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
  if (!fs::is_directory(config.data_dir)) throw std::runtime_error("data folder '" + config.data_dir + "' does not exist");
  if (fs::exists(config.out_dir) && fs::equivalent(config.data_dir, config.out_dir)) {
    throw std::runtime_error("the output folder must differ from the data folder");
  }
  if (config.depth_num < 2 || config.num_sources < 1) throw std::runtime_error("depth_num must be >= 2 and num_sources >= 1");
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

ImportSummary import_rgbd(const RgbdImportConfig& config) {
  if (!fs::is_directory(config.data_dir)) throw std::runtime_error("data folder '" + config.data_dir + "' does not exist");
  if (fs::exists(config.out_dir) && fs::equivalent(config.data_dir, config.out_dir)) {
    throw std::runtime_error("the output folder must differ from the data folder");
  }
  if (config.depth_num < 2 || config.num_sources < 1) throw std::runtime_error("depth_num must be >= 2 and num_sources >= 1");
  if (!(config.depth_scale > 0)) throw std::runtime_error("depth scale must be > 0");
  for (const char* sub : {"color", "depth"}) {
    if (!fs::is_directory(fs::path(config.data_dir) / sub)) throw std::runtime_error(config.data_dir + " has no " + sub + "/ folder");
  }
  const std::string pose_path = config.data_dir + "/pose.txt";
  checked_file_size(pose_path, kMaxTextFileBytes, "pose file");
  std::ifstream pose_in(pose_path);
  if (!pose_in) throw std::runtime_error("cannot open " + pose_path);
  std::vector<Eigen::Matrix4d> poses;  // camera-to-world, line k = frame k+1
  for (std::string line; std::getline(pose_in, line);) {
    std::istringstream ls(line);
    double t[3], q[4];
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    if (!(ls >> t[0] >> t[1] >> t[2] >> q[0] >> q[1] >> q[2] >> q[3])) {
      throw std::runtime_error(pose_path + " line " + std::to_string(poses.size() + 1) + ": expected 'tx ty tz qx qy qz qw'");
    }
    const Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
    if (!std::isfinite(quat.norm()) || std::abs(quat.norm() - 1.0) > 1e-3 || !std::isfinite(t[0] + t[1] + t[2])) {
      throw std::runtime_error(pose_path + " line " + std::to_string(poses.size() + 1) + ": not a unit quaternion or non-finite pose");
    }
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    T.topLeftCorner<3, 3>() = quat.normalized().toRotationMatrix();
    T.topRightCorner<3, 1>() = Eigen::Vector3d(t[0], t[1], t[2]);
    poses.push_back(T);
  }
  std::vector<std::pair<int, std::string>> frames;
  for (const auto& e : fs::directory_iterator(fs::path(config.data_dir) / "color")) {
    const int id = id_from_name(e.path().filename().string());
    if (id >= 0) frames.emplace_back(id, e.path().string());
  }
  std::sort(frames.begin(), frames.end());
  if (frames.empty()) throw std::runtime_error(config.data_dir + "/color has no numbered images");

  for (const char* sub : {"images", "cams", "depth_gt"}) make_directories(config.out_dir + "/" + sub);
  ImportSummary summary;
  summary.depth_min = std::numeric_limits<double>::infinity();
  std::vector<ImportedView> views;
  std::vector<std::vector<Eigen::Vector3d>> points;
  for (const auto& [id, color_path] : frames) {
    if (id < 1 || id > static_cast<int>(poses.size())) {
      throw std::runtime_error(color_path + ": no line " + std::to_string(id) + " in " + pose_path + " (" + std::to_string(poses.size()) +
                               " poses)");
    }
    const std::string depth_path = depth_image_for(config.data_dir + "/depth", color_path);
    const auto image = read_image_rgb8(color_path);
    const auto raw = read_image_u16(depth_path);
    if (raw.size(0) != image.size(0) || raw.size(1) != image.size(1)) {
      throw std::runtime_error(depth_path + ": size differs from " + color_path);
    }
    auto depth = raw.to(torch::kFloat32) / static_cast<float>(config.depth_scale);  // 0 stays 0 = no depth
    ImportedView iv;
    iv.id = id;
    Camera& cam = iv.cam.camera;
    cam.K << config.fx, 0, config.cx, 0, config.fy, config.cy, 0, 0, 1;
    cam.T_cam_world = poses[id - 1].inverse();
    cam.T_cam_world.row(3) << 0, 0, 0, 1;
    cam.width = static_cast<int>(image.size(1));
    cam.height = static_cast<int>(image.size(0));
    try {
      cam.validate(color_path);
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(e.what());
    }
    auto valid = depth.masked_select(depth > 0);
    if (valid.numel() == 0) throw std::runtime_error(depth_path + ": no valid depth");
    set_depth_range(iv.cam, valid.min().item<double>(), valid.max().item<double>(), config.depth_margin, config.depth_num, depth_path);
    summary.depth_min = std::min(summary.depth_min, iv.cam.depth_min);
    summary.depth_max = std::max(summary.depth_max, iv.cam.depth_max);
    // Surface samples for the view-selection score: a 32x24 grid of the GT depth.
    std::vector<Eigen::Vector3d> pts;
    auto d = depth.accessor<float, 2>();
    for (int gy = 0; gy < 24; ++gy) {
      for (int gx = 0; gx < 32; ++gx) {
        const int y = (2 * gy + 1) * cam.height / 48, x = (2 * gx + 1) * cam.width / 64;
        if (d[y][x] > 0) pts.push_back(cam.backproject(x, y, d[y][x]));
      }
    }
    const std::string stem = view_file_stem(id);
    copy_atomically(color_path, config.out_dir + "/images/" + stem + fs::path(color_path).extension().string());
    write_pfm(config.out_dir + "/depth_gt/" + stem + ".pfm", depth);
    write_cam_file(config.out_dir + "/cams/" + stem + "_cam.txt", iv.cam);
    views.push_back(iv);
    points.push_back(std::move(pts));
  }
  write_pairs(config.out_dir + "/pair.txt", views, points, config.num_sources);
  summary.views = static_cast<int>(views.size());
  return summary;
}

}  // namespace umvs
