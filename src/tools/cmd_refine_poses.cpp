// umvs refine-poses: a copy of an MVSNet-format folder with its cameras' orientations corrected
// without labels (io/refine_poses.h).
#include <torch/torch.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <iostream>

#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/io/refine_poses.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"
#include "unsup_mvs/tools/progress.h"

namespace {

int refine_poses(int argc, char** argv) {
  umvs::Args args("refine-poses",
                  "Poses from odometry or SLAM are often a few tenths of a degree off between views, several\n"
                  "pixels at 640 wide, and depth made from them is wrong. For every reference view of DIR (or\n"
                  "--ref) and its --sources best neighbours in pair.txt, this measures with the model the turn of\n"
                  "the neighbour that warps it best onto the reference (SSIM over textured windows, kept when\n"
                  "clearly better, as `umvs infer --source-rotation-search`), then turns every camera about its\n"
                  "own centre so that all views agree with those turns at once. No label is read. OUT is a new\n"
                  "MVSNet-format folder (images/ and pair.txt copied, cams/ corrected, pose_refinement.txt) that\n"
                  "`umvs infer`, `umvs train` and `umvs fuse` use without searching again; depth_gt/ is not copied.");
  args.required("data", "MVSNet-format input folder (images/, cams/, pair.txt)")
      .required("checkpoint", "model: our checkpoint or MVSNet_pytorch weights")
      .required("out", "new output folder (refused when it holds files)")
      .option("ref", "", "comma-separated reference view ids to measure from (default: all in pair.txt); views that no "
              "measured pair names keep their poses")
      .option("sources", "2", "neighbours measured per reference, best first in pair.txt")
      .option("search-deg", "2", "largest turn about each axis per round, degrees")
      .option("rounds", "2", "measure and solve again from the corrected cameras this many times in all")
      .option("num-depth", "0", "depth planes (multiple of 8; 0 = 128 at 640 wide, scaled with the width)")
      .option("max-width", "0", "scale images down to at most this width (0 = keep)")
      .option("max-height", "0", "scale images down to at most this height (0 = keep)")
      .option("device", "cpu", "cpu | cuda | cuda:N")
      .option("threads", 0, "CPU threads (0 = all cores)");
  if (!args.parse(argc, argv)) return 0;

  umvs::configure_threads(args.integer("threads"));
  const auto device = umvs::parse_device(args.str("device"));
  umvs::PoseRefinementConfig config;
  config.data_dir = args.str("data");
  config.out_dir = args.str("out");
  config.refs = args.integers("ref");
  config.sources = args.integer("sources");
  config.search_deg = args.real("search-deg");
  config.rounds = args.integer("rounds");

  const umvs::MvsFolder folder(config.data_dir);
  if (folder.pairs().empty()) throw std::invalid_argument("'" + config.data_dir + "/pair.txt' lists no view");
  auto loaded = umvs::load_model(args.str("checkpoint"), device);
  umvs::DepthEstimatorConfig estimator_config;
  estimator_config.max_width = args.integer("max-width");
  estimator_config.max_height = args.integer("max-height");
  const umvs::Camera first = folder.load_view(folder.pairs().front().ref).cam.camera;
  const umvs::NetworkResize plan =
      umvs::plan_network_resize(first.width, first.height, estimator_config.max_width, estimator_config.max_height);
  const umvs::PlaneCount planes = umvs::choose_plane_count(args.integer("num-depth"), "--num-depth", plan.width, plan.height,
                                                           loaded.model->config().num_depth,
                                                           loaded.model->config().planes_fixed_by_weights());
  estimator_config.num_depth = planes.planes;
  umvs::DepthEstimator estimator(loaded.model, device, estimator_config);
  std::cerr << "model: " << args.str("checkpoint") << " (" << loaded.format << "), device " << device << ", "
            << torch::get_num_threads() << " threads; depth planes: " << planes.why << "\n";

  std::unique_ptr<umvs::Progress> progress;
  const auto result = umvs::refine_folder_poses(config, estimator, [&](int done, int total, const umvs::MeasuredPair& p) {
    if (!progress) progress = std::make_unique<umvs::Progress>("measure", total);
    char extra[160];
    std::snprintf(extra, sizeof(extra), "round %d, view %d, source %d: best turn (%.1f, %.1f, %.1f) deg, warp %.1f %% better%s",
                  p.round, p.reference, p.source, p.turn.degrees.x(), p.turn.degrees.y(), p.turn.degrees.z(),
                  100.0 * p.turn.search_gain, p.turn.kept ? ", kept" : "");
    progress->update(done, extra);
  });
  if (progress) progress->finish();
  for (int round = 1; round <= config.rounds; ++round) {
    int measured = 0, kept = 0;
    for (const auto& p : result.pairs) {
      if (p.round != round) continue;
      ++measured;
      kept += p.turn.kept ? 1 : 0;
    }
    std::cout << "round " << round << ": " << measured << " pairs measured, " << kept << " turns kept (warp "
              << 100.0 * umvs::kMinSourceTurnGain << " % better, also at full size)\n";
  }
  for (const auto& [id, turn] : result.view_degrees) {
    const Eigen::Vector3d d = turn.unaryExpr([](double v) { return std::abs(v) < 5e-3 ? 0.0 : v; });  // no "-0.00"
    char line[120];
    std::snprintf(line, sizeof(line), "  view %d: turned by (%.2f, %.2f, %.2f) degrees about x, y, z\n", id, d.x(), d.y(), d.z());
    std::cout << line;
  }
  std::cout << "wrote " << config.out_dir << " (cams/ corrected, images/ and pair.txt copied, pose_refinement.txt)\n";
  return 0;
}

}  // namespace

static umvs::CommandRegistrar refine_poses_registrar(
    "refine-poses", "correct the cameras' orientations of an MVSNet-format folder without labels", &refine_poses);
