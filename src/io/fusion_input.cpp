// What `umvs fuse` reads (unsup_mvs/io/fusion_input.h).
#include "unsup_mvs/io/fusion_input.h"

#include <chrono>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <ostream>
#include <map>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

// Where the depth maps, confidences, cameras, colours and pairs of a fusion come from.
struct Layout {
  std::string depth_dir, confidence_dir, cam_dir, image_dir, pair_file;
};

Layout find_layout(const std::string& depth, const std::string& data) {
  Layout l;
  auto need_data = [&](const std::string& what) {
    if (data.empty()) throw std::invalid_argument("--depth " + depth + " has no " + what + ": give --data (the MVSNet folder)");
    return data;
  };
  if (InferenceFolder::holds(depth)) {  // written by `umvs infer`
    const InferenceFolder f(depth);
    l.depth_dir = f.depth_dir();
    if (fs::is_directory(f.confidence_dir())) l.confidence_dir = f.confidence_dir();
    l.cam_dir = fs::is_directory(f.cams_dir()) ? f.cams_dir() : need_data("cams/") + "/cams";
    l.image_dir = fs::is_directory(f.images_dir()) ? f.images_dir() : need_data("images/") + "/images";
    l.pair_file = fs::exists(f.pair_file()) ? f.pair_file() : need_data("pair.txt") + "/pair.txt";
  } else if (fs::is_directory(depth)) {  // a folder of XXXXXXXX.pfm, e.g. DATA/depth_gt
    l.depth_dir = depth;
    l.cam_dir = need_data("cams/") + "/cams";
    l.image_dir = data + "/images";
    l.pair_file = data + "/pair.txt";
  } else {
    throw std::invalid_argument("--depth '" + depth + "' is not a folder");
  }
  return l;
}

// Depth map, confidence, camera (rescaled to the depth map) and colours of one view.
FusionView load_view(const Layout& l, int id) {
  const std::string stem = view_file_stem(id);
  FusionView v;
  v.id = id;
  v.depth = read_pfm(l.depth_dir + "/" + stem + ".pfm");
  if (v.depth.dim() != 2) throw std::runtime_error(l.depth_dir + "/" + stem + ".pfm: expected a one-channel depth map");
  const int H = static_cast<int>(v.depth.size(0)), W = static_cast<int>(v.depth.size(1));
  if (!l.confidence_dir.empty() && fs::exists(l.confidence_dir + "/" + stem + ".pfm")) {
    v.confidence = read_pfm(l.confidence_dir + "/" + stem + ".pfm");
  }
  const auto image = read_image_rgb8(find_view_image(l.image_dir, id));
  Camera cam = read_cam_file(l.cam_dir + "/" + stem + "_cam.txt").camera;
  cam.width = static_cast<int>(image.size(1));
  cam.height = static_cast<int>(image.size(0));
  if (cam.width != W || cam.height != H) {
    // The cam file describes the image; the depth map is a scaled version of it.
    cam = cam.resized(W, H);
    v.color = float_to_rgb8(resize_image(rgb8_to_float(image), W, H));
  } else {
    v.color = image;
  }
  v.camera = cam;
  return v;
}

}  // namespace

FusionInput load_fusion_input(const std::string& depth, const std::string& data, const std::vector<int>& wanted) {
  const Layout layout = find_layout(depth, data);
  if (!fs::exists(layout.pair_file)) throw std::runtime_error("no pair file " + layout.pair_file);
  const auto pairs = read_pair_file(layout.pair_file);
  std::vector<int> ids = wanted;
  if (ids.empty()) {
    for (const auto& p : pairs) {
      if (fs::exists(layout.depth_dir + "/" + view_file_stem(p.ref) + ".pfm")) ids.push_back(p.ref);
    }
  }
  if (ids.empty()) throw std::runtime_error("no depth maps (XXXXXXXX.pfm) for the views of " + layout.pair_file + " in " + layout.depth_dir);
  FusionInput input;
  input.depth_dir = layout.depth_dir;
  std::map<int, int> index_of;
  for (int id : ids) {
    index_of[id] = static_cast<int>(input.views.size());
    input.views.push_back(load_view(layout, id));
  }
  // Sources from pair.txt, restricted to the views we have.
  input.sources.resize(input.views.size());
  for (const auto& p : pairs) {
    auto it = index_of.find(p.ref);
    if (it == index_of.end()) continue;
    for (int s : p.sources) {
      auto jt = index_of.find(s);
      if (jt != index_of.end() && jt->second != it->second) input.sources[it->second].push_back(jt->second);
    }
  }
  return input;
}

PointCloud fuse_input(const FusionInput& input, const FusionConfig& config, bool stream, int window,
                      const torch::Device& device, std::ostream& log) {
  char line[160];
  if (!stream) {
    std::vector<FusionViewStats> stats;
    PointCloud cloud = DepthFusion(config, device).fuse(input.views, input.sources, &stats);
    for (const auto& s : stats) {
      std::snprintf(line, sizeof(line), "view %8" PRId64 ": %2d sources, %8" PRId64 " valid px, %8" PRId64 " points, %.3f s\n",
                    static_cast<int64_t>(s.id), s.num_sources, static_cast<int64_t>(s.valid_pixels),
                    static_cast<int64_t>(s.points), s.seconds);
      log << line;
    }
    return cloud;
  }
  StreamingFusion fusion(config, window, size_t(1) << 40, device);
  for (const auto& v : input.views) {
    const auto t = std::chrono::steady_clock::now();
    const size_t added = fusion.add(v).size();
    std::snprintf(line, sizeof(line), "view %8" PRId64 ": %zu new points, %.3f s\n", static_cast<int64_t>(v.id), added,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count());
    log << line;
  }
  log << fusion.points_cleared() << " points removed as free space (seen through by " << config.clear_after_views
      << " estimates in a row)\n";
  return fusion.cloud();
}

InputIntegration integrate_input(OccupancyMap& map, const FusionInput& input) {
  InputIntegration total;
  for (const auto& v : input.views) {
    const OccupancyIntegration r = map.integrate(v.depth, v.confidence, v.camera);
    total.rays += r.rays;
    total.cameras_outside += r.camera_outside;
  }
  return total;
}

BoundingBox parse_box(const std::string& text, const std::string& option) {
  const auto refuse = [&] {
    return std::invalid_argument("--" + option + " needs xmin,ymin,zmin,xmax,ymax,zmax (numbers, min < max), got '" + text + "'");
  };
  std::vector<double> b;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) {
    size_t used = 0;
    try {
      b.push_back(std::stod(item, &used));
    } catch (const std::logic_error&) {  // not a number, or out of range
      throw refuse();
    }
    if (used != item.size() || !std::isfinite(b.back())) throw refuse();
  }
  if (b.size() != 6 || b[0] >= b[3] || b[1] >= b[4] || b[2] >= b[5]) throw refuse();
  return {b[0], b[1], b[2], b[3], b[4], b[5]};
}

size_t points_inside(const PointCloud& cloud, const BoundingBox& b) {
  size_t inside = 0;
  for (const auto& p : cloud.points) {
    inside += p.x() >= b[0] && p.y() >= b[1] && p.z() >= b[2] && p.x() <= b[3] && p.y() <= b[4] && p.z() <= b[5];
  }
  return inside;
}

}  // namespace umvs
