// Folder inference (unsup_mvs/jobs/folder_inference.h): what `umvs infer` does.
#include "unsup_mvs/jobs/folder_inference.h"

#include <torch/torch.h>

#include <cmath>
#include <cstdio>
#include <map>
#include <ostream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/core/memory_bounds.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/plane_count.h"

namespace umvs {

namespace {

std::string as_text(double v) {
  std::ostringstream s;
  s << v;
  return s.str();
}

// The rotation search's verdict on each source, for the log.
void log_source_turns(std::ostream& log, int ref, const DepthMap& map, const ViewPair& pair) {
  log << "\nview " << ref << ", rotation search (turns kept when the warp is " << 100.0 * kMinSourceTurnGain
      << " % better, also at full size):";
  for (size_t s = 0; s < map.source_turns.size(); ++s) {
    const SourceTurn& turn = map.source_turns[s];
    char text[160];
    std::snprintf(text, sizeof(text), "\n  source %d: %s (%.1f, %.1f, %.1f) degrees about x, y, z; warp %.1f %% better",
                  pair.sources[s], turn.kept ? "turned by" : "not turned; best turn", turn.degrees.x(), turn.degrees.y(),
                  turn.degrees.z(), 100.0 * turn.search_gain);
    log << text;
    if (turn.full_size_gain != 0.0) {
      std::snprintf(text, sizeof(text), ", at full size %.1f %%", 100.0 * turn.full_size_gain);
      log << text;
    }
  }
  log << "\n";
}

// The one-line summary of a written map.
std::string summary(int ref, const DepthMap& map, const DepthEstimatorConfig& cfg) {
  char line[200];
  int used = std::snprintf(line, sizeof(line), "view %d: %.2f s, conf>0.8 %.1f%%", ref, map.seconds,
                           100.0 * (map.confidence > 0.8).to(torch::kFloat32).mean().item<double>());
  if (map.per_source_passes && cfg.source_combination == SourceCombination::kAuto && used > 0 &&
      used < static_cast<int>(sizeof(line))) {
    used += std::snprintf(line + used, sizeof(line) - used, ", sources also alone");
  }
  if (cfg.completion.enabled() && used > 0 && used < static_cast<int>(sizeof(line))) {
    std::snprintf(line + used, sizeof(line) - used, ", completed %.1f%% in %.2f s%s", 100.0 * map.completion.completed_share,
                  map.completion_seconds, map.completion.converged ? "" : " (not converged)");
  }
  return line;
}

void write_map(const InferenceFolder& written, int ref, const DepthMap& map, double dmin, double dmax, int num_depth,
               bool completed) {
  write_pfm(written.depth_path(ref), map.depth);
  write_pfm(written.confidence_path(ref), map.confidence);
  // The preview hides unsure pixels, unless they were completed.
  const auto shown = completed ? map.depth > 0 : map.confidence > 0.5;
  write_png(written.depth_preview_path(ref), colorize(map.depth, dmin, dmax, shown));
  write_png(written.confidence_preview_path(ref), map.confidence.mul(255).round().clamp(0, 255).to(torch::kUInt8));
  write_png(written.image_path(ref), map.color);
  MvsCam out_cam;
  out_cam.camera = map.camera;
  out_cam.depth_min = dmin;
  out_cam.depth_interval = (dmax - dmin) / (num_depth - 1);
  out_cam.depth_num = num_depth;
  out_cam.depth_max = dmax;
  write_cam_file(written.cam_path(ref), out_cam);
}

}  // namespace

void FolderInferenceOptions::validate() const {
  if (views < 2) throw std::invalid_argument("--views must be at least 2");
  for (const auto& [name, v] : {std::pair{"depth-min", depth_min}, std::pair{"depth-max", depth_max}}) {
    if (!std::isfinite(v) || v < 0) {
      throw std::invalid_argument(std::string("--") + name + " must be a depth > 0 (or 0: from the cam file), got " + as_text(v));
    }
  }
  if (depth_min > 0 && depth_max > 0 && depth_max <= depth_min) {
    throw std::invalid_argument("impossible depth range: --depth-max " + as_text(depth_max) + " <= --depth-min " + as_text(depth_min));
  }
  const double floor = estimator.completion.min_confidence;
  if (!(floor >= 0 && floor < 1)) {
    throw std::invalid_argument("--complete-below-confidence must be a confidence in [0,1) (0 = off), got " + as_text(floor));
  }
  const double search = estimator.source_rotation_search_deg;
  if (!std::isfinite(search) || search < 0) {
    throw std::invalid_argument("--source-rotation-search must be an angle >= 0 in degrees (0 = off), got " + as_text(search));
  }
}

FolderInferenceResult infer_folder(const std::string& data_dir, const std::string& checkpoint, const torch::Device& device,
                                   const std::string& out_dir, const FolderInferenceOptions& options, std::ostream& log,
                                   const FolderInferenceProgress& progress) {
  options.validate();
  MvsFolder folder(data_dir);
  std::vector<int> refs = options.refs;
  std::set<int> in_pairs;
  for (const auto& p : folder.pairs()) in_pairs.insert(p.ref);
  for (int ref : refs) {
    if (!in_pairs.count(ref)) {
      throw std::invalid_argument("--ref: view " + std::to_string(ref) + " is not in " + data_dir + "/pair.txt (it lists " +
                                  std::to_string(in_pairs.size()) + " reference views)");
    }
  }
  if (refs.empty()) {
    for (const auto& p : folder.pairs()) refs.push_back(p.ref);
  }
  const DepthSampling sampling = options.depth_sampling.empty() ? DepthSampling{} : depth_sampling_from_string(options.depth_sampling);
  const FeatureWarp warp = options.feature_warp.empty() ? FeatureWarp{} : feature_warp_from_string(options.feature_warp);
  LoadedModel model = load_model(checkpoint, device);
  if (!options.depth_sampling.empty()) model.model->set_depth_sampling(sampling);
  if (!options.feature_warp.empty()) model.model->set_feature_warp(warp);
  log << "model: " << checkpoint << " (" << model.format << ", " << model.model->config().to_string() << "), device "
      << device << ", " << torch::get_num_threads() << " threads\n";
  std::map<int, MvsView> cache;
  auto view = [&](int id) -> const MvsView& {
    auto it = cache.find(id);
    if (it == cache.end()) it = cache.emplace(id, folder.load_view(id)).first;
    return it->second;
  };
  // The plane count follows the network input of the first reference (as MVSNet's 640x512 ->
  // 128), not the checkpoint; that input must fit in memory before anything is written.
  DepthEstimatorConfig cfg = options.estimator;
  NetworkResize plan{};
  plan.width = 640;
  plan.height = 512;
  if (!refs.empty()) {
    const auto& first = view(refs.front()).cam.camera;
    plan = plan_network_resize(first.width, first.height, cfg.max_width, cfg.max_height);
  }
  const auto& net = model.model->config();
  const PlaneCount planes = choose_plane_count(options.num_depth, "--num-depth", first_pass_size(cfg, plan.width),
                                               first_pass_size(cfg, plan.height), net.num_depth, net.planes_fixed_by_weights());
  cfg.num_depth = planes.planes;
  DepthEstimator estimator(model.model, device, cfg);  // refuses a bad source_rotation_search_deg
  FolderInferenceResult result;
  result.num_depth = estimator.num_depth();
  result.planes_why = planes.why;
  log << "depth planes: " << planes.why << "\n";
  if (!refs.empty()) check_inference_memory(plan.width, plan.height, estimator.num_depth(), options.views);
  const InferenceFolder written(out_dir);
  written.create();

  std::vector<ViewPair> out_pairs;
  bool range_reported = false;  // which range is used, said once when options override the cam files
  const bool overridden = options.depth_min > 0 || options.depth_max > 0;
  for (int ref : refs) {
    const auto& pair = folder.pair_of(ref);
    if (static_cast<int>(pair.sources.size()) < options.views - 1) {
      log << "\nview " << ref << ": only " << pair.sources.size() << " neighbours in pair.txt, need " << options.views - 1
          << "; skipped\n";
      ++result.skipped;
      if (progress) progress(result.done + result.skipped, static_cast<int>(refs.size()), "");
      continue;
    }
    std::vector<ViewInput> inputs;
    inputs.push_back({view(ref).image, view(ref).cam.camera});
    for (int i = 0; i < options.views - 1; ++i) inputs.push_back({view(pair.sources[i]).image, view(pair.sources[i]).cam.camera});
    const auto& cam = view(ref).cam;
    const double dmin = options.depth_min > 0 ? options.depth_min : cam.depth_min;
    const double dmax = options.depth_max > 0 ? options.depth_max : cam.resolved_depth_max(estimator.num_depth());
    const std::string near_from = options.depth_min > 0 ? "--depth-min" : "its cam file";
    const std::string far_from = options.depth_max > 0 ? "--depth-max" : "its cam file";
    if (dmin <= 0) throw std::invalid_argument("view " + std::to_string(ref) + ": no depth range in its cam file; give --depth-min/--depth-max");
    if (!(dmax > dmin)) {
      throw std::invalid_argument("view " + std::to_string(ref) + ": impossible depth range " + std::to_string(dmin) +
                                  " (from " + near_from + ") .. " + std::to_string(dmax) + " (from " + far_from + ")");
    }
    if (!range_reported && overridden) {
      range_reported = true;
      log << "depth range of view " << ref << ": " << dmin << " (from " << near_from << ") .. " << dmax << " (from "
          << far_from << ")";
      if (cam.depth_min > 0) log << "; its cam file gives " << cam.depth_min << " .. " << cam.resolved_depth_max(estimator.num_depth());
      log << "\n";
    }
    const DepthMap map = estimator.estimate(inputs, dmin, dmax);
    result.network_seconds += map.seconds;
    if (!map.source_turns.empty()) log_source_turns(log, ref, map, pair);
    write_map(written, ref, map, dmin, dmax, estimator.num_depth(), cfg.completion.enabled());
    out_pairs.push_back(pair);
    ++result.done;
    if (progress) progress(result.done + result.skipped, static_cast<int>(refs.size()), summary(ref, map, cfg));
  }
  write_pair_file(written.pair_file(), out_pairs);
  return result;
}

}  // namespace umvs
