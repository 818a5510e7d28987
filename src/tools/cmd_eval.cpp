// umvs eval depth|cloud: depth-map and point-cloud metrics against ground truth (core/metrics.h).
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/metrics.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/jobs/fine_tune_job.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

namespace fs = std::filesystem;

namespace {

std::vector<double> parse_reals(const umvs::Args& args, const std::string& name) {
  std::vector<double> out;
  for (const auto& s : args.all(name)) {
    if (s.empty()) continue;
    char* end = nullptr;
    const double v = std::strtod(s.c_str(), &end);
    if (end == s.c_str() || *end != '\0' || !std::isfinite(v) || v <= 0) {
      throw std::invalid_argument("option --" + name + " needs comma-separated positive numbers, got '" + s + "'");
    }
    out.push_back(v);
  }
  return out;
}

std::string pct(double share) {
  char buf[16];
  std::snprintf(buf, sizeof(buf), "%6.2f", 100.0 * share);
  return buf;
}
std::string num(double v, const char* fmt = "%10.5g") {
  if (!std::isfinite(v)) return std::string(10 - 3, ' ') + "nan";
  char buf[32];
  std::snprintf(buf, sizeof(buf), fmt, v);
  return buf;
}
std::string threshold_label(double t) {
  std::ostringstream os;
  os << t;
  return os.str();
}

// The folder of depth maps inside an estimate folder: depth_est/ (umvs infer), depth_gt/, depth/, or the folder itself.
std::string find_depth_dir(const std::string& root, const std::string& sub) {
  if (!sub.empty()) {
    const auto p = fs::path(root) / sub;
    if (!fs::is_directory(p)) throw std::runtime_error("no folder " + p.string());
    return p.string();
  }
  if (umvs::InferenceFolder::holds(root)) return umvs::InferenceFolder(root).depth_dir();
  for (const char* s : {"depth_gt", "depth"}) {
    if (fs::is_directory(fs::path(root) / s)) return (fs::path(root) / s).string();
  }
  if (!fs::is_directory(root)) throw std::runtime_error("estimate folder '" + root + "' does not exist");
  return root;
}

// JSON objects keep the order written here; NaN and infinity (metrics without pixels) print as
// null, nlohmann-json's default.
nlohmann::ordered_json depth_json(const umvs::DepthMetrics& m) {
  return {{"gt_pixels", m.gt_pixels}, {"evaluated_pixels", m.evaluated_pixels}, {"completeness", m.completeness()},
          {"mae", m.mae}, {"abs_rel", m.abs_rel}, {"rmse", m.rmse},
          {"within_rel", m.within_rel}, {"within_abs", m.within_abs}};
}

int eval_depth(int argc, char** argv) {
  umvs::Args args("eval depth",
                  "Depth maps of EST against the ground truth of GT (a `umvs synth` folder: depth_gt/*.pfm, cams/).\n"
                  "EST holds depth_est/XXXXXXXX.pfm (umvs infer), depth_gt/ or depth/ (or the .pfm files directly).\n"
                  "An estimate at another resolution (MVSNet's 1/4) is compared at its own pixels: each looks up\n"
                  "the nearest ground-truth pixel through the two cameras (EST/cams/XXXXXXXX_cam.txt, same pose),\n"
                  "i.e. pixel (4i, 4j) for umvs infer output. Errors count pixels where both are valid;\n"
                  "completeness is the share of valid ground-truth pixels that have a valid estimate.\n"
                  "--covisibility-sources N adds rows for the pixels that one of the view's first N neighbours in\n"
                  "GT/pair.txt sees (seen) and for the others (unseen), decided on the ground truth of both views:\n"
                  "where the network had something to match, and where it could only guess.");
  args.required("est", "estimate folder")
      .required("gt", "ground-truth folder (depth_gt/, cams/)")
      .option("est-subdir", "", "subfolder of EST with the depth maps (default: depth_est, depth_gt or depth)")
      .option("min-confidence", "0", "ignore estimates whose EST/confidence/XXXXXXXX.pfm is below this")
      .option("rel-thresholds", "0.01,0.03", "relative error thresholds (comma-separated)")
      .option("abs-thresholds", "0.001,0.003", "absolute error thresholds in scene units (comma-separated)")
      .option("views", "", "comma-separated view ids (default: every estimate)")
      .option("covisibility-sources", "0",
              "split the errors by whether the first N neighbours in GT/pair.txt see the pixel (2 = umvs infer's "
              "default --views 3); 0 = off")
      .option("max-turn-deg", "0",
              "accept estimates whose cameras are turned by up to this many degrees from GT's, as after "
              "`umvs refine-poses`: the images are the same, so depth is compared pixel for pixel (0 = same pose only)")
      .flag("sparsification",
            "also judge the confidence (EST/confidence/): the abs rel of the most confident 10 %, 20 %, ... of the "
            "pixels beside the oracle's (AUSE), and for each --confidence-levels the share of the image at or above "
            "it with its abs rel and share within --confident-within")
      .option("confidence-levels", "0.5,0.8", "confidence floors reported with --sparsification")
      .option("confident-within", "0.1", "relative error counted as right at those floors")
      .flag("json", "print JSON instead of a table");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(0);
  umvs::DepthMetricsConfig cfg;
  cfg.rel_thresholds = parse_reals(args, "rel-thresholds");
  cfg.abs_thresholds = parse_reals(args, "abs-thresholds");
  const std::string est_root = args.str("est"), gt_root = args.str("gt");
  const std::string est_dir = find_depth_dir(est_root, args.str("est-subdir"));
  const double min_conf = args.real("min-confidence");
  const int covisibility_sources = args.integer("covisibility-sources");
  const double max_turn_deg = args.real("max-turn-deg");
  if (!std::isfinite(max_turn_deg) || max_turn_deg < 0) {
    throw std::invalid_argument("--max-turn-deg must be an angle >= 0 in degrees, got " + args.str("max-turn-deg"));
  }
  if (covisibility_sources < 0) throw std::invalid_argument("--covisibility-sources must be >= 0");
  std::vector<umvs::ViewPair> pairs;
  if (covisibility_sources > 0) {
    const std::string pair_path = gt_root + "/pair.txt";
    if (!fs::exists(pair_path)) throw std::runtime_error("--covisibility-sources needs " + pair_path);
    pairs = umvs::read_pair_file(pair_path);
  }
  // The ground truth of view `id` and its camera at the ground truth's own size.
  const auto read_ground_truth = [&](int id) {
    const std::string stem = umvs::view_file_stem(id);
    const std::string depth_path = gt_root + "/depth_gt/" + stem + ".pfm";
    const std::string cam_path = gt_root + "/cams/" + stem + "_cam.txt";
    if (!fs::exists(depth_path)) throw std::runtime_error("no ground truth " + depth_path + " for view " + std::to_string(id));
    umvs::DepthView view{umvs::read_pfm(depth_path), {}};
    if (fs::exists(cam_path)) {
      view.camera = umvs::read_cam_file(cam_path).camera;
      view.camera.width = static_cast<int>(view.depth.size(1));
      view.camera.height = static_cast<int>(view.depth.size(0));
    }
    return view;
  };

  std::vector<int> ids = args.integers("views");
  if (ids.empty()) {
    for (const auto& e : fs::directory_iterator(est_dir)) {
      const auto p = e.path();
      if (p.extension() != ".pfm") continue;
      const std::string stem = p.stem().string();
      if (stem.size() != 8 || stem.find_first_not_of("0123456789") != std::string::npos) continue;
      ids.push_back(std::stoi(stem));
    }
    std::sort(ids.begin(), ids.end());
  }
  if (ids.empty()) throw std::runtime_error("no depth maps XXXXXXXX.pfm in " + est_dir);

  const bool sparsification = args.on("sparsification");
  const std::vector<double> levels = parse_reals(args, "confidence-levels");
  const double confident_within = args.real("confident-within");
  std::vector<torch::Tensor> scored_errors, scored_confidences;  // --sparsification: per evaluated pixel
  std::vector<umvs::ConfidentPixels> confident(levels.size());
  for (size_t i = 0; i < levels.size(); ++i) confident[i].level = levels[i];
  std::vector<umvs::DepthMetrics> per_view, per_view_seen, per_view_unseen;
  for (int id : ids) {
    const std::string stem = umvs::view_file_stem(id);
    const std::string est_path = est_dir + "/" + stem + ".pfm";
    if (!fs::exists(est_path)) throw std::runtime_error("no estimate " + est_path);
    torch::Tensor est = umvs::read_pfm(est_path);
    const umvs::DepthView ground_truth = read_ground_truth(id);
    torch::Tensor gt = ground_truth.depth;
    const std::string est_cam = umvs::InferenceFolder(est_root).cam_path(id);
    const std::string gt_cam = gt_root + "/cams/" + stem + "_cam.txt";
    umvs::Camera gt_camera_at_estimate = ground_truth.camera;  // the camera of `gt` once it has the estimate's size
    if (fs::exists(est_cam) && fs::exists(gt_cam)) {
      auto ce = umvs::read_cam_file(est_cam).camera;
      const auto& cg = ground_truth.camera;
      ce.width = static_cast<int>(est.size(1));
      ce.height = static_cast<int>(est.size(0));
      gt_camera_at_estimate = ce;
      gt_camera_at_estimate.T_cam_world = cg.T_cam_world;  // the same unless --max-turn-deg allows a refined pose
      try {
        gt = umvs::sample_depth_at_camera(gt, cg, ce, max_turn_deg);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("view " + std::to_string(id) + ": " + e.what() + " (" + est_cam + " vs " + gt_cam + ")");
      }
    } else if (est.sizes() != gt.sizes()) {
      throw std::invalid_argument("view " + std::to_string(id) + ": estimate " + std::to_string(est.size(1)) + "x" +
                                  std::to_string(est.size(0)) + " and ground truth " + std::to_string(gt.size(1)) + "x" +
                                  std::to_string(gt.size(0)) + " differ in size and " +
                                  (fs::exists(est_cam) ? gt_cam : est_cam) +
                                  " is missing: both cameras are needed to compare them");
    }
    torch::Tensor valid;
    if (min_conf > 0) {
      const std::string conf_path = umvs::InferenceFolder(est_root).confidence_path(id);
      if (!fs::exists(conf_path)) throw std::runtime_error("--min-confidence given but " + conf_path + " is missing");
      const auto conf = umvs::read_pfm(conf_path);
      if (conf.sizes() != est.sizes()) throw std::runtime_error(conf_path + " does not match the size of its depth map");
      valid = conf >= min_conf;
    }
    per_view.push_back(umvs::evaluate_depth(est, gt, valid, cfg));
    if (sparsification) {
      const std::string conf_path = umvs::InferenceFolder(est_root).confidence_path(id);
      if (!fs::exists(conf_path)) throw std::runtime_error("--sparsification needs the confidence maps, and " + conf_path + " is missing");
      const auto conf = umvs::read_pfm(conf_path);
      if (conf.sizes() != est.sizes()) throw std::runtime_error(conf_path + " does not match the size of its depth map");
      const auto has_estimate = (est > 0) & torch::isfinite(est);
      const auto scored = has_estimate & (gt > 0) & torch::isfinite(gt);
      const auto error = ((est - gt).abs() / gt).masked_select(scored);
      scored_errors.push_back(error);
      scored_confidences.push_back(conf.masked_select(scored));
      for (auto& c : confident) {
        const auto above = conf >= c.level;
        c.pixels += est.numel();
        c.confident += (above & has_estimate).sum().item<int64_t>();
        const auto e = error.masked_select(conf.masked_select(scored) >= c.level);
        c.scored += e.numel();
        c.abs_rel += e.sum().item<double>();                           // a sum until the end
        c.within += (e <= confident_within).sum().item<double>();      // a count until the end
      }
    }
    if (covisibility_sources > 0) {
      if (ground_truth.camera.width == 0) throw std::runtime_error("--covisibility-sources needs the camera " + gt_cam);
      const auto pair = std::find_if(pairs.begin(), pairs.end(), [id](const umvs::ViewPair& p) { return p.ref == id; });
      if (pair == pairs.end()) throw std::runtime_error("view " + std::to_string(id) + " has no line in " + gt_root + "/pair.txt");
      std::vector<umvs::DepthView> sources;
      for (size_t i = 0; i < pair->sources.size() && static_cast<int>(i) < covisibility_sources; ++i) {
        sources.push_back(read_ground_truth(pair->sources[i]));
        if (sources.back().camera.width == 0) {
          throw std::runtime_error("--covisibility-sources needs the camera of view " + std::to_string(pair->sources[i]));
        }
      }
      const auto seen = umvs::covisible_by_ground_truth(gt, gt_camera_at_estimate, sources);
      per_view_seen.push_back(umvs::evaluate_depth(est, gt.where(seen, torch::zeros_like(gt)), valid, cfg));
      per_view_unseen.push_back(umvs::evaluate_depth(est, gt.where(~seen, torch::zeros_like(gt)), valid, cfg));
    }
  }
  const umvs::DepthMetrics all = umvs::combine_depth_metrics(per_view);
  const bool split = covisibility_sources > 0;
  const umvs::DepthMetrics seen = split ? umvs::combine_depth_metrics(per_view_seen) : umvs::DepthMetrics{};
  const umvs::DepthMetrics unseen = split ? umvs::combine_depth_metrics(per_view_unseen) : umvs::DepthMetrics{};
  // Share of the ground-truth pixels that a source sees.
  const auto seen_share = [](const umvs::DepthMetrics& s, const umvs::DepthMetrics& u) {
    return s.gt_pixels + u.gt_pixels > 0 ? static_cast<double>(s.gt_pixels) / (s.gt_pixels + u.gt_pixels) : 0.0;
  };

  umvs::Sparsification curve;
  if (sparsification) {
    for (auto& c : confident) {
      c.abs_rel = c.scored > 0 ? c.abs_rel / c.scored : std::nan("");
      c.within = c.scored > 0 ? c.within / c.scored : std::nan("");
    }
    curve = umvs::sparsification_curve(torch::cat(scored_errors), torch::cat(scored_confidences));
  }

  if (args.on("json")) {
    nlohmann::ordered_json out = {{"rel_thresholds", cfg.rel_thresholds}, {"abs_thresholds", cfg.abs_thresholds}};
    if (sparsification) {
      out["sparsification"] = {{"kept", curve.kept}, {"abs_rel", curve.abs_rel}, {"oracle", curve.oracle}, {"ause", curve.ause}};
      out["confident"] = nlohmann::ordered_json::array();
      for (const auto& c : confident) {
        out["confident"].push_back({{"level", c.level}, {"image_share", c.image_share()}, {"scored_pixels", c.scored},
                                    {"abs_rel", c.abs_rel}, {"within", c.within}, {"within_rel", confident_within}});
      }
    }
    out["views"] = nlohmann::ordered_json::array();
    for (size_t i = 0; i < ids.size(); ++i) {
      nlohmann::ordered_json view = {{"view", ids[i]}};
      view.update(depth_json(per_view[i]));
      if (split) {
        view["seen_share"] = seen_share(per_view_seen[i], per_view_unseen[i]);
        view["seen"] = depth_json(per_view_seen[i]);
        view["unseen"] = depth_json(per_view_unseen[i]);
      }
      out["views"].push_back(view);
    }
    out["overall"] = depth_json(all);
    if (split) {
      out["covisibility_sources"] = covisibility_sources;
      out["overall"]["seen_share"] = seen_share(seen, unseen);
      out["seen"] = depth_json(seen);
      out["unseen"] = depth_json(unseen);
    }
    std::cout << out.dump(1) << "\n";
    return 0;
  }
  std::ostringstream head;
  head << "    view        MAE    abs rel";
  for (double t : cfg.rel_thresholds) head << std::string(std::max<int>(1, 8 - 2 - static_cast<int>(threshold_label(100 * t).size())), ' ') << "<" << threshold_label(100 * t) << "%";
  for (double t : cfg.abs_thresholds) head << "  <" << threshold_label(t);
  head << "  complete%";
  std::cout << "depth: " << est_dir << " vs " << gt_root << "/depth_gt (shares in % of evaluated pixels)\n" << head.str() << "\n";
  auto row = [&](const std::string& name, const umvs::DepthMetrics& m) {
    std::printf("%8s %10s %10s", name.c_str(), num(m.mae).c_str(), num(m.abs_rel).c_str());
    for (size_t i = 0; i < m.within_rel.size(); ++i) {
      const int w = static_cast<int>(threshold_label(100 * cfg.rel_thresholds[i]).size()) + 4;
      std::printf("%*s", std::max(w, 8), pct(m.within_rel[i]).c_str());
    }
    for (size_t i = 0; i < m.within_abs.size(); ++i) {
      const int w = static_cast<int>(threshold_label(cfg.abs_thresholds[i]).size()) + 3;
      std::printf("%*s", std::max(w, 7), pct(m.within_abs[i]).c_str());
    }
    std::printf("  %9s\n", pct(m.completeness()).c_str());
  };
  for (size_t i = 0; i < ids.size(); ++i) row(std::to_string(ids[i]), per_view[i]);
  row("overall", all);
  if (split) {
    row("seen", seen);
    row("unseen", unseen);
    std::printf("seen: %s %% of the ground-truth pixels lie in one of the first %d neighbours' views, unhidden\n",
                pct(seen_share(seen, unseen)).c_str(), covisibility_sources);
  }
  if (sparsification) {
    std::printf("\nsparsification (abs rel of the most confident share of the evaluated pixels; oracle: of least error)\n");
    std::printf("    kept%%  abs rel   oracle\n");
    for (size_t i = 0; i < curve.kept.size(); ++i) {
      std::printf("  %6.0f  %7.4f  %7.4f\n", 100 * curve.kept[i], curve.abs_rel[i], curve.oracle[i]);
    }
    std::printf("AUSE %.4f\n\n", curve.ause);
    std::printf("confidence >=   image%%   abs rel   within %g%%\n", 100 * confident_within);
    for (const auto& c : confident) {
      std::printf("%13g  %7s  %8s  %10s\n", c.level, pct(c.image_share()).c_str(), num(c.abs_rel, "%8.4f").c_str(), pct(c.within).c_str());
    }
  }
  return 0;
}

// The points of every view's sensor depth in an imported RGB-D folder, thinned to `spacing`.
umvs::PointCloud sensor_depth_cloud(const std::string& folder, std::vector<int> ids, int stride, double spacing) {
  if (stride < 1) throw std::invalid_argument("--gt-stride must be >= 1");
  if (!(spacing >= 0) || !std::isfinite(spacing)) throw std::invalid_argument("--gt-spacing must be >= 0");
  const std::string depth_dir = folder + "/depth_gt";
  if (!fs::is_directory(depth_dir)) throw std::runtime_error("--gt-depth: " + folder + " has no depth_gt/ (import an RGB-D set with umvs import)");
  if (ids.empty()) {
    for (const auto& e : fs::directory_iterator(depth_dir)) {
      const std::string stem = e.path().stem().string();
      if (e.path().extension() == ".pfm" && stem.size() == 8 && stem.find_first_not_of("0123456789") == std::string::npos) {
        ids.push_back(std::stoi(stem));
      }
    }
    std::sort(ids.begin(), ids.end());
  }
  if (ids.empty()) throw std::runtime_error("--gt-depth: no XXXXXXXX.pfm in " + depth_dir);
  umvs::PointCloud cloud;
  for (int id : ids) {
    const std::string stem = umvs::view_file_stem(id);
    const std::string depth_path = depth_dir + "/" + stem + ".pfm";
    if (!fs::exists(depth_path)) throw std::runtime_error("--gt-depth: view " + std::to_string(id) + " has no " + depth_path);
    const auto depth = umvs::read_pfm(depth_path);
    umvs::Camera camera = umvs::read_cam_file(folder + "/cams/" + stem + "_cam.txt").camera;
    camera.width = static_cast<int>(depth.size(1));
    camera.height = static_cast<int>(depth.size(0));
    cloud.append(umvs::depth_map_points(depth, camera, stride));
    // Thin as we go, so that hundreds of views never hold all their points at once.
    if (spacing > 0 && cloud.size() > 4000000) cloud = umvs::downsample_min_spacing(cloud, spacing);
  }
  return spacing > 0 ? umvs::downsample_min_spacing(cloud, spacing) : cloud;
}

int eval_cloud(int argc, char** argv) {
  umvs::Args args("eval cloud",
                  "DTU-style accuracy (EST -> GT nearest-neighbour distance) and completeness (GT -> EST), mean and\n"
                  "median, distances above --max-dist left out as outliers; overall = mean of the two means.\n"
                  "Tanks-and-Temples precision, recall and F-score at each --thresholds distance. Distances in scene units.\n"
                  "The ground truth is a cloud (--gt) or an RGB-D set's sensor depth (--gt-depth: umvs import's folder);\n"
                  "for a robot's log, e.g. --gt-depth DATA --thresholds 0.02,0.05,0.1 (metres).");
  args.required("est", "estimated cloud (.ply or .pcd)")
      .option("gt", "", "ground-truth cloud (.ply or .pcd), e.g. gt.ply of a `umvs synth` folder")
      .option("gt-depth", "",
              "or: a folder of sensor depth (depth_gt/, cams/: `umvs import` of an RGB-D set), back-projected as the "
              "ground truth")
      .option("gt-views", "", "with --gt-depth: comma-separated view ids (default: every view)")
      .option("gt-stride", "2", "with --gt-depth: every N-th pixel each way")
      .option("gt-spacing", "0.01", "with --gt-depth: the reference thinned to this spacing (scene units; 0 = no)")
      .option("max-dist", "0", "outlier cap: distances above it are left out of the means (DTU: 0.02 m); 0 = none")
      .option("thresholds", "0.002,0.005,0.01", "precision/recall thresholds (comma-separated)")
      .option("downsample", "0", "first reduce both clouds to this minimum spacing (DTU: 0.0002 m); 0 = no")
      .flag("json", "print JSON instead of a table");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(0);
  umvs::CloudMetricsConfig cfg;
  cfg.max_distance = args.real("max-dist");
  cfg.thresholds = parse_reals(args, "thresholds");
  cfg.downsample_spacing = args.real("downsample");
  if (args.given("gt") == args.given("gt-depth")) throw std::invalid_argument("give one of --gt CLOUD and --gt-depth FOLDER");
  const auto est = umvs::read_cloud(args.str("est"));
  const auto gt = args.given("gt") ? umvs::read_cloud(args.str("gt"))
                                   : sensor_depth_cloud(args.str("gt-depth"), args.integers("gt-views"), args.integer("gt-stride"),
                                                        args.real("gt-spacing"));
  if (est.empty()) throw std::runtime_error("estimated cloud " + args.str("est") + " has no points: nothing to evaluate");
  if (gt.empty()) throw std::runtime_error("ground-truth cloud " + args.str("gt") + " has no points");
  const umvs::CloudMetrics m = umvs::evaluate_cloud(est, gt, cfg);
  if (args.on("json")) {
    const nlohmann::ordered_json out = {
        {"est_points", m.est_points}, {"gt_points", m.gt_points}, {"accuracy_mean", m.accuracy_mean},
        {"accuracy_median", m.accuracy_median}, {"completeness_mean", m.completeness_mean},
        {"completeness_median", m.completeness_median}, {"overall", m.overall},
        {"accuracy_outliers", m.accuracy_outliers}, {"completeness_outliers", m.completeness_outliers},
        {"thresholds", m.thresholds}, {"precision", m.precision}, {"recall", m.recall},
        {"fscore", m.fscore}};
    std::cout << out.dump(1) << "\n";
    return 0;
  }
  std::cout << "cloud: " << args.str("est") << " (" << m.est_points << " points) vs "
            << (args.given("gt") ? args.str("gt") : "sensor depth of " + args.str("gt-depth")) << " ("
            << m.gt_points << " points)" << (cfg.downsample_spacing > 0 ? ", after downsampling" : "") << "\n";
  std::printf("              mean      median   outliers%%\n");
  std::printf("accuracy  %10s  %10s   %7s\n", num(m.accuracy_mean).c_str(), num(m.accuracy_median).c_str(), pct(m.accuracy_outliers).c_str());
  std::printf("complete  %10s  %10s   %7s\n", num(m.completeness_mean).c_str(), num(m.completeness_median).c_str(), pct(m.completeness_outliers).c_str());
  std::printf("overall   %10s\n", num(m.overall).c_str());
  std::printf("\n threshold  precision%%  recall%%  F-score%%\n");
  for (size_t i = 0; i < m.thresholds.size(); ++i) {
    std::printf("%10s  %10s  %7s  %8s\n", num(m.thresholds[i], "%.4g").c_str(), pct(m.precision[i]).c_str(), pct(m.recall[i]).c_str(),
                pct(m.fscore[i]).c_str());
  }
  return 0;
}

// The trainer node's reload rule (jobs/fine_tune_job.h, decide_reload) on two `umvs train --eval-only`
// results, for scripts that tabulate its verdicts.
int eval_rule(int argc, char** argv) {
  umvs::Args args("eval rule",
                  "The trainer node's reload rule on two evaluations (eval.csv of `umvs train --eval-only`): prints\n"
                  "'reload' or 'keep', then the comparison it made.");
  args.required("served", "eval.csv of the served model")
      .required("candidate", "eval.csv of the adapted model");
  if (!args.parse(argc, argv)) return 0;
  umvs::EvalScores served, candidate;
  for (const auto& [name, scores] : {std::pair{"served", &served}, std::pair{"candidate", &candidate}}) {
    if (!umvs::read_eval_scores(args.str(name), scores)) {
      throw std::invalid_argument("--" + std::string(name) + " " + args.str(name) +
                                  ": no held-out photometric loss and consistency in it (an eval.csv of umvs train --eval-only?)");
    }
  }
  const umvs::ReloadVerdict verdict = umvs::decide_reload(candidate, served);
  std::printf("%s\n%s\n", verdict.reload ? "reload" : "keep", verdict.comparison.c_str());
  return 0;
}

}  // namespace

UMVS_COMMAND(eval, "depth-map (eval depth) and point-cloud (eval cloud) metrics against ground truth") {
  const std::string help = umvs::subcommands_help(
      "umvs eval", "Metrics against ground truth: umvs eval depth --est DIR --gt DIR, umvs eval cloud --est PLY --gt PLY.",
      {{"depth", "depth maps of `umvs infer` against depth_gt/"}, {"cloud", "a fused cloud against a ground-truth cloud"},
       {"rule", "the trainer node's reload rule on two `umvs train --eval-only` results"}});
  if (argc < 1) {
    std::cerr << help;
    return 2;
  }
  const std::string mode = argv[0];
  if (mode == "depth") return eval_depth(argc - 1, argv + 1);
  if (mode == "cloud") return eval_cloud(argc - 1, argv + 1);
  if (mode == "rule") return eval_rule(argc - 1, argv + 1);
  if (mode == "--help" || mode == "-h") {
    std::cout << help;
    return 0;
  }
  throw std::invalid_argument("unknown evaluation '" + mode + "' (expected depth, cloud or rule; see umvs eval --help)");
}
