// The benchmarks of `umvs bench` as library calls (jobs/bench.h), at sizes a test can afford.
#include <gtest/gtest.h>
#include <torch/types.h>

#include <sstream>

#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/core/sweep_net.h"
#include "unsup_mvs/jobs/bench.h"

namespace umvs {
namespace {

TEST(Bench, SummarizeTakesTheMiddleOfTheSortedRuns) {
  const auto odd = summarize({0.3, 0.1, 0.2});
  EXPECT_EQ(odd.runs, 3);
  EXPECT_DOUBLE_EQ(odd.median, 0.2);
  EXPECT_DOUBLE_EQ(odd.min, 0.1);
  EXPECT_DOUBLE_EQ(odd.max, 0.3);
  EXPECT_DOUBLE_EQ(summarize({0.4, 0.1, 0.2, 0.3}).median, 0.25);
  EXPECT_EQ(summarize({}).runs, 0);
}

TEST(Bench, NetworkTimesBothPathsAndCountsTheNetworksWork) {
  NetworkBenchOptions options;
  options.width = 64;
  options.height = 32;
  options.views = 2;
  options.num_depth = 8;
  options.path = "both";
  options.runs = {2, 0};
  const auto r = bench_network(options, torch::kCPU);
  EXPECT_EQ(r.stats.runs, 2);
  ASSERT_TRUE(r.autograd.has_value());
  EXPECT_EQ(r.autograd->runs, 2);
  EXPECT_EQ(r.num_depth, 8);
  EXPECT_EQ(r.regularizer, "3-D U-Net");
  EXPECT_DOUBLE_EQ(r.gflop, mvsnet_forward_flops(32, 64, 8, 2) / 1e9);
  EXPECT_TRUE(r.have_stages);
  EXPECT_GT(r.features, 0.0);
  EXPECT_GT(r.regularization, 0.0);
  EXPECT_LE(r.stats.min, r.stats.median);

  const auto json = to_json(r, {2, "cpu", true});
  EXPECT_EQ(json.at("case"), "network");
  EXPECT_DOUBLE_EQ(json.at("autograd_over_fast").get<double>(), r.autograd->median / r.stats.median);
  std::ostringstream text;
  print_text(text, r, {2, "cpu", false});
  EXPECT_NE(text.str().find("mvsnet 64x32 D=8 V=2 device=cpu threads=2 path=fast (untuned)"), std::string::npos) << text.str();

  options.network = "sweep2d";
  options.views = 3;
  options.num_depth = 16;
  options.path = "fast";
  const auto sweep = bench_network(options, torch::kCPU);
  EXPECT_EQ(sweep.regularizer, "2-D encoder-decoder");
  EXPECT_DOUBLE_EQ(sweep.gflop, sweep_net_forward_flops(32, 64, 16, 3) / 1e9);
  EXPECT_FALSE(sweep.autograd.has_value());

  options.path = "fastest";
  EXPECT_THROW(bench_network(options, torch::kCPU), std::invalid_argument);
}

TEST(Bench, FusionFusesEveryViewOfThePlane) {
  FusionBenchOptions options;
  options.width = 32;
  options.height = 24;
  options.sources = 3;  // fusion's default needs 3 agreeing sources
  options.runs = {2, 0};
  const auto r = bench_fusion(options, torch::kCPU);
  EXPECT_EQ(r.views, 4);
  EXPECT_EQ(r.per_view.runs, 2);
  // The plane fills every image, so most pixels of every view agree with another view.
  EXPECT_GT(r.points, size_t{32 * 24});
  EXPECT_LE(r.points, size_t{4 * 32 * 24});
  EXPECT_GT(r.points_per_s, 0.0);
  EXPECT_EQ(to_json(r, {1, "cpu", true}).at("points").get<size_t>(), r.points);

  options.sources = 0;
  EXPECT_THROW(bench_fusion(options, torch::kCPU), std::invalid_argument);
}

TEST(Bench, PipelineNeedsATrainedModel) {
  PipelineBenchOptions options;
  try {
    bench_pipeline(options, torch::kCPU);
    FAIL() << "no checkpoint accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("give --checkpoint"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace umvs
