// umvs bench: speed and memory of the network (and later fusion) on synthetic input.
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>
#include <sys/resource.h>

#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/fast_mvsnet.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/core/recommended_estimator.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/core/timing_log.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/bench_util.h"
#include "unsup_mvs/tools/command.h"

namespace umvs {

double peak_rss_mib() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return 0.0;
}

long minor_page_faults() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_minflt;
}

BenchStats summarize(std::vector<double> seconds) {
  std::sort(seconds.begin(), seconds.end());
  BenchStats s;
  s.runs = static_cast<int>(seconds.size());
  s.min = seconds.front();
  s.max = seconds.back();
  const size_t n = seconds.size();
  s.median = n % 2 ? seconds[n / 2] : 0.5 * (seconds[n / 2 - 1] + seconds[n / 2]);
  return s;
}

namespace {

// Cameras on a short horizontal baseline looking at a fronto-parallel scene.
std::vector<Camera> bench_cameras(int width, int height, int views) {
  std::vector<Camera> cams;
  for (int v = 0; v < views; ++v) {
    Camera c;
    c.width = width;
    c.height = height;
    c.K << 0.8 * width, 0, width / 2.0 - 0.5, 0, 0.8 * width, height / 2.0 - 0.5, 0, 0, 1;
    c.T_cam_world(0, 3) = -0.05 * v;
    cams.push_back(c);
  }
  return cams;
}

// Fusion case: one reference and `sources` source views on an arc (+-15 degrees) 2 m from a
// slanted plane that fills every image, so every pixel is an estimate (the worst case). Each run
// fuses every view against all the others; reports seconds per reference view and points/s.
int bench_fusion(const Args& args, const torch::Device& device) {
  const int W = args.integer("width"), H = args.integer("height"), S = args.integer("sources");
  const int runs = args.integer("runs");
  if (S < 1) throw std::invalid_argument("--sources must be >= 1");
  const Eigen::Vector3d n = Eigen::Vector3d(0.2, -0.3, 1.0).normalized();  // plane n.X = 0 through the origin
  std::vector<FusionView> views;
  for (int i = 0; i <= S; ++i) {
    const double a = (S == 0 ? 0.0 : (2.0 * i / S - 1.0)) * 15.0 * M_PI / 180.0;
    const Eigen::Vector3d eye(2.0 * std::sin(a), 0.1 * std::cos(3 * a), -2.0 * std::cos(a));
    const Eigen::Vector3d f = (-eye).normalized();
    const Eigen::Vector3d r = Eigen::Vector3d::UnitY().cross(f).normalized();
    Eigen::Matrix3d R;
    R.row(0) = r;
    R.row(1) = f.cross(r);
    R.row(2) = f;
    FusionView v;
    v.id = i;
    v.camera.width = W;
    v.camera.height = H;
    v.camera.K << 0.9 * W, 0, (W - 1) / 2.0, 0, 0.9 * W, (H - 1) / 2.0, 0, 0, 1;
    v.camera.T_cam_world.topLeftCorner<3, 3>() = R;
    v.camera.T_cam_world.topRightCorner<3, 1>() = -R * eye;
    // z-depth along each pixel ray d (camera z = 1): eye + s d on the plane -> s = -n.eye / n.d
    const Eigen::Vector3d m = (R.transpose() * v.camera.K.inverse()).transpose() * n;  // n.d = m.(x, y, 1)
    auto xs = torch::arange(W, torch::kFloat64).view({1, W}), ys = torch::arange(H, torch::kFloat64).view({H, 1});
    v.depth = (-n.dot(eye) / (m.x() * xs + m.y() * ys + m.z())).to(torch::kFloat32);
    v.confidence = torch::ones_like(v.depth);
    v.color = torch::full({H, W, 3}, 128, torch::kUInt8);
    views.push_back(v);
  }
  FusionConfig cfg;
  cfg.max_source_views = S;
  DepthFusion fusion(cfg, device);
  std::vector<double> per_view, rates, ranking, consistency, making_points;
  size_t points = 0;
  for (int r = 0; r < args.integer("warmup") + runs; ++r) {
    std::vector<FusionViewStats> stats;
    const auto t0 = std::chrono::steady_clock::now();
    points = fusion.fuse(views, {}, &stats).size();
    const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (r < args.integer("warmup")) continue;
    per_view.push_back(total / views.size());
    rates.push_back(points / total);
    for (const auto& st : stats) {
      ranking.push_back(st.ranking_seconds);
      consistency.push_back(st.consistency_seconds);
      making_points.push_back(st.points_seconds);
    }
  }
  const auto s = summarize(per_view);
  // Per reference view, median over views and runs; the rest of a view's time is preparing the
  // views (validity masks) once per fusion.
  const double rank_s = summarize(ranking).median, check_s = summarize(consistency).median,
               points_s = summarize(making_points).median;
  std::sort(rates.begin(), rates.end());
  const double rate = rates[rates.size() / 2];
  std::ostringstream device_name;
  device_name << device;
  if (args.on("json")) {
    const nlohmann::ordered_json out = {
        {"case", "fusion"}, {"width", W}, {"height", H}, {"sources", S}, {"threads", torch::get_num_threads()},
        {"device", device_name.str()}, {"runs", s.runs}, {"median_s_per_view", s.median}, {"min_s", s.min}, {"max_s", s.max},
        {"points_per_s", rate}, {"points", points}, {"peak_rss_mib", peak_rss_mib()},
        {"stages_median_s_per_view", {{"ranking", rank_s}, {"consistency", check_s}, {"points", points_s}}}};
    std::cout << out.dump() << "\n";
  } else {
    std::cout << std::fixed << std::setprecision(3) << "fusion " << W << "x" << H << " reference, " << S << " sources, device="
              << device_name.str() << " threads=" << torch::get_num_threads() << ": median " << s.median << " s per reference view (min "
              << s.min << ", max " << s.max << ", " << s.runs << " runs of " << views.size() << " views), " << std::setprecision(0)
              << rate << " points/s (" << points << " points per run), peak RSS " << peak_rss_mib() << " MiB\n"
              << std::setprecision(5) << "  stages per view (median s): source ranking " << rank_s << ", consistency "
              << check_s << ", points " << points_s << "\n";
  }
  return 0;
}


// The timings of one estimator over the runs of --case pipeline.
struct PipelineTimes {
  std::vector<double> total, network, first_pass, completion, features, volume, unet, fine_pass;
  int extra_passes = 0, width = 0, height = 0;
  const char* regularizer = "3-D U-Net";
};

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

const char* regularizer_name(const MvsNetConfig& c) {
  return c.network == NetworkKind::kSweep2d ? "2-D encoder-decoder" : "3-D U-Net";
}

std::pair<double, double> p50_p90(const std::vector<double>& v) { return {percentile(v, 50), percentile(v, 90)}; }

// One estimator's keys of the JSON object (all but case, threads, device and peak_rss_mib).
nlohmann::ordered_json pipeline_json(const PipelineTimes& t, int W, int H, int num_depth, int V) {
  auto pair = [](const std::vector<double>& v) { return nlohmann::ordered_json{{"p50", p50_p90(v).first}, {"p90", p50_p90(v).second}}; };
  return {{"width", W}, {"height", H}, {"num_depth", num_depth}, {"views", V},
          {"depth_map_width", t.width}, {"depth_map_height", t.height},
          {"runs", static_cast<int>(t.total.size())}, {"runs_with_per_source_passes", t.extra_passes},
          {"total_s", pair(t.total)}, {"network_all_passes_s", pair(t.network)}, {"first_pass_s", pair(t.first_pass)},
          {"completion_s", pair(t.completion)},
          {"first_pass_stages_p50_s", {{"features", p50_p90(t.features).first}, {"cost_volume", p50_p90(t.volume).first},
                                       {"unet3d", p50_p90(t.unet).first}}}};
}

// One estimator's text block: `header`, then p50/p90 of the estimate and each stage.
void print_pipeline_block(const std::string& header, const PipelineTimes& t, bool fine) {
  auto line = [](const char* name, const std::vector<double>& v) {
    std::cout << "  " << std::left << std::setw(34) << name << std::right << std::setprecision(3) << "p50 "
              << p50_p90(v).first << " s, p90 " << p50_p90(v).second << " s\n";
  };
  std::cout << header;
  line("image to depth map (estimate)", t.total);
  line("network, every pass", t.network);
  line("  features", t.features);
  line("  cost volume", t.volume);
  line((std::string("  ") + t.regularizer).c_str(), t.unet);
  if (fine) {
    line("  of the last two, the fine pass", t.fine_pass);
    line("network, first pass", t.first_pass);
  }
  line("completion", t.completion);
}

// Pipeline case: what the inference nodelet does per keyframe set with its default settings
// (recommended_estimator_config: at most 640x512, planes following the input, `auto` sources,
// completion), on a rendered room (the demo's scene) so that the confidence, and with it `auto`'s
// extra passes, is what real input gives. Each run takes the next view as the reference with its
// best views-1 neighbours; reports p50/p90 of the whole estimate and of each stage. --against
// times a second checkpoint in the nodelet's one-pass configuration on the same views,
// interleaved run by run.
int bench_pipeline(const Args& args, const torch::Device& device) {
  if (args.str("checkpoint").empty()) {
    throw std::invalid_argument("--case pipeline times a trained model's behaviour (its confidence decides the extra "
                                "passes): give --checkpoint (e.g. models/unsup_mvsnet.pt)");
  }
  const int W = args.integer("width"), H = args.integer("height"), V = args.integer("views");
  const int runs = args.integer("runs"), warmup = args.integer("warmup");
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
  if (args.given("fine-planes")) cfg.fine.planes = args.integer("fine-planes");
  if (args.given("fine-span")) cfg.fine.span = args.real("fine-span");
  if (args.given("fine-resolution")) cfg.fine.resolution_divisor = args.integer("fine-resolution");
  if (args.given("first-pass-downscale")) cfg.fine.first_pass_downscale = args.integer("first-pass-downscale");
  const LoadedModel model = load_model(args.str("checkpoint"), device);
  cfg.num_depth = args.given("num-depth") ? args.integer("num-depth") : default_planes(cfg, model);
  DepthEstimator estimator(model.model, device, cfg);
  // The nodelet's plain one pass: no fine pass, planes by the default rule.
  const std::string against_path = args.str("against");
  std::unique_ptr<DepthEstimator> against;
  if (!against_path.empty()) {
    DepthEstimatorConfig against_cfg = recommended_estimator_config();
    against_cfg.fine = FinePassConfig{};
    const LoadedModel against_model = load_model(against_path, device);
    against_cfg.num_depth = default_planes(against_cfg, against_model);
    against = std::make_unique<DepthEstimator>(against_model.model, device, against_cfg);
  }
  PipelineTimes times, against_times;
  times.regularizer = regularizer_name(model.model->config());
  if (against) against_times.regularizer = regularizer_name(against->model()->config());
  for (int r = 0; r < warmup + runs; ++r) {
    const size_t ref = static_cast<size_t>(r) % scene.views.size();
    std::vector<ViewInput> views{{scene.views[ref].image, scene.views[ref].camera}};
    for (const auto& [source, score] : scene.pairs[ref]) {
      if (static_cast<int>(views.size()) == V) break;
      views.push_back({scene.views[source].image, scene.views[source].camera});
    }
    time_estimate(estimator, views, scene, r >= warmup, times);
    if (against) time_estimate(*against, views, scene, r >= warmup, against_times);
  }
  std::ostringstream device_name;
  device_name << device;
  const int num_depth = estimator.num_depth();
  if (args.on("json")) {
    nlohmann::ordered_json out = {{"case", "pipeline"}};
    out.update(pipeline_json(times, W, H, num_depth, V));
    out["threads"] = torch::get_num_threads();
    out["device"] = device_name.str();
    out["peak_rss_mib"] = peak_rss_mib();
    if (against) out["against"] = pipeline_json(against_times, W, H, against->num_depth(), V);
    std::cout << out.dump() << "\n";
  } else {
    std::ostringstream header;
    header << std::fixed << "pipeline (the inference nodelet's defaults) " << W << "x" << H << " images, D=" << num_depth
           << ", " << V << " views, device=" << device_name.str() << " threads=" << torch::get_num_threads() << ": "
           << times.width << "x" << times.height << " depth maps, " << runs << " runs (" << times.extra_passes
           << " with the per-source passes of auto), peak RSS " << std::setprecision(0) << peak_rss_mib() << " MiB\n";
    std::cout << std::fixed;
    print_pipeline_block(header.str(), times, cfg.fine.enabled());
    if (against) {
      std::ostringstream against_header;
      against_header << "against (one pass, " << against_path << "): D=" << against->num_depth() << ", "
                     << against_times.width << "x" << against_times.height << " depth maps, " << runs << " runs ("
                     << against_times.extra_passes << " with the per-source passes of auto)\n";
      print_pipeline_block(against_header.str(), against_times, false);
      const double c = p50_p90(times.total).second, a = p50_p90(against_times.total).second;
      std::cout << std::setprecision(3) << "image to depth map p90: candidate " << c << " s, against " << a
                << " s (against / candidate = " << std::setprecision(2) << a / c << "x)\n";
    }
  }
  return 0;
}
}  // namespace
}  // namespace umvs

