// The model card's rebuild command (models/README.md): scripts/experiments/
// train_default_model.sh run end to end at a tiny size (one scene per recipe at 96x64, 2 steps), so
// that the command that made models/unsup_mvsnet.pt keeps working: it renders its scenes, imports
// templeRing when ../shared is there, trains and leaves a checkpoint that umvs infer serves.
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <filesystem>
#include <string>

#include "cli_test_util.h"
#include "unsup_mvs/io/checkpoint.h"

namespace umvs {
namespace {

// Runs the script at a tiny size with `environment` added; returns the work folder.
std::string rebuild_at_a_tiny_size(const std::string& name, const std::string& environment) {
  const std::string work = test::temp_dir(name);
  const test::Result r = test::run_shell(
      "STEPS=2 SCENES_PER_RECIPE=1 TEXTURES=none RENDER_WIDTH=96 RENDER_HEIGHT=64 WIDTH=96 HEIGHT=64 " + environment +
      " THREADS=2 UMVS=" + test::umvs_binary() + " bash " + UMVS_SOURCE_DIR + "/scripts/experiments/train_default_model.sh " +
      work);
  EXPECT_EQ(r.status, 0) << r.output;
  return work;
}

TEST(ModelCard, TheRebuildScriptTrainsAServableModelAtATinySize) {
  const std::string work = rebuild_at_a_tiny_size("model_card", "NUM_DEPTH=8");
  const LoadedModel model = load_model(work + "/run/last.pt", torch::kCPU);
  EXPECT_EQ(model.meta.step, 2);
  // A held-out scene of the run (heldout.txt: comma-separated folders).
  std::string scene = test::file_bytes(work + "/data/rendered/heldout.txt");
  scene = scene.substr(0, scene.find_first_of(",\n"));
  const test::Result infer = test::run_umvs("infer --data " + scene + " --checkpoint " + work + "/run/last.pt --ref 0 --threads 2 --out " + work + "/infer");
  EXPECT_EQ(infer.status, 0) << infer.output;
  EXPECT_TRUE(std::filesystem::exists(work + "/infer/depth_est/00000000.pfm")) << infer.output;
}

// The CPU network's recipe: a new sweep2d model, and with ../shared the first frames of the HoloLens
// video trained on photometrically, imported at the fixed range and without their depth.
TEST(ModelCard, TheRebuildScriptTrainsTheCpuNetworkOnRealVideoWithoutItsDepth) {
  const bool real = !test::shared_data_dir().empty();
  const std::string work = rebuild_at_a_tiny_size(
      "model_card_sweep", std::string("NETWORK=sweep2d NUM_DEPTH=16 SHARED=") + (real ? test::shared_data_dir() : "/none") +
                              (real ? " REAL_VIDEOS=hololens REAL_VIDEO_FRAMES=10" : ""));
  const LoadedModel model = load_model(work + "/run/last.pt", torch::kCPU);
  EXPECT_EQ(model.meta.step, 2);
  EXPECT_EQ(model.model->config().network, NetworkKind::kSweep2d);
  EXPECT_EQ(model.model->config().num_depth, 16);
  if (!real) GTEST_SKIP() << "../shared/data absent: the real video part was not run";
  EXPECT_TRUE(std::filesystem::exists(work + "/data/hololens/pair.txt"));
  EXPECT_FALSE(std::filesystem::exists(work + "/data/hololens/depth_gt"));
  const std::string record = test::file_bytes(work + "/run/run_config.json");
  EXPECT_NE(record.find(work + "/data/hololens"), std::string::npos) << record;
}

}  // namespace
}  // namespace umvs
