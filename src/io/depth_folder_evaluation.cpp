// Scoring folders against ground truth (unsup_mvs/io/evaluation.h): the walk over an estimate
// folder's depth maps, and the reference cloud of an RGB-D set's sensor depth.
#include "unsup_mvs/io/evaluation.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

// The folder of depth maps inside an estimate folder: depth_est/ (umvs infer), depth_gt/, depth/,
// or the folder itself.
std::string find_depth_dir(const std::string& root, const std::string& sub) {
  if (!sub.empty()) {
    const auto p = fs::path(root) / sub;
    if (!fs::is_directory(p)) throw std::runtime_error("no folder " + p.string());
    return p.string();
  }
  if (InferenceFolder::holds(root)) return InferenceFolder(root).depth_dir();
  for (const char* s : {"depth_gt", "depth"}) {
    if (fs::is_directory(fs::path(root) / s)) return (fs::path(root) / s).string();
  }
  if (!fs::is_directory(root)) throw std::runtime_error("estimate folder '" + root + "' does not exist");
  return root;
}

// The ids of a folder's XXXXXXXX.pfm files, in order.
std::vector<int> pfm_ids(const std::string& dir) {
  std::vector<int> ids;
  for (const auto& e : fs::directory_iterator(dir)) {
    const auto p = e.path();
    const std::string stem = p.stem().string();
    if (p.extension() == ".pfm" && stem.size() == 8 && stem.find_first_not_of("0123456789") == std::string::npos) {
      ids.push_back(std::stoi(stem));
    }
  }
  std::sort(ids.begin(), ids.end());
  return ids;
}

// The ground truth of view `id` and its camera at the ground truth's own size (width 0 without a cam file).
DepthView read_ground_truth(const std::string& gt_root, int id) {
  const std::string stem = view_file_stem(id);
  const std::string depth_path = gt_root + "/depth_gt/" + stem + ".pfm";
  const std::string cam_path = gt_root + "/cams/" + stem + "_cam.txt";
  if (!fs::exists(depth_path)) throw std::runtime_error("no ground truth " + depth_path + " for view " + std::to_string(id));
  DepthView view{read_pfm(depth_path), {}};
  if (fs::exists(cam_path)) {
    view.camera = read_cam_file(cam_path).camera;
    view.camera.width = static_cast<int>(view.depth.size(1));
    view.camera.height = static_cast<int>(view.depth.size(0));
  }
  return view;
}

// The confidence map of view `id`, of the depth map's size; `why` names the option that needs it.
torch::Tensor read_confidence(const std::string& est_root, int id, const torch::Tensor& est, const std::string& why) {
  const std::string path = InferenceFolder(est_root).confidence_path(id);
  if (!fs::exists(path)) throw std::runtime_error(why + " and " + path + " is missing");
  const auto conf = read_pfm(path);
  if (conf.sizes() != est.sizes()) throw std::runtime_error(path + " does not match the size of its depth map");
  return conf;
}

// Adds one view's pixels to the confidence judgement (sums and counts until finish_confidence).
void score_confidence(const torch::Tensor& est, const torch::Tensor& gt, const torch::Tensor& conf,
                      double confident_within, std::vector<torch::Tensor>& errors,
                      std::vector<torch::Tensor>& confidences, std::vector<ConfidentPixels>& confident) {
  const auto has_estimate = (est > 0) & torch::isfinite(est);
  const auto scored = has_estimate & (gt > 0) & torch::isfinite(gt);
  const auto error = ((est - gt).abs() / gt).masked_select(scored);
  errors.push_back(error);
  confidences.push_back(conf.masked_select(scored));
  for (auto& c : confident) {
    c.pixels += est.numel();
    c.confident += ((conf >= c.level) & has_estimate).sum().item<int64_t>();
    const auto e = error.masked_select(confidences.back() >= c.level);
    c.scored += e.numel();
    c.abs_rel += e.sum().item<double>();
    c.within += (e <= confident_within).sum().item<double>();
  }
}

}  // namespace

void DepthFolderEvalOptions::validate() const {
  if (!std::isfinite(max_turn_deg) || max_turn_deg < 0) {
    throw std::invalid_argument("--max-turn-deg must be an angle >= 0 in degrees, got " + std::to_string(max_turn_deg));
  }
  if (covisibility_sources < 0) throw std::invalid_argument("--covisibility-sources must be >= 0");
  if (!std::isfinite(min_confidence)) throw std::invalid_argument("--min-confidence must be a number");
  if (!(confident_within > 0)) throw std::invalid_argument("--confident-within must be > 0");
  for (double level : confidence_levels) {
    if (!(level > 0) || !std::isfinite(level)) throw std::invalid_argument("--confidence-levels must be positive numbers");
  }
}

double seen_share(const DepthMetrics& seen, const DepthMetrics& unseen) {
  const auto all = seen.gt_pixels + unseen.gt_pixels;
  return all > 0 ? static_cast<double>(seen.gt_pixels) / all : 0.0;
}

