#include "unsup_mvs/io/mvs_folder.h"

#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/input_limits.h"

namespace umvs {

namespace fs = std::filesystem;

std::string view_file_stem(int id) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "%08d", id);
  return buf;
}

double MvsCam::resolved_depth_max(int default_num) const {
  if (depth_max > 0.0) return depth_max;
  const int n = depth_num > 0 ? depth_num : default_num;
  return depth_min + depth_interval * (n - 1);
}

namespace {

// Pose files written with few digits hold almost-rotations: those beyond validate()'s tolerance
// but within kMaxRotationRepairError are replaced by the nearest rotation, with one warning per
// process (a sequence repeats the problem in every file). Files within the tolerance are read as
// written; anything further off is left for validate() to refuse.
void repair_rotation(Camera& camera, const std::string& path) {
  const Eigen::Matrix3d R = camera.R();
  if (!R.allFinite() || R.determinant() <= 0.0) return;
  if ((R.transpose() * R).isIdentity(kRotationTolerance)) return;
  const double error = orthonormality_error(R);
  if (error > kMaxRotationRepairError) return;
  camera.T_cam_world.topLeftCorner<3, 3>() = nearest_rotation(R);
  static std::atomic<bool> warned{false};
  if (!warned.exchange(true)) {
    std::cerr << "warning: camera file '" << path << "': rotation re-orthonormalised (R^T R - I max " << error
              << "); other files of this kind are repaired without a message\n";
  }
}

}  // namespace

MvsCam read_cam_file(const std::string& path) {
  checked_file_size(path, kMaxTextFileBytes, "camera file");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open camera file '" + path + "'");
  auto fail = [&](const std::string& what) -> void { throw std::runtime_error("camera file '" + path + "': " + what); };
  // The format has 31 tokens at most; anything after them is ignored (and never held in memory).
  std::vector<std::string> tokens;
  for (std::string tok; tokens.size() < 31 && in >> tok;) tokens.push_back(tok);
  size_t pos = 0;
  auto expect = [&](const std::string& word) {
    if (pos >= tokens.size() || tokens[pos] != word) fail("expected '" + word + "'");
    ++pos;
  };
  auto number = [&](const char* what) {
    if (pos >= tokens.size()) fail(std::string("file ends before ") + what);
    const std::string& t = tokens[pos++];
    char* end = nullptr;
    const double v = std::strtod(t.c_str(), &end);
    if (end == t.c_str() || *end != '\0') fail(std::string("'") + t + "' in " + what + " is not a number");
    if (!std::isfinite(v)) fail(std::string("non-finite value in ") + what);
    return v;
  };
  MvsCam cam;
  expect("extrinsic");
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) cam.camera.T_cam_world(r, c) = number("the extrinsic matrix");
  expect("intrinsic");
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) cam.camera.K(r, c) = number("the intrinsic matrix");
  if (pos < tokens.size()) {
    cam.depth_min = number("the depth line");
    cam.depth_interval = pos < tokens.size() ? number("the depth line") : 0.0;
    if (pos < tokens.size()) {
      const double num = number("the depth line");
      if (num < 0 || num > 1e6 || num != std::floor(num)) fail("DEPTH_NUM must be a whole number in [0, 1000000]");
      cam.depth_num = static_cast<int>(num);
    }
    if (pos < tokens.size()) cam.depth_max = number("the depth line");
    if (cam.depth_min <= 0.0) fail("DEPTH_MIN must be positive, got " + std::to_string(cam.depth_min));
    if (cam.depth_interval < 0.0) fail("DEPTH_INTERVAL must not be negative");
    if (cam.depth_max != 0.0 && cam.depth_max <= cam.depth_min) {
      fail("impossible depth range: DEPTH_MAX " + std::to_string(cam.depth_max) + " <= DEPTH_MIN " + std::to_string(cam.depth_min));
    }
    if (cam.depth_max == 0.0 && cam.depth_interval == 0.0) fail("DEPTH_INTERVAL is 0 and no DEPTH_MAX is given");
  }
  repair_rotation(cam.camera, path);
  try {
    cam.camera.validate("camera file '" + path + "'");
  } catch (const std::invalid_argument& e) {
    throw std::runtime_error(e.what());
  }
  return cam;
}

