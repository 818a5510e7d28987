// The umvs command line on CLI11 and nlohmann-json: every --help is CLI11's, written from the
// options' declarations with their defaults; bad arguments are refused with the option's name and
// exit status 2 on stderr; --json output parses.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include <filesystem>
#include <map>
#include <string>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/io/array_io.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using test::contains;
using test::Result;
using test::run_umvs;

const std::string kOnlyStdout = "2>/dev/null", kOnlyStderr = "2>&1 >/dev/null";

TEST(CliHelp, EverySubcommandPrintsCli11HelpWithItsDefaults) {
  // Each subcommand with one option as its help must show it: name, value type and default.
  std::map<std::string, std::string> shown = {
      {"bench", "--width INT=640"},              // bound to an int field: INT
      {"eval depth", "--rel-thresholds TEXT=0.01,0.03"},
      {"eval cloud", "--thresholds TEXT=0.002,0.005,0.01"},
      {"fuse", "--window INT=10"},
      {"import middlebury", "--margin NUMBER=0.1"},
      {"import rgbd", "--num-depth INT=192"},  // an integer field: INT
      {"infer", "--device TEXT=cpu"},
      {"render", "--height NUMBER=480"},
      {"synth", "--scene TEXT=room"},
      {"train", "--steps INT=10000"},           // bound to an int field: INT
  };
#ifdef UMVS_HAVE_ROS
  shown["bag"] = "--rate NUMBER=2";
#endif
  for (const auto& [command, option] : shown) {
    const Result r = run_umvs(command + " --help", kOnlyStdout);
    EXPECT_EQ(r.status, 0) << command << ": " << r.output;
    EXPECT_TRUE(contains(r.output, "Usage: umvs " + command + " [OPTIONS]")) << command << ": " << r.output;
    EXPECT_TRUE(contains(r.output, "Options:\n  -h,--help")) << command << ": " << r.output;
    EXPECT_TRUE(contains(r.output, option)) << command << ": " << r.output;
    EXPECT_EQ(run_umvs(command + " -h").output, r.output) << command;
  }
  // The required options say so.
  EXPECT_TRUE(contains(run_umvs("infer --help").output, "--checkpoint TEXT REQUIRED"));
}

TEST(CliHelp, CommandListsAreCli11Subcommands) {
  const Result top = run_umvs("--help");
  EXPECT_EQ(top.status, 0) << top.output;
  EXPECT_TRUE(contains(top.output, "Usage: umvs [OPTIONS] SUBCOMMAND")) << top.output;
  for (const std::string command : {"bench", "eval", "fuse", "import", "infer", "render", "synth", "train"}) {
    EXPECT_TRUE(contains(top.output, "\n  " + command + " ")) << command << " not listed: " << top.output;
  }
  EXPECT_EQ(run_umvs("").status, 2);  // no command: the list, as a usage error
  const Result eval = run_umvs("eval --help");
  EXPECT_EQ(eval.status, 0);
  EXPECT_TRUE(contains(eval.output, "Subcommands:") && contains(eval.output, "\n  depth ") && contains(eval.output, "\n  cloud "))
      << eval.output;
  const Result import = run_umvs("import --help");
  EXPECT_EQ(import.status, 0);
  EXPECT_TRUE(contains(import.output, "\n  middlebury ") && contains(import.output, "\n  rgbd ")) << import.output;
}

TEST(CliErrors, BadArgumentsAreRefusedOnStderrNamingTheOption) {
  const std::string out = test::temp_dir("cli_errors") + "/run";
  struct Case {
    std::string args, named;
  };
  for (const auto& c : {
           Case{"train --steps abc --out " + out, "--steps"},       // not a number: refused by CLI11
           Case{"train --steps=abc --out " + out, "--steps"},       // the same in the --opt=value form
           Case{"train --steps 1.5 --out " + out, "--steps"},       // a number, but not an integer
           Case{"train --frobnicate 3 --out " + out, "--frobnicate"},  // unknown option
           Case{"bench --runs", "--runs"},                          // missing value
           Case{"render --cloud a.ply", "--out"},                   // missing required option
           Case{"fuse --depth d --out o.ply --min-agreeing-views many", "--min-agreeing-views"},  // bound to a FusionConfig int
       }) {
    const Result r = run_umvs(c.args, kOnlyStderr);
    EXPECT_EQ(r.status, 2) << c.args << ": " << r.output;
    EXPECT_TRUE(contains(r.output, c.named)) << c.args << ": " << r.output;
    EXPECT_TRUE(contains(r.output, "error")) << c.args << ": " << r.output;
  }
  EXPECT_FALSE(fs::exists(out)) << "a refused call created its output folder";
}