DepthFolderEvaluation evaluate_depth_folder(const std::string& est_root, const std::string& gt_root,
                                            const DepthFolderEvalOptions& options) {
  options.validate();
  DepthFolderEvaluation out;
  out.est_dir = find_depth_dir(est_root, options.est_subdir);
  out.views = options.views.empty() ? pfm_ids(out.est_dir) : options.views;
  if (out.views.empty()) throw std::runtime_error("no depth maps XXXXXXXX.pfm in " + out.est_dir);
  std::vector<ViewPair> pairs;
  if (options.covisibility_sources > 0) {
    const std::string pair_path = gt_root + "/pair.txt";
    if (!fs::exists(pair_path)) throw std::runtime_error("--covisibility-sources needs " + pair_path);
    pairs = read_pair_file(pair_path);
  }
  std::vector<torch::Tensor> scored_errors, scored_confidences;
  if (options.sparsification) {
    for (double level : options.confidence_levels) out.confident.push_back(ConfidentPixels{level});
  }
  const InferenceFolder estimates(est_root);
  for (int id : out.views) {
    const std::string stem = view_file_stem(id);
    const std::string est_path = out.est_dir + "/" + stem + ".pfm";
    if (!fs::exists(est_path)) throw std::runtime_error("no estimate " + est_path);
    const torch::Tensor est = read_pfm(est_path);
    const DepthView ground_truth = read_ground_truth(gt_root, id);
    torch::Tensor gt = ground_truth.depth;
    const std::string est_cam = estimates.cam_path(id);
    const std::string gt_cam = gt_root + "/cams/" + stem + "_cam.txt";
    Camera gt_camera_at_estimate = ground_truth.camera;  // the camera of `gt` once it has the estimate's size
    if (fs::exists(est_cam) && fs::exists(gt_cam)) {
      auto ce = read_cam_file(est_cam).camera;
      const auto& cg = ground_truth.camera;
      ce.width = static_cast<int>(est.size(1));
      ce.height = static_cast<int>(est.size(0));
      gt_camera_at_estimate = ce;
      gt_camera_at_estimate.T_cam_world = cg.T_cam_world;  // the same unless max_turn_deg allows a refined pose
      try {
        gt = sample_depth_at_camera(gt, cg, ce, options.max_turn_deg);
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
    if (options.min_confidence > 0) {
      valid = read_confidence(est_root, id, est, "--min-confidence given but") >= options.min_confidence;
    }
    out.per_view.push_back(evaluate_depth(est, gt, valid, options.metrics));
    if (options.sparsification) {
      const auto conf = read_confidence(est_root, id, est, "--sparsification needs the confidence maps,");
      score_confidence(est, gt, conf, options.confident_within, scored_errors, scored_confidences, out.confident);
    }
    if (options.covisibility_sources > 0) {
      if (ground_truth.camera.width == 0) throw std::runtime_error("--covisibility-sources needs the camera " + gt_cam);
      const auto pair = std::find_if(pairs.begin(), pairs.end(), [id](const ViewPair& p) { return p.ref == id; });
      if (pair == pairs.end()) throw std::runtime_error("view " + std::to_string(id) + " has no line in " + gt_root + "/pair.txt");
      std::vector<DepthView> sources;
      for (size_t i = 0; i < pair->sources.size() && static_cast<int>(i) < options.covisibility_sources; ++i) {
        sources.push_back(read_ground_truth(gt_root, pair->sources[i]));
        if (sources.back().camera.width == 0) {
          throw std::runtime_error("--covisibility-sources needs the camera of view " + std::to_string(pair->sources[i]));
        }
      }
      const auto seen = covisible_by_ground_truth(gt, gt_camera_at_estimate, sources);
      out.per_view_seen.push_back(evaluate_depth(est, gt.where(seen, torch::zeros_like(gt)), valid, options.metrics));
      out.per_view_unseen.push_back(evaluate_depth(est, gt.where(~seen, torch::zeros_like(gt)), valid, options.metrics));
    }
  }
  out.overall = combine_depth_metrics(out.per_view);
  if (out.split()) {
    out.seen = combine_depth_metrics(out.per_view_seen);
    out.unseen = combine_depth_metrics(out.per_view_unseen);
  }
  if (options.sparsification) {
    for (auto& c : out.confident) {
      c.abs_rel = c.scored > 0 ? c.abs_rel / c.scored : std::nan("");
      c.within = c.scored > 0 ? c.within / c.scored : std::nan("");
    }
    out.curve = sparsification_curve(torch::cat(scored_errors), torch::cat(scored_confidences));
  }
  return out;
}

PointCloud sensor_depth_cloud(const std::string& folder, std::vector<int> views, int stride, double spacing) {
  if (stride < 1) throw std::invalid_argument("--gt-stride must be >= 1");
  if (!(spacing >= 0) || !std::isfinite(spacing)) throw std::invalid_argument("--gt-spacing must be >= 0");
  const std::string depth_dir = folder + "/depth_gt";
  if (!fs::is_directory(depth_dir)) {
    throw std::runtime_error("--gt-depth: " + folder + " has no depth_gt/ (import an RGB-D set with umvs import)");
  }
  if (views.empty()) views = pfm_ids(depth_dir);
  if (views.empty()) throw std::runtime_error("--gt-depth: no XXXXXXXX.pfm in " + depth_dir);
  PointCloud cloud;
  for (int id : views) {
    const std::string stem = view_file_stem(id);
    const std::string depth_path = depth_dir + "/" + stem + ".pfm";
    if (!fs::exists(depth_path)) throw std::runtime_error("--gt-depth: view " + std::to_string(id) + " has no " + depth_path);
    const auto depth = read_pfm(depth_path);
    Camera camera = read_cam_file(folder + "/cams/" + stem + "_cam.txt").camera;
    camera.width = static_cast<int>(depth.size(1));
    camera.height = static_cast<int>(depth.size(0));
    cloud.append(depth_map_points(depth, camera, stride));
    // Thin as we go, so that hundreds of views never hold all their points at once.
    if (spacing > 0 && cloud.size() > 4000000) cloud = downsample_min_spacing(cloud, spacing);
  }
  return spacing > 0 ? downsample_min_spacing(cloud, spacing) : cloud;
}

}  // namespace umvs
