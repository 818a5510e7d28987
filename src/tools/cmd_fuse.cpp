// umvs fuse: depth maps of a scene -> one consistent coloured point cloud (binary PLY or PCD),
// optionally cleaned by PCL filters (io/cloud_filter.h).
#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <sstream>
#include <tuple>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/fusion_settings.h"
#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/cloud_filter.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/occupancy_map.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

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
  if (umvs::InferenceFolder::holds(depth)) {  // written by `umvs infer`
    const umvs::InferenceFolder f(depth);
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
umvs::FusionView load_view(const Layout& l, int id) {
  const std::string stem = umvs::view_file_stem(id);
  umvs::FusionView v;
  v.id = id;
  v.depth = umvs::read_pfm(l.depth_dir + "/" + stem + ".pfm");
  if (v.depth.dim() != 2) throw std::runtime_error(l.depth_dir + "/" + stem + ".pfm: expected a one-channel depth map");
  const int H = static_cast<int>(v.depth.size(0)), W = static_cast<int>(v.depth.size(1));
  if (!l.confidence_dir.empty() && fs::exists(l.confidence_dir + "/" + stem + ".pfm")) {
    v.confidence = umvs::read_pfm(l.confidence_dir + "/" + stem + ".pfm");
  }
  const auto image = umvs::read_image_rgb8(umvs::find_view_image(l.image_dir, id));
  umvs::Camera cam = umvs::read_cam_file(l.cam_dir + "/" + stem + "_cam.txt").camera;
  cam.width = static_cast<int>(image.size(1));
  cam.height = static_cast<int>(image.size(0));
  if (cam.width != W || cam.height != H) {
    // The cam file describes the image; the depth map is a scaled version of it.
    cam = cam.resized(W, H);
    v.color = umvs::float_to_rgb8(umvs::resize_image(umvs::rgb8_to_float(image), W, H));
  } else {
    v.color = image;
  }
  v.camera = cam;
  return v;
}

// A box given as xmin,ymin,zmin,xmax,ymax,zmax to `option`.
std::vector<double> parse_box(const std::string& s, const std::string& option) {
  const auto refuse = [&] {
    return std::invalid_argument("--" + option + " needs xmin,ymin,zmin,xmax,ymax,zmax (numbers, min < max), got '" + s + "'");
  };
  std::vector<double> b;
  std::stringstream ss(s);
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
  return b;
}

}  // namespace

