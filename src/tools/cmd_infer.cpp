// umvs infer: depth and confidence maps for the views of an MVSNet-format folder (jobs/folder_inference.h).
#include <torch/torch.h>

#include <iostream>
#include <memory>

#include "unsup_mvs/core/depth_completion.h"
#include "unsup_mvs/core/device.h"
#include "unsup_mvs/jobs/folder_inference.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"
#include "unsup_mvs/tools/progress.h"

UMVS_COMMAND(infer, "depth + confidence maps for an MVSNet-format folder") {
  umvs::Args args("infer",
                  "Runs MVSNet on every reference view of DIR (or those given by --ref) with its best\n"
                  "neighbours from pair.txt. Writes, per view XXXXXXXX:\n"
                  "  OUT/depth_est/XXXXXXXX.pfm (+ .png preview)   depth in scene units, 1/4 of the network input\n"
                  "  OUT/confidence/XXXXXXXX.pfm (+ .png)         photometric confidence in [0,1]\n"
                  "  OUT/cams/XXXXXXXX_cam.txt, OUT/images/XXXXXXXX.png  camera and colours of the depth map\n"
                  "and OUT/pair.txt, so OUT is itself a folder `umvs fuse` and `umvs eval` read.");
  umvs::FolderInferenceOptions options;
  umvs::DepthEstimatorConfig& cfg = options.estimator;
  std::string source_combination = umvs::to_string(umvs::kRecommendedSourceCombination);
  cfg.completion.min_confidence = umvs::kRecommendedCompletionConfidence;
  args.required("data", "MVSNet-format input folder (images/, cams/, pair.txt)")
      .required("checkpoint", "model: our checkpoint or MVSNet_pytorch weights")
      .required("out", "output folder")
      .bind("views", &options.views, "views per depth map (reference + neighbours)")
      .bind("source-combination", &source_combination,
              "auto: MVSNet's one variance pass over all views, plus most_confident's passes on the maps where that "
              "pass is unsure (confidence >= 0.5 on fewer than 20 % of the pixels: far-apart views whose sources "
              "disagree); variance: that one pass only; most_confident: also one pass per source with the reference "
              "alone on every map, each pixel keeping its most confident estimate (1 + neighbours passes)")
      .bind("source-rotation-search", &cfg.source_rotation_search_deg,
              "correct each source's orientation by up to this many degrees about each axis: the turn with which "
              "the source warps best onto the reference, kept when clearly better than the pose as given (poses a "
              "few tenths of a degree off; about 30 half-size passes per source; 0 = off)")
      .bind("complete-below-confidence", &cfg.completion.min_confidence,
              "replace the depth of pixels below this confidence by what the confident pixels around them imply "
              "(edge-aware, a wall is filled as a plane; dense depth maps where the network has no evidence: plain walls, "
              "parts no source sees; measured in docs/results.md; the confidence maps stay as the network gave them; "
              "0 = off: the network's own depth)")
      .bind("min-parallax-px", &cfg.min_parallax_px,
              "confidence 0 (unknown) where a 10 % change of depth moves the pixel by less than this many pixels in "
              "every source: too little parallax to tell depth (a camera turning in place, a short baseline); 0 = off")
      .bind("num-depth", &options.num_depth, "depth planes (multiple of 8; 0 = 128 at 640 wide, scaled with the width)")
      .bind("fine-planes", &cfg.fine.planes,
              "a second pass with this many hypotheses per pixel around the first pass's depth (coarse to fine; "
              "multiple of 8; --num-depth is then the first pass's planes; 0 = one pass)")
      .bind("fine-span", &cfg.fine.span,
              "the second pass's hypotheses cover this many of the first pass's plane intervals")
      .bind("fine-resolution", &cfg.fine.resolution_divisor,
              "the second pass's resolution, and the depth map's: 1/2 or 1/4 of the network input (2 | 4)")
      .bind("first-pass-downscale", &cfg.fine.first_pass_downscale,
              "with --fine-planes: 2 = the first pass sees the input at half its size (1 = as given)")
      .bind("depth-sampling", &options.depth_sampling, "depth|inverse_depth (default: the checkpoint's)")
      .bind("feature-warp", &options.feature_warp, "exact|mvsnet_pytorch: where the cost volume samples the source views (default: the checkpoint's)")
      .bind("max-width", &cfg.max_width, "scale images down to at most this width (0 = keep)")
      .bind("max-height", &cfg.max_height, "scale images down to at most this height (0 = keep)")
      .bind("depth-min", &options.depth_min, "override the near end of the depth range (0 = from the cam file)")
      .bind("depth-max", &options.depth_max, "override the far end of the depth range (0 = from the cam file)")
      .bind("ref", &options.refs, "comma-separated reference view ids (default: all in pair.txt)")
      .option("device", "cpu", "cpu | cuda | cuda:N")
      .option("threads", 0, "CPU threads (0 = all cores)");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(args.integer("threads"));
  const auto device = umvs::parse_device(args.str("device"));
  cfg.source_combination = umvs::source_combination_from_string(source_combination);
  std::unique_ptr<umvs::Progress> progress;
  const auto result = umvs::infer_folder(args.str("data"), args.str("checkpoint"), device, args.str("out"), options, std::cerr,
                                         [&](int finished, int total, const std::string& line) {
                                           if (!progress) progress = std::make_unique<umvs::Progress>("infer", total);
                                           progress->update(finished, line);
                                         });
  if (progress) progress->finish();
  std::cout << "wrote " << result.done << " depth maps to " << args.str("out") << " (" << result.skipped << " skipped), "
            << (result.done ? result.network_seconds / result.done : 0.0) << " s per depth map\n";
  return result.done > 0 ? 0 : 1;
}
