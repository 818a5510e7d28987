// The posed RGB-D layouts of io/import.h: frames listed per layout, then one writer.
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

bool CameraIntrinsics::distorted() const {
  return std::any_of(distortion.begin(), distortion.end(), [](double d) { return d != 0.0; });
}

const char* to_string(RgbdLayout layout) {
  switch (layout) {
    case RgbdLayout::kSlambook: return "slambook";
    case RgbdLayout::kTum: return "tum";
    case RgbdLayout::kSevenScenes: return "sevenscenes";
    case RgbdLayout::kDvmvs: return "dvmvs";
  }
  return "?";
}

CameraIntrinsics read_intrinsics_file(const std::string& path) {
  checked_file_size(path, kMaxTextFileBytes, "intrinsics file");
  const std::string text = read_file_bytes(path);
  CameraIntrinsics in;
  const auto set_pinhole = [&](double fx, double fy, double cx, double cy) {
    in.K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  };
  // ORB-SLAM / OpenCV YAML: "Camera.fx: 535.4".
  static const std::regex key(R"(Camera\.(fx|fy|cx|cy|k1|k2|p1|p2|k3)\s*:\s*([-+0-9.eE]+))");
  std::map<std::string, double> keys;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), key); it != std::sregex_iterator(); ++it) {
    keys[(*it)[1]] = std::stod((*it)[2]);
  }
  if (!keys.empty()) {
    for (const char* k : {"fx", "fy", "cx", "cy"}) {
      if (!keys.count(k)) throw std::runtime_error(path + ": has Camera.* keys but no Camera." + k);
    }
    set_pinhole(keys["fx"], keys["fy"], keys["cx"], keys["cy"]);
    for (const char* k : {"k1", "k2", "p1", "p2", "k3"}) in.distortion.push_back(keys.count(k) ? keys[k] : 0.0);
  } else {
    const std::vector<double> v = numbers_in(text, path);
    // Nine numbers are a 3x3 matrix when they look like one (bottom row 0 0 1), else
    // "fx fy cx cy k1 k2 p1 p2 k3".
    const bool matrix = v.size() == 9 && v[3] == 0.0 && v[6] == 0.0 && v[7] == 0.0 && v[8] == 1.0;
    if (matrix) {
      for (int i = 0; i < 9; ++i) in.K(i / 3, i % 3) = v[i];
    } else if (v.size() == 4 || v.size() == 8 || v.size() == 9) {
      set_pinhole(v[0], v[1], v[2], v[3]);
      in.distortion.assign(v.begin() + 4, v.end());
    } else {
      throw std::runtime_error(path + ": expected a 3x3 matrix or 'fx fy cx cy [k1 k2 p1 p2 [k3]]', found " +
                               std::to_string(v.size()) + " numbers");
    }
  }
  if (!in.K.allFinite() || in.K(0, 0) == 0.0 || in.K(1, 1) == 0.0 || in.K(2, 2) != 1.0 || in.K(1, 0) != 0.0 ||
      in.K(2, 0) != 0.0 || in.K(2, 1) != 0.0) {
    throw std::runtime_error(path + ": not a pinhole intrinsic matrix [[fx,s,cx],[0,fy,cy],[0,0,1]] with fx, fy != 0");
  }
  return in;
}