UMVS_COMMAND(fuse, "fuse depth maps into one consistent point cloud (PLY or PCD)") {
  umvs::FusionConfig cfg;  // the thresholds' options are bound to its fields (core/fusion_settings.h)
  umvs::Args args("fuse",
                  "Keeps the depth-map pixels that enough other views agree with (reprojection error and\n"
                  "relative depth difference after a round trip, see docs/fusion.md) and writes them as one\n"
                  "binary PLY or compressed PCD (by the extension of --out) with colour, confidence and\n"
                  "agreeing-view count, optionally cleaned by PCL filters (off by default; in this order:\n"
                  "--sor-k, --radius, --voxel-grid).\n"
                  "--depth is either a folder written by `umvs infer` (depth_est/, confidence/, cams/,\n"
                  "images/, pair.txt: --data is then optional) or a folder of XXXXXXXX.pfm depth maps such as\n"
                  "DATA/depth_gt (cameras, images and pair.txt then come from --data; cameras are rescaled\n"
                  "when the depth maps are smaller than the images).");
  args.required("depth", "depth folder: `umvs infer` output or a folder of XXXXXXXX.pfm")
      .option("data", "", "MVSNet-format folder for cams/images/pair.txt missing from --depth")
      .required("out", "output cloud, .ply or .pcd (written atomically; an existing file is kept when fusion fails); "
                       "or an occupancy map, .bt (OctoMap: confident pixels ray-cast from their cameras)")
      .option("octomap-resolution", umvs::OccupancyMapConfig{}.resolution, ".bt: leaf edge (metres)")
      .option("octomap-max-range", umvs::OccupancyMapConfig{}.max_range, ".bt: rays cut at this range (metres)")
      .option("octomap-pixel-stride", umvs::OccupancyMapConfig{}.pixel_stride, ".bt: every N-th depth pixel each way casts a ray")
      .option("octomap-extent", "",
              ".bt: the map's box MIN_X,MIN_Y,MIN_Z,MAX_X,MAX_Y,MAX_Z in metres (default: a building floor, "
              "-25,-25,-2,25,25,4); nothing outside is mapped");
  for (const auto& setting : umvs::fusion_settings()) {
    setting.visit(cfg, [&](auto& field) { args.bind(setting.option(), &field, setting.help); });
    for (const auto& old : setting.old_options) args.deprecated(old, setting.option());
  }
  args.option("source-rule", umvs::to_string(cfg.source_rule),
              "which source depths count: neighbours (the 4 source pixels around the projection are confident\n"
              "estimates) | mvsnet (MVSNet's eval.py: the raw source depth, as cv2.remap reads it)")
      .option("ref", "", "comma-separated view ids to fuse (default: all in pair.txt with a depth map)")
      .flag("stream", "use the streaming fusion (views in pair.txt order, --window recent estimates)")
      .option("window", "10", "with --stream: estimates kept in the ring")
      .option("sor-k", "0", "statistical outlier removal: neighbours per point (PCL mean-K; 0 = off)")
      .option("sor-std", "2.0", "statistical outlier removal: drop points farther than mean + this many std devs")
      .option("radius", "0", "radius outlier removal: search radius in scene units (0 = off)")
      .option("radius-min", "2", "radius outlier removal: neighbours needed within --radius")
      .option("voxel-grid", "0", "PCL voxel grid leaf in scene units: one averaged point per cube (0 = off)")
      .option("bbox", "", "xmin,ymin,zmin,xmax,ymax,zmax: also report the share of points inside")
      .option("device", "cpu", "cpu | cuda | cuda:N")
      .option("threads", 0, "CPU threads (0 = all cores)");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(args.integer("threads"));
  const auto device = umvs::parse_device(args.str("device"));
  cfg.source_rule = umvs::fusion_source_rule_from_string(args.str("source-rule"));
  cfg.validate();
  umvs::CloudFilterConfig filters;
  filters.sor_mean_k = args.integer("sor-k");
  filters.sor_std_mul = args.real("sor-std");
  filters.radius = args.real("radius");
  filters.radius_min_neighbors = args.integer("radius-min");
  filters.voxel_leaf = args.real("voxel-grid");
  filters.validate();
  const bool occupancy = fs::path(args.str("out")).extension() == ".bt";
  umvs::OccupancyMapConfig occupancy_cfg;
  occupancy_cfg.resolution = args.real("octomap-resolution");
  occupancy_cfg.max_range = args.real("octomap-max-range");
  occupancy_cfg.pixel_stride = args.integer("octomap-pixel-stride");
  occupancy_cfg.min_confidence = cfg.min_confidence;
  if (!args.str("octomap-extent").empty()) {
    const std::vector<double> box = parse_box(args.str("octomap-extent"), "octomap-extent");
    std::tie(occupancy_cfg.min_x, occupancy_cfg.min_y, occupancy_cfg.min_z, occupancy_cfg.max_x, occupancy_cfg.max_y,
             occupancy_cfg.max_z) = std::tie(box[0], box[1], box[2], box[3], box[4], box[5]);
  }
  if (occupancy) occupancy_cfg.validate();
  else umvs::cloud_file_format(args.str("out"));  // a wrong extension is refused before any work
  const auto bbox = args.given("bbox") ? parse_box(args.str("bbox"), "bbox") : std::vector<double>{};

  const Layout layout = find_layout(args.str("depth"), args.str("data"));
  if (!fs::exists(layout.pair_file)) throw std::runtime_error("no pair file " + layout.pair_file);
  const auto pairs = umvs::read_pair_file(layout.pair_file);
  std::vector<int> ids = args.integers("ref");
  if (ids.empty()) {
    for (const auto& p : pairs) {
      if (fs::exists(layout.depth_dir + "/" + umvs::view_file_stem(p.ref) + ".pfm")) ids.push_back(p.ref);
    }
  }
  if (ids.empty()) throw std::runtime_error("no depth maps (XXXXXXXX.pfm) for the views of " + layout.pair_file + " in " + layout.depth_dir);

  const auto t_load = std::chrono::steady_clock::now();
  std::vector<umvs::FusionView> views;
  std::map<int, int> index_of;
  for (int id : ids) {
    index_of[id] = static_cast<int>(views.size());
    views.push_back(load_view(layout, id));
  }
  // Sources from pair.txt, restricted to the views we have.
  std::vector<std::vector<int>> sources(views.size());
  for (const auto& p : pairs) {
    auto it = index_of.find(p.ref);
    if (it == index_of.end()) continue;
    for (int s : p.sources) {
      auto jt = index_of.find(s);
      if (jt != index_of.end() && jt->second != it->second) sources[it->second].push_back(jt->second);
    }
  }
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_load).count();
  std::cerr << "loaded " << views.size() << " depth maps (" << views[0].depth.size(1) << "x" << views[0].depth.size(0) << ") from "
            << layout.depth_dir << " in " << load_s << " s; device " << device << ", " << torch::get_num_threads() << " threads\n";

  if (occupancy) {  // an OctoMap: every confident pixel a ray from its camera, no consistency test
    const auto t = std::chrono::steady_clock::now();
    umvs::OccupancyMap map(occupancy_cfg);
    int64_t rays = 0, outside = 0;
    for (const auto& v : views) {
      const umvs::OccupancyIntegration r = map.integrate(v.depth, v.confidence, v.camera);
      rays += r.rays;
      outside += r.camera_outside;
    }
    if (outside > 0) {
      std::cerr << "warning: " << outside << " of " << views.size()
                << " views have their camera outside --octomap-extent and were left out of the map\n";
    }
    map.save(args.str("out"));
    std::printf("occupancy map of %zu views (%lld rays, %.3g m leaves) in %.2f s: %zu occupied, %zu free leaves; wrote %s\n",
                views.size(), static_cast<long long>(rays), occupancy_cfg.resolution,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(), map.occupied_leaves(),
                map.free_leaves(), args.str("out").c_str());
    return 0;
  }
  const auto t0 = std::chrono::steady_clock::now();
  umvs::PointCloud cloud;
  if (args.on("stream")) {
    umvs::StreamingFusion stream(cfg, args.integer("window"), size_t(1) << 40, device);
    for (const auto& v : views) {
      const auto t = std::chrono::steady_clock::now();
      const size_t added = stream.add(v).size();
      std::printf("view %8lld: %zu new points, %.3f s\n", static_cast<long long>(v.id), added,
                  std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count());
    }
    cloud = stream.cloud();
    std::printf("%lld points removed as free space (seen through by %d estimates in a row)\n",
                static_cast<long long>(stream.points_cleared()), cfg.clear_after_views);
  } else {
    std::vector<umvs::FusionViewStats> stats;
    cloud = umvs::DepthFusion(cfg, device).fuse(views, sources, &stats);
    for (const auto& s : stats) {
      std::printf("view %8lld: %2d sources, %8lld valid px, %8lld points, %.3f s\n", static_cast<long long>(s.id), s.num_sources,
                  static_cast<long long>(s.valid_pixels), static_cast<long long>(s.points), s.seconds);
    }
  }
  const double fuse_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("fused %zu views into %zu points in %.2f s (%.3f s per view)\n", views.size(), cloud.size(), fuse_s,
              fuse_s / views.size());
  auto report_bbox = [&] {
    if (bbox.empty()) return;
    size_t inside = 0;
    for (const auto& p : cloud.points) {
      inside += p.x() >= bbox[0] && p.y() >= bbox[1] && p.z() >= bbox[2] && p.x() <= bbox[3] && p.y() <= bbox[4] && p.z() <= bbox[5];
    }
    std::printf("inside the bounding box: %zu of %zu points (%.1f%%)\n", inside, cloud.size(),
                cloud.empty() ? 0.0 : 100.0 * inside / cloud.size());
  };
  report_bbox();
  if (filters.any()) {
    std::vector<umvs::CloudFilterStep> steps;
    cloud = umvs::filter_cloud(cloud, filters, &steps);
    for (const auto& s : steps) {
      std::printf("filter %s: %zu -> %zu points in %.3f s\n", s.name.c_str(), s.points_before, s.points_after, s.seconds);
    }
    report_bbox();  // the last line is the written cloud's
  }
  if (cloud.empty()) {
    std::cerr << "no point survived the consistency test: nothing written (loosen --min-agreeing-views, "
                 "--min-confidence, --max-reprojection-px or --max-relative-depth)\n";
    return 1;
  }
  umvs::write_cloud(args.str("out"), cloud);
  std::printf("wrote %s\n", args.str("out").c_str());
  return 0;
}
