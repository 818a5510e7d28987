// umvs eval depth|cloud|rule: depth-map and point-cloud metrics against ground truth (io/evaluation.h).
#include <cstdio>
#include <iostream>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/evaluation.h"
#include "unsup_mvs/jobs/fine_tune_job.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

namespace {

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
  umvs::DepthFolderEvalOptions options;
  args.required("est", "estimate folder")
      .required("gt", "ground-truth folder (depth_gt/, cams/)")
      .bind("est-subdir", &options.est_subdir, "subfolder of EST with the depth maps (default: depth_est, depth_gt or depth)")
      .bind("min-confidence", &options.min_confidence, "ignore estimates whose EST/confidence/XXXXXXXX.pfm is below this")
      .bind("rel-thresholds", &options.metrics.rel_thresholds, "relative error thresholds (comma-separated)")
      .bind("abs-thresholds", &options.metrics.abs_thresholds, "absolute error thresholds in scene units (comma-separated)")
      .bind("views", &options.views, "comma-separated view ids (default: every estimate)")
      .bind("covisibility-sources", &options.covisibility_sources,
            "split the errors by whether the first N neighbours in GT/pair.txt see the pixel (2 = umvs infer's "
            "default --views 3); 0 = off")
      .bind("max-turn-deg", &options.max_turn_deg,
            "accept estimates whose cameras are turned by up to this many degrees from GT's, as after "
            "`umvs refine-poses`: the images are the same, so depth is compared pixel for pixel (0 = same pose only)")
      .flag("sparsification", &options.sparsification,
            "also judge the confidence (EST/confidence/): the abs rel of the most confident 10 %, 20 %, ... of the "
            "pixels beside the oracle's (AUSE), and for each --confidence-levels the share of the image at or above "
            "it with its abs rel and share within --confident-within")
      .bind("confidence-levels", &options.confidence_levels, "confidence floors reported with --sparsification")
      .bind("confident-within", &options.confident_within, "relative error counted as right at those floors")
      .flag("json", "print JSON instead of a table");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(0);
  const auto eval = umvs::evaluate_depth_folder(args.str("est"), args.str("gt"), options);
  if (args.on("json")) {
    std::cout << umvs::to_json(eval, options).dump(1) << "\n";
  } else {
    umvs::print_table(std::cout, eval, options, args.str("gt"));
  }
  return 0;
}

int eval_cloud(int argc, char** argv) {
  umvs::Args args("eval cloud",
                  "DTU-style accuracy (EST -> GT nearest-neighbour distance) and completeness (GT -> EST), mean and\n"
                  "median, distances above --max-dist left out as outliers; overall = mean of the two means.\n"
                  "Tanks-and-Temples precision, recall and F-score at each --thresholds distance. Distances in scene units.\n"
                  "The ground truth is a cloud (--gt) or an RGB-D set's sensor depth (--gt-depth: umvs import's folder);\n"
                  "for a robot's log, e.g. --gt-depth DATA --thresholds 0.02,0.05,0.1 (metres).");
  umvs::CloudMetricsConfig cfg;
  args.required("est", "estimated cloud (.ply or .pcd)")
      .option("gt", "", "ground-truth cloud (.ply or .pcd), e.g. gt.ply of a `umvs synth` folder")
      .option("gt-depth", "",
              "or: a folder of sensor depth (depth_gt/, cams/: `umvs import` of an RGB-D set), back-projected as the "
              "ground truth")
      .option("gt-views", "", "with --gt-depth: comma-separated view ids (default: every view)")
      .option("gt-stride", "2", "with --gt-depth: every N-th pixel each way")
      .option("gt-spacing", "0.01", "with --gt-depth: the reference thinned to this spacing (scene units; 0 = no)")
      .bind("max-dist", &cfg.max_distance, "outlier cap: distances above it are left out of the means (DTU: 0.02 m); 0 = none")
      .bind("thresholds", &cfg.thresholds, "precision/recall thresholds (comma-separated)")
      .bind("downsample", &cfg.downsample_spacing, "first reduce both clouds to this minimum spacing (DTU: 0.0002 m); 0 = no")
      .flag("json", "print JSON instead of a table");
  if (!args.parse(argc, argv)) return 0;
  umvs::configure_threads(0);
  if (args.given("gt") == args.given("gt-depth")) throw std::invalid_argument("give one of --gt CLOUD and --gt-depth FOLDER");
  const auto est = umvs::read_cloud(args.str("est"));
  const auto gt = args.given("gt") ? umvs::read_cloud(args.str("gt"))
                                   : umvs::sensor_depth_cloud(args.str("gt-depth"), args.integers("gt-views"),
                                                              args.integer("gt-stride"), args.real("gt-spacing"));
  if (est.empty()) throw std::runtime_error("estimated cloud " + args.str("est") + " has no points: nothing to evaluate");
  if (gt.empty()) throw std::runtime_error("ground-truth cloud " + args.str("gt") + " has no points");
  const umvs::CloudMetrics m = umvs::evaluate_cloud(est, gt, cfg);
  if (args.on("json")) {
    std::cout << umvs::to_json(m).dump(1) << "\n";
  } else {
    const std::string gt_name = args.given("gt") ? args.str("gt") : "sensor depth of " + args.str("gt-depth");
    umvs::print_table(std::cout, m, args.str("est"), gt_name, cfg.downsample_spacing > 0);
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