void write_cam_file(const std::string& path, const MvsCam& cam) {
  write_file_atomically(path, [&](std::ostream& out) {
    out << std::setprecision(12) << "extrinsic\n";
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) out << cam.camera.T_cam_world(r, c) << (c < 3 ? " " : "\n");
    }
    out << "\nintrinsic\n";
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 3; ++c) out << cam.camera.K(r, c) << (c < 2 ? " " : "\n");
    }
    out << "\n" << cam.depth_min << " " << cam.depth_interval;
    if (cam.depth_num > 0 || cam.depth_max > 0) out << " " << cam.depth_num;
    if (cam.depth_max > 0) out << " " << cam.depth_max;
    out << "\n";
  });
}

std::vector<ViewPair> read_pair_file(const std::string& path) {
  const uint64_t size = checked_file_size(path, kMaxTextFileBytes, "pair file");
  std::ifstream in(path);
  if (!in) throw std::runtime_error("cannot open pair file '" + path + "'");
  auto fail = [&](const std::string& what) { throw std::runtime_error("pair file '" + path + "': " + what); };
  // Counts are bounded by the file size before anything is allocated: a view entry takes at least
  // 4 bytes ("r\n0\n"), a source at least 4 ("i s ").
  int count = 0;
  if (!(in >> count) || count < 0) fail("first line must be the number of views");
  check_claimed_count(static_cast<uint64_t>(count), 4, size, "pair file '" + path + "': number of views");
  std::vector<ViewPair> pairs(count);
  for (auto& p : pairs) {
    int n = 0;
    if (!(in >> p.ref >> n) || n < 0) fail("truncated or malformed entry");
    check_claimed_count(static_cast<uint64_t>(n), 4, size,
                        "pair file '" + path + "': number of sources of view " + std::to_string(p.ref));
    for (int i = 0; i < n; ++i) {
      int id;
      double score;
      if (!(in >> id >> score)) fail("truncated source list for view " + std::to_string(p.ref));
      p.sources.push_back(id);
      p.scores.push_back(score);
    }
  }
  return pairs;
}

void write_pair_file(const std::string& path, const std::vector<ViewPair>& pairs) {
  write_file_atomically(path, [&](std::ostream& out) {
    out << pairs.size() << "\n";
    for (const auto& p : pairs) {
      out << p.ref << "\n" << p.sources.size();
      for (size_t i = 0; i < p.sources.size(); ++i) out << " " << p.sources[i] << " " << std::setprecision(6) << p.scores[i];
      out << "\n";
    }
  });
}

MvsFolder::MvsFolder(const std::string& root) : root_(root) {
  if (!fs::is_directory(root)) throw std::runtime_error("MVS folder '" + root + "' does not exist");
  for (const char* sub : {"images", "cams"}) {
    if (!fs::is_directory(fs::path(root) / sub)) {
      throw std::runtime_error("MVS folder '" + root + "' has no " + sub + "/ subfolder");
    }
  }
  const auto pair_path = (fs::path(root) / "pair.txt").string();
  if (!fs::exists(pair_path)) throw std::runtime_error("MVS folder '" + root + "' has no pair.txt");
  pairs_ = read_pair_file(pair_path);
}

const ViewPair& MvsFolder::pair_of(int ref) const {
  for (const auto& p : pairs_) if (p.ref == ref) return p;
  throw std::runtime_error("view " + std::to_string(ref) + " has no entry in " + root_ + "/pair.txt");
}

std::string MvsFolder::image_path(int id) const { return find_view_image(root_ + "/images", id); }

std::string MvsFolder::cam_path(int id) const {
  return (fs::path(root_) / "cams" / (view_file_stem(id) + "_cam.txt")).string();
}

std::string MvsFolder::depth_gt_path(int id) const {
  const auto p = fs::path(root_) / "depth_gt" / (view_file_stem(id) + ".pfm");
  return fs::exists(p) ? p.string() : "";
}

MvsView MvsFolder::load_view(int id) const {
  MvsView view;
  view.id = id;
  view.cam = read_cam_file(cam_path(id));
  view.image = read_image_rgb8(image_path(id));
  view.cam.camera.height = static_cast<int>(view.image.size(0));
  view.cam.camera.width = static_cast<int>(view.image.size(1));
  return view;
}

std::string find_view_image(const std::string& images_dir, int id) {
  for (const char* ext : {".jpg", ".png", ".jpeg", ".JPG", ".PNG"}) {
    const auto p = fs::path(images_dir) / (view_file_stem(id) + ext);
    if (fs::exists(p)) return p.string();
  }
  throw std::runtime_error("no image for view " + std::to_string(id) + " in " + images_dir + " (expected " +
                           view_file_stem(id) + ".jpg or .png)");
}

}  // namespace umvs
