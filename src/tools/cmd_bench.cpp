// umvs bench: speed and memory of the network, the inference pipeline and fusion on synthetic
// input (jobs/bench.h).
#include <torch/torch.h>

#include <iostream>
#include <sstream>
#include <thread>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/recommended_estimator.h"
#include "unsup_mvs/jobs/bench.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

UMVS_COMMAND(bench, "time and memory of the network on synthetic input") {
  umvs::NetworkBenchOptions network;  // its size, views and runs are every case's
  umvs::PipelineBenchOptions pipeline;
  umvs::FusionBenchOptions fusion;
  std::string bench_case = "network";
  umvs::Args args("bench",
                  "Times forward passes of MVSNet on random images (random weights unless --checkpoint):\n"
                  "median/min/max seconds per depth map over --runs runs after --warmup runs, achieved\n"
                  "GFLOP/s (convolutions), the median time of each stage (fast path), minor page faults per\n"
                  "run and peak memory (the process's peak RSS, host memory also on CUDA). --path both interleaves\n"
                  "the inference path and the autograd (training) path and reports both and their ratio.");
  args.bind("case", &bench_case,
            "what to time: network | fusion | pipeline (the inference nodelet's defaults on a rendered room, "
            "with --checkpoint: every pass, completion, p50/p90)")
      .bind("width", &network.width, "image width (multiple of 32)")
      .bind("height", &network.height, "image height (multiple of 32)")
      .option("num-depth", "128", "depth hypotheses")
      .bind("network", &network.network, "network case, random weights: mvsnet | sweep2d (a --checkpoint says its own)")
      .bind("views", &network.views, "views per depth map")
      .option("fine-planes", umvs::recommended_estimator_config().fine.planes,
              "pipeline: hypotheses per pixel of the second, finer pass (0 = one pass)")
      .option("fine-span", umvs::recommended_estimator_config().fine.span,
              "pipeline: first-pass plane intervals the second pass covers")
      .option("fine-resolution", umvs::recommended_estimator_config().fine.resolution_divisor,
              "pipeline: 2 | 4, the second pass's resolution (1/2 or 1/4 of the input)")
      .option("first-pass-downscale", umvs::recommended_estimator_config().fine.first_pass_downscale,
              "pipeline: 2 = the first pass at half the input's size")
      .bind("sources", &fusion.sources, "fusion: source views per reference")
      .option("threads", 2, "CPU threads")
      .option("device", "cpu", "cpu | cuda")
      .bind("runs", &network.runs.runs, "timed runs (>= 5 recommended)")
      .bind("warmup", &network.runs.warmup, "untimed runs first")
      .bind("checkpoint", &network.checkpoint, "time these weights (default random init)")
      .bind("against", &pipeline.against,
            "pipeline: also time this checkpoint in the nodelet's one-pass configuration, interleaved with "
            "--checkpoint on the same views")
      .bind("path", &network.path, "network: fast (inference path, as umvs infer) | autograd (MvsNetImpl::forward) | both")
      .flag("no-tuning", "leave OpenBLAS threads and malloc as the environment sets them (see tune_cpu_process)")
      .flag("refine", &network.refine, "include the refinement network")
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
  if (!pipeline.against.empty() && bench_case != "pipeline") throw std::invalid_argument("--against is for --case pipeline only");
  if (args.given("num-depth")) network.num_depth = pipeline.num_depth = args.integer("num-depth");
  std::ostringstream device_name;
  device_name << device;
  const umvs::BenchContext context{torch::get_num_threads(), device_name.str(), !args.on("no-tuning")};
  const auto report = [&](const auto& result) {
    if (args.on("json")) {
      std::cout << umvs::to_json(result, context).dump() << "\n";
    } else {
      umvs::print_text(std::cout, result, context);
    }
    return 0;
  };
  if (bench_case == "network") return report(umvs::bench_network(network, device));
  if (bench_case == "fusion") {
    fusion.width = network.width;
    fusion.height = network.height;
    fusion.runs = network.runs;
    return report(umvs::bench_fusion(fusion, device));
  }
  if (bench_case != "pipeline") throw std::invalid_argument("unknown --case '" + bench_case + "'");
  pipeline.checkpoint = network.checkpoint;
  pipeline.width = network.width;
  pipeline.height = network.height;
  pipeline.views = network.views;
  pipeline.runs = network.runs;
  if (args.given("fine-planes")) pipeline.fine_planes = args.integer("fine-planes");
  if (args.given("fine-span")) pipeline.fine_span = args.real("fine-span");
  if (args.given("fine-resolution")) pipeline.fine_resolution = args.integer("fine-resolution");
  if (args.given("first-pass-downscale")) pipeline.first_pass_downscale = args.integer("first-pass-downscale");
  const auto result = umvs::bench_pipeline(pipeline, device);
  if (args.on("json")) {
    std::cout << umvs::to_json(result, context).dump() << "\n";
  } else {
    umvs::print_text(std::cout, result, context, pipeline.against);
  }
  return 0;
}
