// umvs fuse: depth maps of a scene -> one consistent coloured point cloud (binary PLY or PCD),
// optionally cleaned by PCL filters (io/cloud_filter.h).
#include <torch/torch.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <optional>
#include <tuple>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/fusion_settings.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/cloud_filter.h"
#include "unsup_mvs/io/fusion_input.h"
#include "unsup_mvs/io/occupancy_map.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

namespace fs = std::filesystem;

UMVS_COMMAND(fuse, "fuse depth maps into one consistent point cloud (PLY or PCD)") {
  umvs::FusionConfig cfg;  // the thresholds' options are bound to its fields (core/fusion_settings.h)
  umvs::CloudFilterConfig filters;
  umvs::OccupancyMapConfig occupancy_cfg;
  int window = 10;
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
      .bind("octomap-resolution", &occupancy_cfg.resolution, ".bt: leaf edge (metres)")
      .bind("octomap-max-range", &occupancy_cfg.max_range, ".bt: rays cut at this range (metres)")
      .bind("octomap-pixel-stride", &occupancy_cfg.pixel_stride, ".bt: every N-th depth pixel each way casts a ray")
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
      .bind("window", &window, "with --stream: estimates kept in the ring")
      .bind("sor-k", &filters.sor_mean_k, "statistical outlier removal: neighbours per point (PCL mean-K; 0 = off)")
      .bind("sor-std", &filters.sor_std_mul, "statistical outlier removal: drop points farther than mean + this many std devs")
      .bind("radius", &filters.radius, "radius outlier removal: search radius in scene units (0 = off)")
      .bind("radius-min", &filters.radius_min_neighbors, "radius outlier removal: neighbours needed within --radius")
      .bind("voxel-grid", &filters.voxel_leaf, "PCL voxel grid leaf in scene units: one averaged point per cube (0 = off)")
      .option("bbox", "", "xmin,ymin,zmin,xmax,ymax,zmax: also report the share of points inside")
      .option("device", "cpu", "cpu | cuda | cuda:N")
      .option("threads", 0, "CPU threads (0 = all cores)");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(args.integer("threads"));
  const auto device = umvs::parse_device(args.str("device"));
  cfg.source_rule = umvs::fusion_source_rule_from_string(args.str("source-rule"));
  cfg.validate();
  filters.validate();
  const bool occupancy = fs::path(args.str("out")).extension() == ".bt";
  occupancy_cfg.min_confidence = cfg.min_confidence;
  if (!args.str("octomap-extent").empty()) {
    const umvs::BoundingBox box = umvs::parse_box(args.str("octomap-extent"), "octomap-extent");
    std::tie(occupancy_cfg.min_x, occupancy_cfg.min_y, occupancy_cfg.min_z, occupancy_cfg.max_x, occupancy_cfg.max_y,
             occupancy_cfg.max_z) = std::tie(box[0], box[1], box[2], box[3], box[4], box[5]);
  }
  if (occupancy) occupancy_cfg.validate();
  else umvs::cloud_file_format(args.str("out"));  // a wrong extension is refused before any work
  const auto bbox = args.given("bbox") ? std::optional(umvs::parse_box(args.str("bbox"), "bbox")) : std::nullopt;

  const auto t_load = std::chrono::steady_clock::now();
  const umvs::FusionInput input = umvs::load_fusion_input(args.str("depth"), args.str("data"), args.integers("ref"));
  const auto& views = input.views;
  const double load_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t_load).count();
  std::cerr << "loaded " << views.size() << " depth maps (" << views[0].depth.size(1) << "x" << views[0].depth.size(0) << ") from "
            << input.depth_dir << " in " << load_s << " s; device " << device << ", " << torch::get_num_threads() << " threads\n";
  if (occupancy) {  // an OctoMap: every confident pixel a ray from its camera, no consistency test
    const auto t = std::chrono::steady_clock::now();
    umvs::OccupancyMap map(occupancy_cfg);
    const auto cast = umvs::integrate_input(map, input);
    if (cast.cameras_outside > 0) {
      std::cerr << "warning: " << cast.cameras_outside << " of " << views.size()
                << " views have their camera outside --octomap-extent and were left out of the map\n";
    }
    map.save(args.str("out"));
    std::printf("occupancy map of %zu views (%lld rays, %.3g m leaves) in %.2f s: %zu occupied, %zu free leaves; wrote %s\n",
                views.size(), static_cast<long long>(cast.rays), occupancy_cfg.resolution,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count(), map.occupied_leaves(),
                map.free_leaves(), args.str("out").c_str());
    return 0;
  }
  const auto t0 = std::chrono::steady_clock::now();
  umvs::PointCloud cloud = umvs::fuse_input(input, cfg, args.on("stream"), window, device, std::cout);
  const double fuse_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("fused %zu views into %zu points in %.2f s (%.3f s per view)\n", views.size(), cloud.size(), fuse_s,
              fuse_s / views.size());
  const auto report_bbox = [&] {
    if (!bbox) return;
    const size_t inside = umvs::points_inside(cloud, *bbox);
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
