// umvs infer: depth and confidence maps for the views of an MVSNet-format folder.
#include <torch/torch.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <set>
#include <sstream>

#include "unsup_mvs/core/depth_completion.h"
#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/core/memory_bounds.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"
#include "unsup_mvs/tools/progress.h"

namespace fs = std::filesystem;

namespace {

// --depth-min/--depth-max: > 0 overrides the cam file, 0 keeps it; anything else is refused.
double depth_override(const umvs::Args& args, const char* name) {
  const double v = args.real(name);
  if (!std::isfinite(v) || v < 0) {
    throw std::invalid_argument(std::string("--") + name + " must be a depth > 0 (or 0: from the cam file), got " +
                                args.str(name));
  }
  return v;
}

// The default of --complete-below-confidence as help shows it ("0.7").
std::string recommended_completion_floor() {
  std::ostringstream text;
  text << umvs::kRecommendedCompletionConfidence;
  return text.str();
}

}  // namespace

UMVS_COMMAND(infer, "depth + confidence maps for an MVSNet-format folder") {
  umvs::Args args("infer",
                  "Runs MVSNet on every reference view of DIR (or those given by --ref) with its best\n"
                  "neighbours from pair.txt. Writes, per view XXXXXXXX:\n"
                  "  OUT/depth_est/XXXXXXXX.pfm (+ .png preview)   depth in scene units, 1/4 of the network input\n"
                  "  OUT/confidence/XXXXXXXX.pfm (+ .png)         photometric confidence in [0,1]\n"
                  "  OUT/cams/XXXXXXXX_cam.txt, OUT/images/XXXXXXXX.png  camera and colours of the depth map\n"
                  "and OUT/pair.txt, so OUT is itself a folder `umvs fuse` and `umvs eval` read.");
  args.required("data", "MVSNet-format input folder (images/, cams/, pair.txt)")
      .required("checkpoint", "model: our checkpoint or MVSNet_pytorch weights")
      .required("out", "output folder")
      .option("views", "3", "views per depth map (reference + neighbours)")
      .option("source-combination", umvs::to_string(umvs::kRecommendedSourceCombination),
              "auto: MVSNet's one variance pass over all views, plus most_confident's passes on the maps where that "
              "pass is unsure (confidence >= 0.5 on fewer than 20 % of the pixels: far-apart views whose sources "
              "disagree); variance: that one pass only; most_confident: also one pass per source with the reference "
              "alone on every map, each pixel keeping its most confident estimate (1 + neighbours passes)")
      .option("source-rotation-search", "0",
              "correct each source's orientation by up to this many degrees about each axis: the turn with which "
              "the source warps best onto the reference, kept when clearly better than the pose as given (poses a "
              "few tenths of a degree off; about 30 half-size passes per source; 0 = off)")
      .option("complete-below-confidence", recommended_completion_floor(),
              "replace the depth of pixels below this confidence by what the confident pixels around them imply "
              "(edge-aware, a wall is filled as a plane; dense depth maps where the network has no evidence: plain walls, "
              "parts no source sees; measured in docs/results.md; the confidence maps stay as the network gave them; "
              "0 = off: the network's own depth)")
      .option("min-parallax-px", umvs::DepthEstimatorConfig{}.min_parallax_px,
              "confidence 0 (unknown) where a 10 % change of depth moves the pixel by less than this many pixels in "
              "every source: too little parallax to tell depth (a camera turning in place, a short baseline); 0 = off")
      .option("num-depth", "0", "depth planes (multiple of 8; 0 = 128 at 640 wide, scaled with the width)")
      .option("fine-planes", umvs::DepthEstimatorConfig{}.fine.planes,
              "a second pass with this many hypotheses per pixel around the first pass's depth (coarse to fine; "
              "multiple of 8; --num-depth is then the first pass's planes; 0 = one pass)")
      .option("fine-span", umvs::DepthEstimatorConfig{}.fine.span,
              "the second pass's hypotheses cover this many of the first pass's plane intervals")
      .option("fine-resolution", umvs::DepthEstimatorConfig{}.fine.resolution_divisor,
              "the second pass's resolution, and the depth map's: 1/2 or 1/4 of the network input (2 | 4)")
      .option("first-pass-downscale", umvs::DepthEstimatorConfig{}.fine.first_pass_downscale,
              "with --fine-planes: 2 = the first pass sees the input at half its size (1 = as given)")
      .option("depth-sampling", "", "depth|inverse_depth (default: the checkpoint's)")
      .option("feature-warp", "", "exact|mvsnet_pytorch: where the cost volume samples the source views (default: the checkpoint's)")
      .option("max-width", "0", "scale images down to at most this width (0 = keep)")
      .option("max-height", "0", "scale images down to at most this height (0 = keep)")
      .option("depth-min", "0", "override the near end of the depth range (0 = from the cam file)")
      .option("depth-max", "0", "override the far end of the depth range (0 = from the cam file)")
      .option("ref", "", "comma-separated reference view ids (default: all in pair.txt)")
      .option("device", "cpu", "cpu | cuda | cuda:N")
      .option("threads", 0, "CPU threads (0 = all cores)");
  if (!args.parse(argc, argv)) return 0;

  umvs::configure_threads(args.integer("threads"));
  const auto device = umvs::parse_device(args.str("device"));
  const int views = args.integer("views");
  if (views < 2) throw std::invalid_argument("--views must be at least 2");
  const auto source_combination = umvs::source_combination_from_string(args.str("source-combination"));
  const double depth_min_option = depth_override(args, "depth-min"), depth_max_option = depth_override(args, "depth-max");
  if (depth_min_option > 0 && depth_max_option > 0 && depth_max_option <= depth_min_option) {
    throw std::invalid_argument("impossible depth range: --depth-max " + args.str("depth-max") + " <= --depth-min " +
                                args.str("depth-min"));
  }
  umvs::MvsFolder folder(args.str("data"));
  std::vector<int> refs = args.integers("ref");
  std::set<int> in_pairs;
  for (const auto& p : folder.pairs()) in_pairs.insert(p.ref);
  for (int ref : refs) {
    if (!in_pairs.count(ref)) {
      throw std::invalid_argument("--ref: view " + std::to_string(ref) + " is not in " + args.str("data") +
                                  "/pair.txt (it lists " + std::to_string(in_pairs.size()) + " reference views)");
    }
  }
  if (refs.empty()) {
    for (const auto& p : folder.pairs()) refs.push_back(p.ref);
  }

  auto loaded = umvs::load_model(args.str("checkpoint"), device);
  if (args.given("depth-sampling")) loaded.model->set_depth_sampling(umvs::depth_sampling_from_string(args.str("depth-sampling")));
  if (args.given("feature-warp")) loaded.model->set_feature_warp(umvs::feature_warp_from_string(args.str("feature-warp")));
  umvs::DepthEstimatorConfig cfg;
  cfg.source_combination = source_combination;
  cfg.max_width = args.integer("max-width");
  cfg.max_height = args.integer("max-height");
  cfg.source_rotation_search_deg = args.real("source-rotation-search");
  cfg.completion.min_confidence = args.real("complete-below-confidence");
  cfg.min_parallax_px = args.real("min-parallax-px");
  cfg.fine.planes = args.integer("fine-planes");
  cfg.fine.span = args.real("fine-span");
  cfg.fine.resolution_divisor = args.integer("fine-resolution");
  cfg.fine.first_pass_downscale = args.integer("first-pass-downscale");
  if (!(cfg.completion.min_confidence >= 0 && cfg.completion.min_confidence < 1)) {
    throw std::invalid_argument("--complete-below-confidence must be a confidence in [0,1) (0 = off), got " +
                                args.str("complete-below-confidence"));
  }
  if (!std::isfinite(cfg.source_rotation_search_deg) || cfg.source_rotation_search_deg < 0) {
    throw std::invalid_argument("--source-rotation-search must be an angle >= 0 in degrees (0 = off), got " +
                                args.str("source-rotation-search"));
  }

  std::map<int, umvs::MvsView> cache;
  auto view = [&](int id) -> const umvs::MvsView& {
    auto it = cache.find(id);
    if (it == cache.end()) it = cache.emplace(id, folder.load_view(id)).first;
    return it->second;
  };
  // The plane count follows the network input of the first reference (as MVSNet's 640x512 ->
  // 128), not the checkpoint; that input must fit in memory before anything is written.
  umvs::NetworkResize plan{};
  plan.width = 640;
  plan.height = 512;
  if (!refs.empty()) {
    const auto& first = view(refs.front()).cam.camera;
    plan = umvs::plan_network_resize(first.width, first.height, cfg.max_width, cfg.max_height);
  }
  const umvs::PlaneCount planes = umvs::choose_plane_count(args.integer("num-depth"), "--num-depth",
                                                           umvs::first_pass_size(cfg, plan.width),
                                                           umvs::first_pass_size(cfg, plan.height),
                                                           loaded.model->config().num_depth,
                                                           loaded.model->config().planes_fixed_by_weights());
  cfg.num_depth = planes.planes;
  umvs::DepthEstimator estimator(loaded.model, device, cfg);  // refuses a bad --source-rotation-search
  std::cerr << "model: " << args.str("checkpoint") << " (" << loaded.format << ", " << loaded.model->config().to_string()
            << "), device " << device << ", " << torch::get_num_threads() << " threads\n"
            << "depth planes: " << planes.why << "\n";
  if (!refs.empty()) umvs::check_inference_memory(plan.width, plan.height, estimator.num_depth(), views);
  const std::string out = args.str("out");
  const umvs::InferenceFolder written(out);
  written.create();

  std::vector<umvs::ViewPair> out_pairs;
  umvs::Progress progress("infer", static_cast<int64_t>(refs.size()));
  int done = 0, skipped = 0;
  bool range_reported = false;  // which range is used, said once when options override the cam files
  double total_seconds = 0;
  for (int ref : refs) {
    const auto& pair = folder.pair_of(ref);
    if (static_cast<int>(pair.sources.size()) < views - 1) {
      std::cerr << "\nview " << ref << ": only " << pair.sources.size() << " neighbours in pair.txt, need "
                << views - 1 << "; skipped\n";
      ++skipped;
      continue;
    }
    std::vector<umvs::ViewInput> inputs;
    inputs.push_back({view(ref).image, view(ref).cam.camera});
    for (int i = 0; i < views - 1; ++i) inputs.push_back({view(pair.sources[i]).image, view(pair.sources[i]).cam.camera});
    const auto& cam = view(ref).cam;
    const double dmin = depth_min_option > 0 ? depth_min_option : cam.depth_min;
    const double dmax = depth_max_option > 0 ? depth_max_option : cam.resolved_depth_max(estimator.num_depth());
    const std::string near_from = depth_min_option > 0 ? "--depth-min" : "its cam file";
    const std::string far_from = depth_max_option > 0 ? "--depth-max" : "its cam file";
    if (dmin <= 0) throw std::invalid_argument("view " + std::to_string(ref) + ": no depth range in its cam file; give --depth-min/--depth-max");
    if (!(dmax > dmin)) {
      throw std::invalid_argument("view " + std::to_string(ref) + ": impossible depth range " + std::to_string(dmin) +
                                  " (from " + near_from + ") .. " + std::to_string(dmax) + " (from " + far_from + ")");
    }
    if (!range_reported && (depth_min_option > 0 || depth_max_option > 0)) {
      range_reported = true;
      std::cerr << "depth range of view " << ref << ": " << dmin << " (from " << near_from << ") .. " << dmax << " (from "
                << far_from << ")";
      if (cam.depth_min > 0) {
        std::cerr << "; its cam file gives " << cam.depth_min << " .. " << cam.resolved_depth_max(estimator.num_depth());
      }
      std::cerr << "\n";
    }

    const umvs::DepthMap map = estimator.estimate(inputs, dmin, dmax);
    total_seconds += map.seconds;
    if (!map.source_turns.empty()) {
      std::cerr << "\nview " << ref << ", rotation search (turns kept when the warp is "
                << 100.0 * umvs::kMinSourceTurnGain << " % better, also at full size):";
      for (size_t s = 0; s < map.source_turns.size(); ++s) {
        const umvs::SourceTurn& turn = map.source_turns[s];
        char text[160];
        std::snprintf(text, sizeof(text), "\n  source %d: %s (%.1f, %.1f, %.1f) degrees about x, y, z; warp %.1f %% better",
                      pair.sources[s], turn.kept ? "turned by" : "not turned; best turn", turn.degrees.x(), turn.degrees.y(),
                      turn.degrees.z(), 100.0 * turn.search_gain);
        std::cerr << text;
        if (turn.full_size_gain != 0.0) {
          std::snprintf(text, sizeof(text), ", at full size %.1f %%", 100.0 * turn.full_size_gain);
          std::cerr << text;
        }
      }
      std::cerr << "\n";
    }
    umvs::write_pfm(written.depth_path(ref), map.depth);
    umvs::write_pfm(written.confidence_path(ref), map.confidence);
    // The preview hides unsure pixels, unless they were completed.
    const auto shown = cfg.completion.enabled() ? map.depth > 0 : map.confidence > 0.5;
    umvs::write_png(written.depth_preview_path(ref), umvs::colorize(map.depth, dmin, dmax, shown));
    umvs::write_png(written.confidence_preview_path(ref),
                    map.confidence.mul(255).round().clamp(0, 255).to(torch::kUInt8));
    umvs::write_png(written.image_path(ref), map.color);
    umvs::MvsCam out_cam;
    out_cam.camera = map.camera;
    out_cam.depth_min = dmin;
    out_cam.depth_interval = (dmax - dmin) / (estimator.num_depth() - 1);
    out_cam.depth_num = estimator.num_depth();
    out_cam.depth_max = dmax;
    umvs::write_cam_file(written.cam_path(ref), out_cam);
    out_pairs.push_back(pair);
    ++done;
    char extra[160];
    int used = std::snprintf(extra, sizeof(extra), "view %d: %.2f s, conf>0.8 %.1f%%", ref, map.seconds,
                             100.0 * (map.confidence > 0.8).to(torch::kFloat32).mean().item<double>());
    if (map.per_source_passes && source_combination == umvs::SourceCombination::kAuto && used > 0 &&
        used < static_cast<int>(sizeof(extra))) {
      used += std::snprintf(extra + used, sizeof(extra) - used, ", sources also alone");
    }
    if (cfg.completion.enabled() && used > 0 && used < static_cast<int>(sizeof(extra))) {
      std::snprintf(extra + used, sizeof(extra) - used, ", completed %.1f%% in %.2f s%s",
                    100.0 * map.completion.completed_share, map.completion_seconds,
                    map.completion.converged ? "" : " (not converged)");
    }
    progress.update(done + skipped, extra);
  }
  progress.finish();
  umvs::write_pair_file(written.pair_file(), out_pairs);
  std::cout << "wrote " << done << " depth maps to " << out << " (" << skipped << " skipped), "
            << (done ? total_seconds / done : 0.0) << " s per depth map\n";
  return done > 0 ? 0 : 1;
}