TEST(CliErrors, TheMessageNamesTheRealProblem) {
  const std::string data = test::scene("cli_errors_data");
  struct Case {
    std::string args, says;
  };
  for (const auto& c : {
           // A misspelt option is named (with what it resembles), not the required one it hides.
           Case{"infer --dta x --out o", "unknown option --dta (did you mean --data?)"},
           Case{"fuse --depth d --out o.ply --threads abc", "needs an integer, got 'abc'"},
           Case{"fuse --depth d --out o.ply --min-confidence high", "needs a number, got 'high'"},
           Case{"fuse --depth d --out o.bt --octomap-extent a,b", "--octomap-extent needs xmin,ymin,zmin,xmax,ymax,zmax"},
           Case{"fuse --depth d --out o.ply --bbox 0,0,0,1,1,1m", "--bbox needs xmin,ymin,zmin,xmax,ymax,zmax"},
           Case{"infer --data " + data + " --checkpoint none.pt --ref 99 --out " + test::temp_dir("cli_errors") + "/infer",
                "view 99 is not in " + data + "/pair.txt"},
       }) {
    const Result r = run_umvs(c.args, kOnlyStderr);
    EXPECT_EQ(r.status, 2) << c.args << ": " << r.output;
    EXPECT_TRUE(contains(r.output, c.says)) << c.args << ": " << r.output;
  }
}

TEST(CliJson, BenchPrintsOneJsonObjectThatParses) {
  const Result r =
      run_umvs("bench --case fusion --width=32 --height 24 --sources 1 --runs 2 --warmup 0 --threads 1 --json", kOnlyStdout);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j.at("case"), "fusion");
  EXPECT_EQ(j.at("width"), 32);
  EXPECT_EQ(j.at("height"), 24);
  EXPECT_EQ(j.at("sources"), 1);
  EXPECT_EQ(j.at("runs"), 2);
  EXPECT_TRUE(j.at("points").is_number_unsigned()) << j;
  const double median = j.at("median_s_per_view"), lo = j.at("min_s"), hi = j.at("max_s");
  EXPECT_GT(lo, 0.0);
  EXPECT_LE(lo, median);
  EXPECT_LE(median, hi);
  for (const char* stage : {"ranking", "consistency", "points"}) EXPECT_GE(j.at("stages_median_s_per_view").at(stage), 0.0);
}

// --against times the old one-pass network beside the candidate in the same run.
TEST(CliJson, BenchPipelineAgainstTimesTheOnePassNetworkToo) {
  const std::string model = std::string(UMVS_SOURCE_DIR) + "/models/unsup_mvsnet.pt";
  const std::string common = "bench --case pipeline --checkpoint " + model + " --against " + model +
                             " --fine-planes 8 --first-pass-downscale 2 --fine-resolution 2 --width 256 --height 192"
                             " --runs 1 --warmup 0";
  const Result r = run_umvs(common + " --json", kOnlyStdout);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j.at("case"), "pipeline");
  ASSERT_TRUE(j.contains("against")) << j;
  const auto& against = j.at("against");
  EXPECT_FALSE(against.contains("case") || against.contains("threads") || against.contains("peak_rss_mib")) << against;
  // The fine pass at 1/2 of the input, the one pass at 1/4.
  EXPECT_EQ(j.at("depth_map_width").get<int>(), 2 * against.at("depth_map_width").get<int>()) << j;
  EXPECT_GT(j.at("total_s").at("p90").get<double>(), 0.0);
  EXPECT_GT(against.at("total_s").at("p90").get<double>(), 0.0);
  EXPECT_EQ(against.at("runs"), 1);

  const Result text = run_umvs(common, kOnlyStdout);
  ASSERT_EQ(text.status, 0) << text.output;
  EXPECT_TRUE(contains(text.output, "against (one pass, " + model + ")")) << text.output;
  EXPECT_TRUE(contains(text.output, "image to depth map p90: candidate ")) << text.output;

  const Result wrong_case = run_umvs("bench --case network --against " + model + " --runs 1", kOnlyStderr);
  EXPECT_EQ(wrong_case.status, 2) << wrong_case.output;
  EXPECT_TRUE(contains(wrong_case.output, "--against")) << wrong_case.output;
}

