// The network benchmark of unsup_mvs/jobs/bench.h, and the statistics every benchmark shares.
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <stdexcept>

#include <sys/resource.h>

#include "unsup_mvs/core/fast_mvsnet.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/core/sweep_net.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/jobs/bench.h"

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
  if (seconds.empty()) return {};
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
std::vector<Camera> baseline_cameras(int width, int height, int views) {
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

}  // namespace

NetworkBenchResult bench_network(const NetworkBenchOptions& options, const torch::Device& device) {
  const std::string& path = options.path;
  if (path != "fast" && path != "autograd" && path != "both") throw std::invalid_argument("unknown --path '" + path + "' (fast|autograd|both)");
  if (options.runs.runs < 1) throw std::invalid_argument("--runs must be >= 1");
  const int W = options.width, H = options.height, V = options.views;
  int D = options.num_depth.value_or(128);
  MvsNetConfig cfg;
  cfg.network = network_kind_from_string(options.network);
  cfg.num_depth = D;
  cfg.num_views = V;
  cfg.refine = options.refine;
  MvsNet model{nullptr};
  if (options.checkpoint.empty()) {
    model = MvsNet(cfg);
  } else {  // the file's network; MVSNet_pytorch weights (no config) as the options say
    auto loaded = load_model(options.checkpoint, device);
    model = loaded.model;
    if (loaded.format == "mvsnet_pytorch") model->set_feature_warp(cfg.feature_warp);
    cfg = model->config();
    if (cfg.planes_fixed_by_weights() && !options.num_depth) D = cfg.num_depth;  // the weights' own count
  }
  model->to(device);
  FastMvsNet fast(model);
  torch::manual_seed(0);
  auto images = torch::rand({1, V, 3, H, W}).to(device);
  auto proj = mvsnet_projection_matrices(baseline_cameras(W, H, V)).unsqueeze(0).to(device);
  auto depth_values = depth_hypotheses(1.0, 10.0, D, DepthSampling::kUniformInverseDepth).unsqueeze(0).to(device);

  // One timed forward pass of either path; the fast path also reports its stages.
  auto run_once = [&](bool use_fast, MvsStageTimes* stages) {
    torch::NoGradGuard no_grad;
    const auto t0 = std::chrono::steady_clock::now();
    auto out = use_fast ? fast.forward(images, proj, depth_values, false, stages) : model->forward(images, proj, depth_values);
    if (device.is_cuda()) torch::cuda::synchronize();
    out.depth.sum().item<double>();
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  };
  std::vector<bool> order;  // which path each run takes; both: interleaved fast, autograd, fast, ...
  if (path == "both") {
    for (int i = 0; i < options.runs.runs; ++i) order.insert(order.end(), {true, false});
  } else {
    order.assign(options.runs.runs, path == "fast");
  }
  for (int i = 0; i < options.runs.warmup; ++i) {
    if (path != "autograd") run_once(true, nullptr);
    if (path != "fast") run_once(false, nullptr);
  }
  std::vector<double> fast_s, autograd_s, features_s, volume_s, unet_s, regression_s, refine_s;
  const long faults_before = minor_page_faults();
  for (const bool use_fast : order) {
    MvsStageTimes st;
    const double t = run_once(use_fast, &st);
    (use_fast ? fast_s : autograd_s).push_back(t);
    if (!use_fast) continue;
    features_s.push_back(st.features);
    volume_s.push_back(st.cost_volume);
    unet_s.push_back(st.regularization);
    regression_s.push_back(st.regression);
    refine_s.push_back(st.refinement);
  }
  NetworkBenchResult r;
  r.minor_faults_per_run = static_cast<double>(minor_page_faults() - faults_before) / order.size();
  r.network = to_string(cfg.network);
  r.path = path == "autograd" ? "autograd" : "fast";
  r.width = W;
  r.height = H;
  r.num_depth = D;
  r.views = V;
  r.refine = cfg.refine;
  r.stats = summarize(path == "autograd" ? autograd_s : fast_s);
  r.gflop = (cfg.network == NetworkKind::kSweep2d ? sweep_net_forward_flops(H, W, D, V) : mvsnet_forward_flops(H, W, D, V, cfg.refine)) / 1e9;
  r.peak_rss_mib = peak_rss_mib();
  r.have_stages = !features_s.empty() && FastMvsNet::accelerates(device);
  r.features = summarize(features_s).median;
  r.cost_volume = summarize(volume_s).median;
  r.regularization = summarize(unet_s).median;
  r.regression = summarize(regression_s).median;
  r.refinement = summarize(refine_s).median;
  r.regularizer = cfg.network == NetworkKind::kSweep2d ? "2-D encoder-decoder" : "3-D U-Net";
  if (path == "both") r.autograd = summarize(autograd_s);
  return r;
}

}  // namespace umvs
