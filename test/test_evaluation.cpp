// Scoring an estimate folder against ground truth (io/evaluation.h) without the command line.
#include <gtest/gtest.h>
#include <torch/types.h>

#include <filesystem>
#include <sstream>

#include "test_util.h"
#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/evaluation.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;

// Two views of 8x8 ground truth (1..2 m) and an estimate 10 % too far, with confidence 0.9 on the
// left half and 0.1 on the right half, where the estimate is 40 % too far instead.
struct Folders {
  std::string gt, est;
};
Folders write_folders(const std::string& name) {
  Folders f{test::temp_dir(name + "_gt"), test::temp_dir(name + "_est")};
  for (const auto& d : {f.gt + "/depth_gt", f.est + "/depth_est", f.est + "/confidence"}) fs::create_directories(d);
  for (int id : {0, 1}) {
    const auto gt = torch::linspace(1.0, 2.0, 64, torch::kFloat32).reshape({8, 8}) + 0.1 * id;
    auto est = gt * 1.1;
    est.slice(1, 4, 8) = gt.slice(1, 4, 8) * 1.4;
    auto conf = torch::full({8, 8}, 0.9f);
    conf.slice(1, 4, 8).fill_(0.1f);
    const std::string stem = "0000000" + std::to_string(id);
    write_pfm(f.gt + "/depth_gt/" + stem + ".pfm", gt);
    write_pfm(f.est + "/depth_est/" + stem + ".pfm", est);
    write_pfm(f.est + "/confidence/" + stem + ".pfm", conf);
  }
  return f;
}

TEST(DepthFolderEvaluation, ScoresEveryViewAndTheirSum) {
  const auto f = write_folders("eval_every_view");
  DepthFolderEvalOptions options;
  options.metrics.rel_thresholds = {0.2};
  const auto eval = evaluate_depth_folder(f.est, f.gt, options);
  EXPECT_EQ(eval.est_dir, f.est + "/depth_est");
  ASSERT_EQ(eval.views, (std::vector<int>{0, 1}));
  for (const auto& m : eval.per_view) {
    EXPECT_EQ(m.gt_pixels, 64);
    EXPECT_NEAR(m.abs_rel, 0.25, 1e-5);  // half at 0.1, half at 0.4
    EXPECT_NEAR(m.within_rel[0], 0.5, 1e-9);
  }
  EXPECT_EQ(eval.overall.evaluated_pixels, 128);
  EXPECT_NEAR(eval.overall.abs_rel, 0.25, 1e-5);
  EXPECT_FALSE(eval.split());

  options.min_confidence = 0.5;  // only the left halves count
  const auto confident = evaluate_depth_folder(f.est, f.gt, options);
  EXPECT_EQ(confident.overall.evaluated_pixels, 64);
  EXPECT_NEAR(confident.overall.abs_rel, 0.1, 1e-5);
  EXPECT_NEAR(confident.overall.completeness(), 0.5, 1e-9);

  options.min_confidence = 0;
  options.views = {1};
  EXPECT_EQ(evaluate_depth_folder(f.est, f.gt, options).per_view.size(), 1u);
}

TEST(DepthFolderEvaluation, JudgesAConfidenceThatRanksWell) {
  const auto f = write_folders("eval_sparsification");
  DepthFolderEvalOptions options;
  options.sparsification = true;
  options.confidence_levels = {0.5};
  options.confident_within = 0.15;
  const auto eval = evaluate_depth_folder(f.est, f.gt, options);
  ASSERT_EQ(eval.confident.size(), 1u);
  EXPECT_NEAR(eval.confident[0].image_share(), 0.5, 1e-9);
  EXPECT_NEAR(eval.confident[0].abs_rel, 0.1, 1e-5);
  EXPECT_NEAR(eval.confident[0].within, 1.0, 1e-9);
  EXPECT_NEAR(eval.curve.ause, 0.0, 1e-5);  // the confident half is the half of least error

  const auto json = to_json(eval, options);
  EXPECT_NEAR(json["overall"]["abs_rel"].get<double>(), 0.25, 1e-5);
  EXPECT_NEAR(json["confident"][0]["within"].get<double>(), 1.0, 1e-9);
  std::ostringstream table;
  print_table(table, eval, options, f.gt);
  EXPECT_NE(table.str().find("AUSE 0.0000"), std::string::npos) << table.str();
  EXPECT_NE(table.str().find(" overall "), std::string::npos) << table.str();
}

TEST(DepthFolderEvaluation, RefusesWhatItCannotScoreNamingTheFile) {
  const auto f = write_folders("eval_refusals");
  const auto message = [&](DepthFolderEvalOptions options) {
    try {
      evaluate_depth_folder(f.est, f.gt, options);
    } catch (const std::exception& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  DepthFolderEvalOptions options;
  options.views = {0, 7};
  EXPECT_NE(message(options).find("no estimate " + f.est + "/depth_est/00000007.pfm"), std::string::npos);
  fs::remove(f.est + "/confidence/00000001.pfm");
  options.views = {};
  options.sparsification = true;
  EXPECT_NE(message(options).find("--sparsification needs the confidence maps"), std::string::npos);
  options.sparsification = false;
  options.covisibility_sources = 2;
  EXPECT_NE(message(options).find("--covisibility-sources needs " + f.gt + "/pair.txt"), std::string::npos);
  options.covisibility_sources = 0;
  options.max_turn_deg = -1;
  EXPECT_NE(message(options).find("--max-turn-deg must be an angle >= 0"), std::string::npos);
}

}  // namespace
}  // namespace umvs
