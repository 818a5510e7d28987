// The benchmarks of `umvs bench` on synthetic input: the network alone, the inference nodelet's
// pipeline (every pass, completion) and fusion. Each takes its options, times `runs` runs after
// `warmup` untimed ones and returns what it measured; the reports print it as JSON or text.
#pragma once

#include <torch/types.h>

#include <iosfwd>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace umvs {

struct BenchStats {
  int runs = 0;
  double median = 0, min = 0, max = 0;  // seconds
};
BenchStats summarize(std::vector<double> seconds);
double peak_rss_mib();     // peak resident memory of this process (VmHWM)
long minor_page_faults();  // of this process so far (getrusage)

// Where and how long to time.
struct BenchRuns {
  int runs = 5;    // timed runs (>= 1)
  int warmup = 1;  // untimed runs first
};

// --- network: one forward pass on random images, random weights unless a checkpoint is given.
struct NetworkBenchOptions {
  std::string network = "mvsnet";  // mvsnet | sweep2d (a checkpoint says its own)
  std::string checkpoint;          // "" = random weights
  int width = 640, height = 512, views = 3;
  std::optional<int> num_depth;    // unset: 128, or the checkpoint's own count where its weights fix it
  bool refine = false;             // include the refinement network
  std::string path = "fast";       // fast (inference path) | autograd (training path) | both, interleaved
  BenchRuns runs;
};
struct NetworkBenchResult {
  std::string network, path;  // path: fast or autograd (the one `stats` times)
  int width = 0, height = 0, num_depth = 0, views = 0;
  bool refine = false;
  BenchStats stats;
  double gflop = 0, peak_rss_mib = 0, minor_faults_per_run = 0;
  bool have_stages = false;  // the fast path's stage medians below
  double features = 0, cost_volume = 0, regularization = 0, regression = 0, refinement = 0;
  std::string regularizer;          // "3-D U-Net" or "2-D encoder-decoder"
  std::optional<BenchStats> autograd;  // with path both
};
NetworkBenchResult bench_network(const NetworkBenchOptions& options, const torch::Device& device);

// --- pipeline: the inference nodelet's defaults on the demo's rendered room.
struct PipelineBenchOptions {
  std::string checkpoint;  // required: the model's confidence decides the extra passes
  std::string against;     // "" or a checkpoint timed in the nodelet's one-pass configuration, interleaved
  int width = 640, height = 512, views = 3;
  std::optional<int> num_depth;  // unset: the default plane rule
  std::optional<int> fine_planes, fine_resolution, first_pass_downscale;
  std::optional<double> fine_span;  // unset: recommended_estimator_config()'s
  BenchRuns runs;
};
// One estimator's timings over the runs (seconds per run).
struct PipelineTimes {
  std::vector<double> total, network, first_pass, completion, features, volume, unet, fine_pass;
  int extra_passes = 0, width = 0, height = 0;  // width x height: the depth maps
  int num_depth = 0;
  bool fine = false;  // a fine pass ran
  std::string regularizer = "3-D U-Net";
};
struct PipelineBenchResult {
  int width = 0, height = 0, views = 0;
  PipelineTimes times;
  std::optional<PipelineTimes> against;
  double peak_rss_mib = 0;
};
PipelineBenchResult bench_pipeline(const PipelineBenchOptions& options, const torch::Device& device);

// --- fusion: a reference and `sources` views on an arc before a slanted plane that fills every
// image (every pixel an estimate: the worst case); each run fuses every view against the others.
struct FusionBenchOptions {
  int width = 640, height = 512, sources = 10;
  BenchRuns runs;
};
struct FusionBenchResult {
  int width = 0, height = 0, sources = 0, views = 0;
  BenchStats per_view;  // seconds per reference view
  double points_per_s = 0;
  size_t points = 0;    // per run
  double ranking_s = 0, consistency_s = 0, points_s = 0;  // per view, medians
  double peak_rss_mib = 0;
};
FusionBenchResult bench_fusion(const FusionBenchOptions& options, const torch::Device& device);

// Reports: `context` holds the keys every case shares (threads, device, tuned).
struct BenchContext {
  int threads = 0;
  std::string device;
  bool tuned = true;
};
nlohmann::ordered_json to_json(const NetworkBenchResult& r, const BenchContext& context);
nlohmann::ordered_json to_json(const PipelineBenchResult& r, const BenchContext& context);
nlohmann::ordered_json to_json(const FusionBenchResult& r, const BenchContext& context);
void print_text(std::ostream& out, const NetworkBenchResult& r, const BenchContext& context);
void print_text(std::ostream& out, const PipelineBenchResult& r, const BenchContext& context, const std::string& against);
void print_text(std::ostream& out, const FusionBenchResult& r, const BenchContext& context);

}  // namespace umvs