TEST(CliJson, EvalDepthPrintsNullForMetricsWithoutPixels) {
  const std::string gt = test::scene("cli_json_gt");
  const std::string est = test::temp_dir("cli_json_est");
  fs::create_directories(est + "/depth");
  const auto gt_depth = read_pfm(gt + "/depth_gt/00000000.pfm");
  write_pfm(est + "/depth/00000000.pfm", torch::zeros_like(gt_depth));  // no estimate anywhere
  write_pfm(est + "/depth/00000001.pfm", read_pfm(gt + "/depth_gt/00000001.pfm"));  // exact
  const Result r = run_umvs("eval depth --est " + est + " --gt " + gt + " --json", kOnlyStdout);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  ASSERT_EQ(j.at("views").size(), 2u);
  const auto& empty = j["views"][0];
  EXPECT_EQ(empty.at("view"), 0);
  EXPECT_EQ(empty.at("evaluated_pixels"), 0);
  EXPECT_TRUE(empty.at("mae").is_null()) << empty;  // NaN is not JSON
  EXPECT_TRUE(empty.at("rmse").is_null()) << empty;
  const auto& exact = j["views"][1];
  EXPECT_EQ(exact.at("evaluated_pixels"), exact.at("gt_pixels"));
  EXPECT_EQ(exact.at("mae"), 0.0);
  EXPECT_EQ(j.at("rel_thresholds"), nlohmann::json({0.01, 0.03}));
  EXPECT_EQ(j.at("overall").at("evaluated_pixels"), exact.at("gt_pixels"));
}

TEST(CliJson, EvalDepthSplitsErrorsByCovisibility) {
  const std::string gt = test::scene("cli_covis_gt");
  const std::string est = test::temp_dir("cli_covis_est");
  fs::create_directories(est + "/depth");
  for (int id : {0, 1}) {  // 2 % too far on every pixel
    const std::string stem = "/0000000" + std::to_string(id) + ".pfm";
    write_pfm(est + "/depth" + stem, read_pfm(gt + "/depth_gt" + stem) * 1.02);
  }
  const Result r = run_umvs("eval depth --est " + est + " --gt " + gt + " --covisibility-sources 2 --json", kOnlyStdout);
  ASSERT_EQ(r.status, 0) << r.output;
  const auto j = nlohmann::json::parse(r.output);
  EXPECT_EQ(j.at("covisibility_sources"), 2);
  const auto& all = j.at("overall");
  const auto& seen = j.at("seen");
  const auto& unseen = j.at("unseen");
  // Every ground-truth pixel is seen or unseen, and the room's neighbours see most of them.
  EXPECT_EQ(seen.at("gt_pixels").get<int64_t>() + unseen.at("gt_pixels").get<int64_t>(), all.at("gt_pixels").get<int64_t>());
  const double share = all.at("seen_share");
  EXPECT_GT(share, 0.5);
  EXPECT_LT(share, 1.0);
  EXPECT_NEAR(share, seen.at("gt_pixels").get<double>() / all.at("gt_pixels").get<double>(), 1e-9);
  EXPECT_NEAR(seen.at("abs_rel").get<double>(), 0.02, 1e-5);
  EXPECT_NEAR(unseen.at("abs_rel").get<double>(), 0.02, 1e-5);
  ASSERT_EQ(j.at("views").size(), 2u);
  EXPECT_TRUE(j["views"][0].contains("seen")) << j["views"][0];

  const Result no_split = run_umvs("eval depth --est " + est + " --gt " + gt + " --json", kOnlyStdout);
  ASSERT_EQ(no_split.status, 0) << no_split.output;
  EXPECT_FALSE(nlohmann::json::parse(no_split.output).contains("seen"));
  const Result negative = run_umvs("eval depth --est " + est + " --gt " + gt + " --covisibility-sources -1", kOnlyStderr);
  EXPECT_NE(negative.status, 0);
  EXPECT_TRUE(contains(negative.output, "--covisibility-sources")) << negative.output;
}

}  // namespace
}  // namespace umvs