UMVS_COMMAND(bench, "time and memory of the network on synthetic input") {
  umvs::Args args("bench",
                  "Times forward passes of MVSNet on random images (random weights unless --checkpoint):\n"
                  "median/min/max seconds per depth map over --runs runs after --warmup runs, achieved\n"
                  "GFLOP/s (convolutions), the median time of each stage (fast path), minor page faults per\n"
                  "run and peak memory (the process's peak RSS, host memory also on CUDA). --path both interleaves\n"
                  "the inference path and the autograd (training) path and reports both and their ratio.");
  args.option("case", "network",
              "what to time: network | fusion | pipeline (the inference nodelet's defaults on a rendered room, "
              "with --checkpoint: every pass, completion, p50/p90)")
      .option("width", "640", "image width (multiple of 32)")
      .option("height", "512", "image height (multiple of 32)")
      .option("num-depth", "128", "depth hypotheses")
      .option("network", "mvsnet", "network case, random weights: mvsnet | sweep2d (a --checkpoint says its own)")
      .option("views", "3", "views per depth map")
      .option("fine-planes", umvs::recommended_estimator_config().fine.planes,
              "pipeline: hypotheses per pixel of the second, finer pass (0 = one pass)")
      .option("fine-span", umvs::recommended_estimator_config().fine.span,
              "pipeline: first-pass plane intervals the second pass covers")
      .option("fine-resolution", umvs::recommended_estimator_config().fine.resolution_divisor,
              "pipeline: 2 | 4, the second pass's resolution (1/2 or 1/4 of the input)")
      .option("first-pass-downscale", umvs::recommended_estimator_config().fine.first_pass_downscale,
              "pipeline: 2 = the first pass at half the input's size")
      .option("sources", "10", "fusion: source views per reference")
      .option("threads", 2, "CPU threads")
      .option("device", "cpu", "cpu | cuda")
      .option("runs", "5", "timed runs (>= 5 recommended)")
      .option("warmup", "1", "untimed runs first")
      .option("checkpoint", "", "time these weights (default random init)")
      .option("against", "",
              "pipeline: also time this checkpoint in the nodelet's one-pass configuration, interleaved with "
              "--checkpoint on the same views")
      .option("path", "fast", "network: fast (inference path, as umvs infer) | autograd (MvsNetImpl::forward) | both")
      .flag("no-tuning", "leave OpenBLAS threads and malloc as the environment sets them (see tune_cpu_process)")
      .flag("refine", "include the refinement network")
      .flag("json", "print one JSON object instead of text");
  if (!args.parse(argc, argv)) return 0;
  if (args.on("no-tuning")) {
    torch::set_num_threads(args.integer("threads") > 0 ? args.integer("threads") : static_cast<int>(std::thread::hardware_concurrency()));
  } else {
    umvs::configure_threads(args.integer("threads"));
  }
  const auto device = umvs::parse_device(args.str("device"));
  if (const int used = umvs::parallel_loop_threads(); used < torch::get_num_threads()) {
    std::cerr << "warning: the parallel loops of this build run on " << used << " of " << torch::get_num_threads()
              << " threads (built without OpenMP? see UMVS_OPENMP in CMakeLists.txt)\n";
  }
  const int W = args.integer("width"), H = args.integer("height"), V = args.integer("views");
  int D = args.integer("num-depth");
  const int runs = args.integer("runs");
  if (runs < 1) throw std::invalid_argument("--runs must be >= 1");
  if (!args.str("against").empty() && args.str("case") != "pipeline") {
    throw std::invalid_argument("--against is for --case pipeline only");
  }
  if (args.str("case") == "fusion") return umvs::bench_fusion(args, device);
  if (args.str("case") == "pipeline") return umvs::bench_pipeline(args, device);
  if (args.str("case") != "network") throw std::invalid_argument("unknown --case '" + args.str("case") + "'");
  const std::string path = args.str("path");
  if (path != "fast" && path != "autograd" && path != "both") throw std::invalid_argument("unknown --path '" + path + "' (fast|autograd|both)");

  umvs::MvsNetConfig cfg;
  cfg.network = umvs::network_kind_from_string(args.str("network"));
  cfg.num_depth = D;
  cfg.num_views = V;
  cfg.refine = args.on("refine");
  umvs::MvsNet model{nullptr};
  if (args.str("checkpoint").empty()) {
    model = umvs::MvsNet(cfg);
  } else {  // the file's network; MVSNet_pytorch weights (no config) as the options say
    auto loaded = umvs::load_model(args.str("checkpoint"), device);
    model = loaded.model;
    if (loaded.format == "mvsnet_pytorch") model->set_feature_warp(cfg.feature_warp);
    cfg = model->config();
    if (cfg.planes_fixed_by_weights() && !args.given("num-depth")) D = cfg.num_depth;  // the weights' own count
  }
  model->to(device);
  umvs::FastMvsNet fast(model);
  torch::manual_seed(0);
  auto images = torch::rand({1, V, 3, H, W}).to(device);
  auto proj = umvs::mvsnet_projection_matrices(umvs::bench_cameras(W, H, V)).unsqueeze(0).to(device);
  auto depth_values = umvs::depth_hypotheses(1.0, 10.0, D, umvs::DepthSampling::kUniformInverseDepth).unsqueeze(0).to(device);

  // One timed forward pass of either path; the fast path also reports its stages.
  auto run_once = [&](bool use_fast, umvs::MvsStageTimes* stages) {
    torch::NoGradGuard no_grad;
    const auto t0 = std::chrono::steady_clock::now();
    auto out = use_fast ? fast.forward(images, proj, depth_values, false, stages) : model->forward(images, proj, depth_values);
    if (device.is_cuda()) torch::cuda::synchronize();
    out.depth.sum().item<double>();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  std::vector<bool> order;  // which path each run takes; both: interleaved fast, autograd, fast, ...
  if (path == "both") {
    for (int i = 0; i < runs; ++i) order.insert(order.end(), {true, false});
  } else {
    order.assign(runs, path == "fast");
  }
  for (int i = 0; i < args.integer("warmup"); ++i) {
    if (path != "autograd") run_once(true, nullptr);
    if (path != "fast") run_once(false, nullptr);
  }
  std::vector<double> fast_s, autograd_s;
  std::vector<double> features_s, volume_s, unet_s, regression_s, refine_s;
  const long faults_before = umvs::minor_page_faults();
  for (const bool use_fast : order) {
    umvs::MvsStageTimes st;
    const double t = run_once(use_fast, &st);
    (use_fast ? fast_s : autograd_s).push_back(t);
    if (!use_fast) continue;
    features_s.push_back(st.features);
    volume_s.push_back(st.cost_volume);
    unet_s.push_back(st.regularization);
    regression_s.push_back(st.regression);
    refine_s.push_back(st.refinement);
  }
  const double faults_per_run = static_cast<double>(umvs::minor_page_faults() - faults_before) / order.size();
  const auto s = umvs::summarize(path == "autograd" ? autograd_s : fast_s);
  const double gflop = (cfg.network == umvs::NetworkKind::kSweep2d ? umvs::sweep_net_forward_flops(H, W, D, V)
                                                                    : umvs::mvsnet_forward_flops(H, W, D, V, cfg.refine)) /
                       1e9;
  const double memory_mib = umvs::peak_rss_mib();
  const bool have_stages = !features_s.empty() && umvs::FastMvsNet::accelerates(device);
  std::ostringstream device_name;
  device_name << device;
  const std::string path_name = path == "autograd" ? "autograd" : "fast";
  if (args.on("json")) {
    nlohmann::ordered_json out = {
        {"case", "network"}, {"path", path_name}, {"width", W}, {"height", H}, {"num_depth", D}, {"views", V},
        {"threads", torch::get_num_threads()}, {"device", device_name.str()}, {"tuned", !args.on("no-tuning")},
        {"runs", s.runs}, {"median_s", s.median}, {"min_s", s.min}, {"max_s", s.max}, {"gflop", gflop},
        {"gflops", gflop / s.median}, {"peak_rss_mib", memory_mib}, {"minor_faults_per_run", faults_per_run}};
    if (have_stages) {
      out["stages_median_s"] = {{"features", umvs::summarize(features_s).median},
                                {"cost_volume", umvs::summarize(volume_s).median},
                                {"unet3d", umvs::summarize(unet_s).median},
                                {"regression", umvs::summarize(regression_s).median},
                                {"refinement", umvs::summarize(refine_s).median}};
    }
    if (path == "both") {
      const double a = umvs::summarize(autograd_s).median;
      out["autograd_median_s"] = a;
      out["autograd_over_fast"] = a / s.median;
    }
    std::cout << out.dump() << "\n";
  } else {
    std::cout << std::fixed << std::setprecision(3) << umvs::to_string(cfg.network) << " " << W << "x" << H << " D=" << D << " V=" << V
              << " device=" << device_name.str() << " threads=" << torch::get_num_threads() << " path=" << path_name
              << (args.on("no-tuning") ? " (untuned)" : "") << ": median " << s.median << " s (min " << s.min << ", max "
              << s.max << ", " << s.runs << " runs), " << std::setprecision(1) << gflop << " GFLOP -> " << gflop / s.median
              << " GFLOP/s, peak RSS " << std::setprecision(0) << memory_mib << " MiB, " << faults_per_run
              << " minor page faults per run\n";
    if (have_stages) {
      const char* regularizer = umvs::regularizer_name(cfg);
      std::cout << std::setprecision(4) << "  stages (median s): features " << umvs::summarize(features_s).median
                << ", cost volume " << umvs::summarize(volume_s).median << ", " << regularizer << " "
                << umvs::summarize(unet_s).median
                << ", regression " << umvs::summarize(regression_s).median;
      if (cfg.refine) std::cout << ", refinement " << umvs::summarize(refine_s).median;
      std::cout << "\n";
    }
    if (path == "both") {
      const auto a = umvs::summarize(autograd_s);
      std::cout << std::setprecision(3) << "  autograd path, interleaved: median " << a.median << " s (min " << a.min
                << ", max " << a.max << ") -> autograd / fast = " << a.median / s.median << "\n";
    }
  }
  return 0;
}