namespace {

// Lines of a text file without comments ('#') and blank lines, with their 1-based line numbers.
std::vector<std::pair<int, std::string>> data_lines(const std::string& path, const char* what) {
  checked_file_size(path, kMaxTextFileBytes, what);
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open " + std::string(what) + " " + path);
  std::vector<std::pair<int, std::string>> lines;
  int number = 0;
  for (std::string line; std::getline(in, line);) {
    ++number;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    lines.emplace_back(number, line);
  }
  return lines;
}

Eigen::Matrix4d pose_from_quaternion(const double t[3], const double q[4], const std::string& where) {
  const Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
  if (!std::isfinite(quat.norm()) || std::abs(quat.norm() - 1.0) > 1e-3 || !std::isfinite(t[0] + t[1] + t[2])) {
    throw std::runtime_error(where + ": not a unit quaternion or non-finite pose");
  }
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = quat.normalized().toRotationMatrix();
  T.topRightCorner<3, 1>() = Eigen::Vector3d(t[0], t[1], t[2]);
  return T;
}

// A camera-to-world 4x4 from 16 numbers (row-major); almost-rotations are repaired as in camera files.
Eigen::Matrix4d pose_from_matrix(const std::vector<double>& v, const std::string& where) {
  if (v.size() != 16) throw std::runtime_error(where + ": expected 16 numbers of a 4x4 pose, found " + std::to_string(v.size()));
  Eigen::Matrix4d T;
  for (int i = 0; i < 16; ++i) T(i / 4, i % 4) = v[i];
  if (!T.allFinite()) throw std::runtime_error(where + ": non-finite pose");
  const Eigen::Matrix3d R = T.topLeftCorner<3, 3>();
  if (R.determinant() <= 0.0 || orthonormality_error(R) > kMaxRotationRepairError) {
    throw std::runtime_error(where + ": the pose's rotation is not a proper rotation");
  }
  T.topLeftCorner<3, 3>() = nearest_rotation(R);
  T.row(3) << 0, 0, 0, 1;
  return T;
}

std::vector<RgbdFrame> slambook_frames(const RgbdImportConfig& config) {
  for (const char* sub : {"color", "depth"}) {
    if (!fs::is_directory(fs::path(config.data_dir) / sub)) throw std::runtime_error(config.data_dir + " has no " + sub + "/ folder");
  }
  const std::string pose_path = config.data_dir + "/pose.txt";
  std::vector<Eigen::Matrix4d> poses;  // line k = frame k+1
  for (const auto& [number, line] : data_lines(pose_path, "pose file")) {
    std::istringstream ls(line);
    double t[3], q[4];
    const std::string where = pose_path + " line " + std::to_string(number);
    if (!(ls >> t[0] >> t[1] >> t[2] >> q[0] >> q[1] >> q[2] >> q[3])) throw std::runtime_error(where + ": expected 'tx ty tz qx qy qz qw'");
    poses.push_back(pose_from_quaternion(t, q, where));
  }
  std::vector<RgbdFrame> frames;
  for (const auto& e : fs::directory_iterator(fs::path(config.data_dir) / "color")) {
    const int id = id_from_name(e.path().filename().string());
    if (id < 0) continue;
    RgbdFrame f;
    f.id = id;
    f.color_path = e.path().string();
    frames.push_back(f);
  }
  std::sort(frames.begin(), frames.end(), [](const RgbdFrame& a, const RgbdFrame& b) { return a.id < b.id; });
  if (frames.empty()) throw std::runtime_error(config.data_dir + "/color has no numbered images");
  for (auto& f : frames) {
    if (f.id < 1 || f.id > static_cast<int>(poses.size())) {
      throw std::runtime_error(f.color_path + ": no line " + std::to_string(f.id) + " in " + pose_path + " (" +
                               std::to_string(poses.size()) + " poses)");
    }
    f.T_world_cam = poses[f.id - 1];
    f.depth_path = depth_image_for(config.data_dir + "/depth", f.color_path);
  }
  return frames;
}

struct Stamped {
  double time = 0.0;
  std::string value;  // the rest of the line
  std::string where;
};

std::vector<Stamped> stamped_lines(const std::string& path, const char* what) {
  std::vector<Stamped> out;
  for (const auto& [number, line] : data_lines(path, what)) {
    std::istringstream ls(line);
    Stamped s;
    s.where = path + " line " + std::to_string(number);
    if (!(ls >> s.time) || !std::isfinite(s.time)) throw std::runtime_error(s.where + ": expected a timestamp first");
    std::getline(ls, s.value);
    out.push_back(s);
  }
  if (out.empty()) throw std::runtime_error(path + " lists nothing");
  return out;
}

// The entry of `list` (sorted by time) nearest to t, or nullptr when none is within max_dt.
const Stamped* nearest_in_time(const std::vector<Stamped>& list, double t, double max_dt) {
  auto it = std::lower_bound(list.begin(), list.end(), t, [](const Stamped& s, double x) { return s.time < x; });
  const Stamped* best = nullptr;
  for (auto c : {it, it == list.begin() ? it : std::prev(it)}) {
    if (c == list.end()) continue;
    if (!best || std::abs(c->time - t) < std::abs(best->time - t)) best = &*c;
  }
  return best && std::abs(best->time - t) <= max_dt ? best : nullptr;
}

std::string first_word(const std::string& s) {
  std::istringstream ss(s);
  std::string w;
  ss >> w;
  return w;
}

std::vector<RgbdFrame> tum_frames(const RgbdImportConfig& config) {
  const bool by_index = config.tum_association == "index";
  if (!by_index && config.tum_association != "timestamp") {
    throw std::runtime_error("unknown association '" + config.tum_association + "' (expected timestamp | index)");
  }
  if (!by_index && !(config.tum_max_dt > 0)) throw std::runtime_error("the timestamp tolerance must be > 0 s");
  const auto rgb = stamped_lines(config.data_dir + "/rgb.txt", "image list");
  auto depth = stamped_lines(config.data_dir + "/depth.txt", "depth list");
  auto poses = stamped_lines(config.data_dir + "/" + config.tum_pose_file, "pose file");
  const auto by_time = [](const Stamped& a, const Stamped& b) { return a.time < b.time; };
  std::stable_sort(depth.begin(), depth.end(), by_time);
  std::stable_sort(poses.begin(), poses.end(), by_time);
  std::vector<RgbdFrame> frames;
  int without = 0;
  for (size_t i = 0; i < rgb.size(); ++i) {
    const Stamped* d = nullptr;
    const Stamped* p = nullptr;
    if (by_index) {
      if (i >= depth.size() || i >= poses.size()) {
        throw std::runtime_error(rgb[i].where + ": association by row needs as many depth images and poses as images (" +
                                 std::to_string(depth.size()) + " depth, " + std::to_string(poses.size()) + " poses)");
      }
      d = &depth[i];
      p = &poses[i];
    } else {
      d = nearest_in_time(depth, rgb[i].time, config.tum_max_dt);
      p = nearest_in_time(poses, rgb[i].time, config.tum_max_dt);
    }
    if (!d || !p) {
      ++without;
      continue;
    }
    std::istringstream ls(p->value);
    double t[3], q[4];
    if (!(ls >> t[0] >> t[1] >> t[2] >> q[0] >> q[1] >> q[2] >> q[3])) throw std::runtime_error(p->where + ": expected 'timestamp tx ty tz qx qy qz qw'");
    RgbdFrame f;
    f.id = static_cast<int>(i);
    f.color_path = config.data_dir + "/" + first_word(rgb[i].value);
    f.depth_path = config.data_dir + "/" + first_word(d->value);
    f.T_world_cam = pose_from_quaternion(t, q, p->where);
    for (const auto* path : {&f.color_path, &f.depth_path}) {
      if (!fs::is_regular_file(*path)) throw std::runtime_error("no file " + *path + " (listed in " + config.data_dir + ")");
    }
    frames.push_back(f);
  }
  if (frames.empty()) {
    throw std::runtime_error("no image of " + config.data_dir + "/rgb.txt has a depth image and a pose within " +
                             std::to_string(config.tum_max_dt) + " s (timestamps of another clock? try --associate index)");
  }
  return frames;
}

std::vector<RgbdFrame> sevenscenes_frames(const RgbdImportConfig& config) {
  std::vector<RgbdFrame> frames;
  static const std::regex color_name(R"(frame-(\d+)\.color\.(png|jpg))");
  for (const auto& e : fs::directory_iterator(config.data_dir)) {
    const std::string name = e.path().filename().string();
    std::smatch m;
    if (!std::regex_match(name, m, color_name)) continue;
    RgbdFrame f;
    f.id = std::stoi(m[1]);
    f.color_path = e.path().string();
    const std::string stem = config.data_dir + "/frame-" + m[1].str();
    f.depth_path = stem + ".depth.png";
    if (!fs::is_regular_file(f.depth_path)) throw std::runtime_error("no depth image " + f.depth_path + " for " + name);
    const std::string pose_path = stem + ".pose.txt";
    checked_file_size(pose_path, kMaxTextFileBytes, "pose file");
    f.T_world_cam = pose_from_matrix(numbers_in(read_file_bytes(pose_path), pose_path), pose_path);
    frames.push_back(f);
  }
  if (frames.empty()) throw std::runtime_error(config.data_dir + " has no frame-N.color.png or .jpg");
  std::sort(frames.begin(), frames.end(), [](const RgbdFrame& a, const RgbdFrame& b) { return a.id < b.id; });
  return frames;
}

std::vector<RgbdFrame> dvmvs_frames(const RgbdImportConfig& config) {
  const fs::path images = fs::path(config.data_dir) / "images";
  if (!fs::is_directory(images)) throw std::runtime_error(config.data_dir + " has no images/ folder");
  std::vector<std::string> names;
  for (const auto& e : fs::directory_iterator(images)) {
    if (e.path().extension() == ".png" || e.path().extension() == ".jpg") names.push_back(e.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  if (names.empty()) throw std::runtime_error(images.string() + " has no images");
  const std::string pose_path = config.data_dir + "/poses.txt";
  const auto lines = data_lines(pose_path, "pose file");
  std::vector<RgbdFrame> frames;
  for (size_t k = 0; k < names.size(); ++k) {
    if (k >= lines.size()) {
      throw std::runtime_error(pose_path + " has " + std::to_string(lines.size()) + " poses for " + std::to_string(names.size()) + " images");
    }
    const std::string where = pose_path + " line " + std::to_string(lines[k].first);
    RgbdFrame f;
    f.id = id_from_name(names[k]);
    if (f.id < 0) f.id = static_cast<int>(k);
    f.color_path = (images / names[k]).string();
    f.depth_path = depth_image_for(config.data_dir + "/depth", f.color_path);
    f.T_world_cam = pose_from_matrix(numbers_in(lines[k].second, where), where);
    frames.push_back(f);
  }
  return frames;
}

// Intrinsics of the layout: as given, else the data set's own file.
CameraIntrinsics layout_intrinsics(const RgbdImportConfig& config) {
  if (config.intrinsics.given()) return config.intrinsics;
  const char* own = config.layout == RgbdLayout::kSevenScenes ? "camera-intrinsics.txt"
                    : config.layout == RgbdLayout::kDvmvs     ? "K.txt"
                                                              : nullptr;
  if (!own) {
    throw std::runtime_error(std::string("the ") + to_string(config.layout) +
                             " layout has no intrinsics file: give them (--intrinsics FILE or --fx --fy --cx --cy)");
  }
  const std::string path = config.data_dir + "/" + own;
  if (!fs::is_regular_file(path)) throw std::runtime_error("no " + path + ": give the intrinsics (--intrinsics FILE or --fx --fy --cx --cy)");
  return read_intrinsics_file(path);
}

// Source pixel for each pixel of the undistorted image ([H,W,2] in grid_sample's [-1,1]
// coordinates, align_corners): the Brown-Conrady model applied to the pinhole ray.
torch::Tensor distortion_grid(const CameraIntrinsics& in, int width, int height) {
  std::vector<double> k = in.distortion;
  k.resize(5, 0.0);
  const auto opts = torch::TensorOptions().dtype(torch::kFloat64);
  const auto v = torch::arange(height, opts).view({height, 1}).expand({height, width});
  const auto u = torch::arange(width, opts).view({1, width}).expand({height, width});
  const double fx = in.K(0, 0), fy = in.K(1, 1), cx = in.K(0, 2), cy = in.K(1, 2), s = in.K(0, 1);
  const auto y = (v - cy) / fy;
  const auto x = (u - cx - s * y) / fx;
  const auto r2 = x * x + y * y;
  const auto radial = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
  const auto xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x);
  const auto yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y;
  const auto ud = fx * xd + s * yd + cx, vd = fy * yd + cy;
  return torch::stack({ud / (width - 1) * 2 - 1, vd / (height - 1) * 2 - 1}, -1).to(torch::kFloat32).unsqueeze(0);
}

torch::Tensor remap(const torch::Tensor& image_hwc, const torch::Tensor& grid, bool nearest) {
  namespace F = torch::nn::functional;
  const auto in = image_hwc.to(torch::kFloat32).permute({2, 0, 1}).unsqueeze(0);
  auto options = F::GridSampleFuncOptions().padding_mode(torch::kZeros).align_corners(true);
  if (nearest) options.mode(torch::kNearest);
  else options.mode(torch::kBilinear);
  const auto out = F::grid_sample(in, grid, options);
  return out.squeeze(0).permute({1, 2, 0});
}

}  // namespace

std::vector<RgbdFrame> list_rgbd_frames(const RgbdImportConfig& config) {
  if (!fs::is_directory(config.data_dir)) throw std::runtime_error("data folder '" + config.data_dir + "' does not exist");
  if (config.first < 0 || config.every < 1 || config.count < 0) throw std::runtime_error("frame selection needs first >= 0, every >= 1, count >= 0");
  std::vector<RgbdFrame> all;
  switch (config.layout) {
    case RgbdLayout::kSlambook: all = slambook_frames(config); break;
    case RgbdLayout::kTum: all = tum_frames(config); break;
    case RgbdLayout::kSevenScenes: all = sevenscenes_frames(config); break;
    case RgbdLayout::kDvmvs: all = dvmvs_frames(config); break;
  }
  std::vector<RgbdFrame> chosen;
  for (size_t i = config.first; i < all.size(); i += config.every) {
    if (config.count > 0 && static_cast<int>(chosen.size()) >= config.count) break;
    chosen.push_back(all[i]);
  }
  if (chosen.empty()) {
    throw std::runtime_error("no frame left of the " + std::to_string(all.size()) + " in " + config.data_dir + " after --first " +
                             std::to_string(config.first));
  }
  return chosen;
}

ImportSummary import_rgbd(const RgbdImportConfig& config) {
  check_import_folders(config.data_dir, config.out_dir, config.depth_num, config.num_sources);
  if (config.depth_scale < 0 || !std::isfinite(config.depth_scale)) throw std::runtime_error("depth scale must be > 0");
  const bool fixed_range = config.depth_near > 0 || config.depth_far > 0;
  if (fixed_range && !(config.depth_near > 0 && config.depth_far > config.depth_near && std::isfinite(config.depth_far))) {
    throw std::runtime_error("depth range needs 0 < near < far");
  }
  if (config.min_baseline < 0 || (config.max_baseline > 0 && config.max_baseline < config.min_baseline)) {
    throw std::runtime_error("baselines need 0 <= min <= max (max 0 = no limit)");
  }
  const CameraIntrinsics intrinsics = layout_intrinsics(config);
  const double depth_scale = config.depth_scale > 0 ? config.depth_scale
                             : (config.layout == RgbdLayout::kSlambook || config.layout == RgbdLayout::kTum) ? 5000.0
                                                                                                            : 1000.0;
  const auto frames = list_rgbd_frames(config);

  for (const char* sub : {"images", "cams", "depth_gt"}) make_directories(config.out_dir + "/" + sub);
  ImportSummary summary;
  summary.depth_min = std::numeric_limits<double>::infinity();
  std::vector<ImportedView> views;
  std::vector<std::vector<Eigen::Vector3d>> points;
  torch::Tensor grid;  // undistortion map, built for the first frame's size
  for (const auto& frame : frames) {
    auto image = read_image_rgb8(frame.color_path);
    const auto raw = read_image_u16(frame.depth_path);
    if (raw.size(0) != image.size(0) || raw.size(1) != image.size(1)) {
      throw std::runtime_error(frame.depth_path + ": size differs from " + frame.color_path);
    }
    // 0 and 65535 (7-Scenes, Kinect drivers) mean no measurement.
    auto depth = raw.to(torch::kFloat32).where(raw < 65535, torch::zeros({}, torch::kFloat32)) / static_cast<float>(depth_scale);
    ImportedView iv;
    iv.id = frame.id;
    Camera& cam = iv.cam.camera;
    cam.K = intrinsics.K;
    cam.width = static_cast<int>(image.size(1));
    cam.height = static_cast<int>(image.size(0));
    cam.T_cam_world = frame.T_world_cam.inverse();
    cam.T_cam_world.row(3) << 0, 0, 0, 1;
    try {
      cam.validate(frame.color_path);
    } catch (const std::invalid_argument& e) {
      throw std::runtime_error(e.what());
    }
    const std::string stem = view_file_stem(frame.id);
    if (intrinsics.distorted()) {
      if (!grid.defined() || grid.size(1) != cam.height || grid.size(2) != cam.width) grid = distortion_grid(intrinsics, cam.width, cam.height);
      image = remap(image, grid, false).round().clamp(0, 255).to(torch::kUInt8).contiguous();
      depth = remap(depth.unsqueeze(-1), grid, true).squeeze(-1).contiguous();
      write_png(config.out_dir + "/images/" + stem + ".png", image);
    } else {
      copy_atomically(frame.color_path, config.out_dir + "/images/" + stem + fs::path(frame.color_path).extension().string());
    }
    auto valid = depth.masked_select(depth > 0);
    if (valid.numel() == 0) throw std::runtime_error(frame.depth_path + ": no valid depth");
    if (fixed_range) {
      set_depth_range(iv.cam, config.depth_near, config.depth_far, 0.0, config.depth_num, frame.color_path);
    } else {
      set_depth_range(iv.cam, valid.min().item<double>(), valid.max().item<double>(), config.depth_margin, config.depth_num,
                      frame.depth_path);
    }
    summary.depth_min = std::min(summary.depth_min, iv.cam.depth_min);
    summary.depth_max = std::max(summary.depth_max, iv.cam.depth_max);
    // Surface samples for the view-selection score: with a fixed range nothing but depth_gt/ may
    // come from the sensor, so the frustum at the range's middle stands in for the surface (as the
    // keyframe selector does); else a 32x24 grid of the sensor depth.
    std::vector<Eigen::Vector3d> pts;
    if (fixed_range) {
      pts = sample_frustum_points(cam, view_selection_depth(config.depth_near, config.depth_far));
    } else {
      auto d = depth.accessor<float, 2>();
      for (int gy = 0; gy < 24; ++gy) {
        for (int gx = 0; gx < 32; ++gx) {
          const int y = (2 * gy + 1) * cam.height / 48, x = (2 * gx + 1) * cam.width / 64;
          if (d[y][x] > 0) pts.push_back(cam.backproject(x, y, d[y][x]));
        }
      }
    }
    write_pfm(config.out_dir + "/depth_gt/" + stem + ".pfm", depth);
    write_cam_file(config.out_dir + "/cams/" + stem + "_cam.txt", iv.cam);
    views.push_back(iv);
    points.push_back(std::move(pts));
  }
  write_pairs(config.out_dir + "/pair.txt", views, points, config.num_sources, config.min_baseline, config.max_baseline);
  summary.views = static_cast<int>(views.size());
  return summary;
}

}  // namespace umvs
