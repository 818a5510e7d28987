// The pipeline benchmark of unsup_mvs/jobs/bench.h: what the inference nodelet does per keyframe
// set with its default settings (recommended_estimator_config: at most 640x512, planes following
// the input, `auto` sources, completion), on a rendered room (the demo's scene) so that the
// confidence, and with it `auto`'s extra passes, is what real input gives. Each run takes the next
// view as the reference with its best views-1 neighbours.
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <stdexcept>

#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/recommended_estimator.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/jobs/bench.h"

namespace umvs {

namespace {

// One estimate, recorded in `t` unless it is a warmup run.
void time_estimate(DepthEstimator& estimator, const std::vector<ViewInput>& views, const SynthScene& scene, bool record,
                   PipelineTimes& t) {
  const auto t0 = std::chrono::steady_clock::now();
  const DepthMap map = estimator.estimate(views, scene.depth_min, scene.depth_max);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (!record) return;
  t.total.push_back(seconds);
  t.network.push_back(map.seconds);
  t.completion.push_back(map.completion_seconds);
  const MvsStageTimes& st = map.stages;
  const double fine_pass = st.fine_cost_volume + st.fine_regularization;  // inside cost_volume and regularization
  t.first_pass.push_back(st.features + st.cost_volume + st.regularization + st.regression + st.refinement - fine_pass);
  t.features.push_back(st.features);
  t.volume.push_back(st.cost_volume);
  t.unet.push_back(st.regularization);
  t.fine_pass.push_back(fine_pass);
  t.extra_passes += map.per_source_passes ? 1 : 0;
  t.width = map.camera.width;
  t.height = map.camera.height;
}

std::string regularizer_name(const MvsNetConfig& c) {
  return c.network == NetworkKind::kSweep2d ? "2-D encoder-decoder" : "3-D U-Net";
}

}  // namespace

PipelineBenchResult bench_pipeline(const PipelineBenchOptions& options, const torch::Device& device) {
  if (options.checkpoint.empty()) {
    throw std::invalid_argument("--case pipeline times a trained model's behaviour (its confidence decides the extra "
                                "passes): give --checkpoint (e.g. models/unsup_mvsnet.pt)");
  }
  const int W = options.width, H = options.height, V = options.views;
  const int runs = options.runs.runs, warmup = options.runs.warmup;
  if (runs < 1) throw std::invalid_argument("--runs must be >= 1");
  if (V < 2) throw std::invalid_argument("--views must be >= 2 for --case pipeline");
  SynthConfig scene_cfg;
  scene_cfg.scene = SynthSceneType::kRoom;
  scene_cfg.seed = 7;  // the demo's room
  scene_cfg.num_views = std::max(V + 1, std::min(24, warmup + runs + V));
  scene_cfg.width = W;
  scene_cfg.height = H;
  scene_cfg.gt_cloud_samples = 0;
  const SynthScene scene = render_synthetic_scene(scene_cfg);
  const auto default_planes = [&](const DepthEstimatorConfig& c, const LoadedModel& m) {
    return default_plane_count(m.model->config(),
                               first_pass_size(c, plan_network_resize(W, H, c.max_width, c.max_height).width));
  };
  DepthEstimatorConfig cfg = recommended_estimator_config();
  if (options.fine_planes) cfg.fine.planes = *options.fine_planes;
  if (options.fine_span) cfg.fine.span = *options.fine_span;
  if (options.fine_resolution) cfg.fine.resolution_divisor = *options.fine_resolution;
  if (options.first_pass_downscale) cfg.fine.first_pass_downscale = *options.first_pass_downscale;
  const LoadedModel model = load_model(options.checkpoint, device);
  cfg.num_depth = options.num_depth ? *options.num_depth : default_planes(cfg, model);
  DepthEstimator estimator(model.model, device, cfg);
  // The nodelet's plain one pass: no fine pass, planes by the default rule.
  std::unique_ptr<DepthEstimator> against;
  PipelineBenchResult result;
  result.width = W;
  result.height = H;
  result.views = V;
  result.times.regularizer = regularizer_name(model.model->config());
  result.times.fine = cfg.fine.enabled();
  if (!options.against.empty()) {
    DepthEstimatorConfig against_cfg = recommended_estimator_config();
    against_cfg.fine = FinePassConfig{};
    const LoadedModel against_model = load_model(options.against, device);
    against_cfg.num_depth = default_planes(against_cfg, against_model);
    against = std::make_unique<DepthEstimator>(against_model.model, device, against_cfg);
    result.against.emplace();
    result.against->regularizer = regularizer_name(against->model()->config());
  }
  for (int r = 0; r < warmup + runs; ++r) {
    const size_t ref = static_cast<size_t>(r) % scene.views.size();
    std::vector<ViewInput> views{{scene.views[ref].image, scene.views[ref].camera}};
    for (const auto& [source, score] : scene.pairs[ref]) {
      if (static_cast<int>(views.size()) == V) break;
      views.push_back({scene.views[source].image, scene.views[source].camera});
    }
    time_estimate(estimator, views, scene, r >= warmup, result.times);
    if (against) time_estimate(*against, views, scene, r >= warmup, *result.against);
  }
  result.times.num_depth = estimator.num_depth();
  if (against) result.against->num_depth = against->num_depth();
  result.peak_rss_mib = peak_rss_mib();
  return result;
}

}  // namespace umvs
