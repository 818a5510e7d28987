// core/weight_blend.h (blend_weights) and `umvs train --fine-tuned-share`: the blend is the
// weighted mean of every parameter and BatchNorm statistic, a refused blend changes nothing, and a
// run writes blended.pt from its best.pt and its --init.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <cmath>
#include <filesystem>
#include <limits>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/core/weight_blend.h"
#include "unsup_mvs/io/checkpoint.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using testing::HasSubstr;
using testing::ThrowsMessage;

MvsNet small_model(uint64_t seed, bool refine = false) {
  torch::manual_seed(seed);
  MvsNetConfig cfg;
  cfg.num_depth = 8;
  cfg.refine = refine;
  MvsNet net(cfg);
  // BatchNorm's scales, shifts and running statistics start at 1 and 0 in every model: give them
  // values of their own, as training would, so that every tensor's blend is tested.
  torch::NoGradGuard no_grad;
  for (auto& p : net->parameters()) p.add_(0.1 * torch::randn_like(p));
  for (auto& b : net->named_buffers()) {
    if (b.value().is_floating_point()) b.value().uniform_(0.5, 2.0);
    else b.value().fill_(static_cast<int64_t>(seed));  // num_batches_tracked
  }
  return net;
}

std::vector<torch::Tensor> copies(const torch::OrderedDict<std::string, torch::Tensor>& d) {
  std::vector<torch::Tensor> out;
  for (const auto& item : d) out.push_back(item.value().clone());
  return out;
}

TEST(BlendWeights, EveryParameterAndStatisticIsTheWeightedMeanAndCountersStay) {
  MvsNet adapted = small_model(1), start = small_model(2);
  const auto a_params = copies(adapted->named_parameters()), a_buffers = copies(adapted->named_buffers());
  const auto s_params = copies(start->named_parameters()), s_buffers = copies(start->named_buffers());
  blend_weights(adapted, start, 0.25);

  const auto params = adapted->named_parameters();
  ASSERT_EQ(params.size(), a_params.size());
  for (size_t i = 0; i < params.size(); ++i) {
    const auto expected = 0.25 * a_params[i] + 0.75 * s_params[i];
    EXPECT_TRUE(torch::allclose(params[i].value(), expected, 1e-6, 1e-7)) << params[i].key();
    EXPECT_FALSE(torch::equal(params[i].value(), a_params[i])) << params[i].key() << " did not change";
  }
  const auto buffers = adapted->named_buffers();
  int statistics = 0, counters = 0;
  for (size_t i = 0; i < buffers.size(); ++i) {
    if (buffers[i].value().is_floating_point()) {
      EXPECT_TRUE(torch::allclose(buffers[i].value(), 0.25 * a_buffers[i] + 0.75 * s_buffers[i], 1e-6, 1e-7))
          << buffers[i].key();
      ++statistics;
    } else {
      EXPECT_TRUE(torch::equal(buffers[i].value(), a_buffers[i])) << buffers[i].key() << ": a counter is not blended";
      ++counters;
    }
  }
  EXPECT_GT(statistics, 0);
  EXPECT_GT(counters, 0);
  // The starting model is only read.
  const auto start_params = start->named_parameters();
  for (size_t i = 0; i < start_params.size(); ++i) EXPECT_TRUE(torch::equal(start_params[i].value(), s_params[i]));
}

TEST(BlendWeights, ShareOneKeepsTheModelAndShareZeroGivesTheStart) {
  MvsNet adapted = small_model(1), start = small_model(2), same = small_model(1);
  const auto original = adapted->named_parameters();
  const auto kept = copies(original);
  blend_weights(adapted, start, 1.0);
  for (size_t i = 0; i < original.size(); ++i) EXPECT_TRUE(torch::equal(original[i].value(), kept[i])) << original[i].key();
  blend_weights(same, same, 0.3);  // with itself: itself
  const auto same_params = same->named_parameters();
  for (size_t i = 0; i < same_params.size(); ++i) {
    EXPECT_TRUE(torch::equal(same_params[i].value(), kept[i])) << same_params[i].key();
  }
  blend_weights(adapted, start, 0.0);
  for (const auto& p : adapted->named_parameters()) {
    EXPECT_TRUE(torch::equal(p.value(), start->named_parameters()[p.key()])) << p.key();
  }
}

TEST(BlendWeights, AnotherArchitectureOrShareIsRefusedAndTheModelStaysAsItWas) {
  MvsNet adapted = small_model(1), refined = small_model(2, /*refine=*/true);
  const auto before = copies(adapted->named_parameters());
  EXPECT_THAT([&] { blend_weights(adapted, refined, 0.5); },
              ThrowsMessage<std::invalid_argument>(HasSubstr("not the same architecture")));
  for (double bad : {-0.1, 1.5, std::numeric_limits<double>::quiet_NaN()}) {
    EXPECT_THAT([&] { blend_weights(adapted, adapted, bad); },
                ThrowsMessage<std::invalid_argument>(HasSubstr("must be in [0, 1]")));
  }
  const auto after = adapted->named_parameters();
  for (size_t i = 0; i < after.size(); ++i) EXPECT_TRUE(torch::equal(after[i].value(), before[i])) << after[i].key();
}

TEST(TrainFineTunedShare, ARunWritesTheBlendOfItsBestModelAndItsInit) {
  const std::string data = test::scene("blend_data");
  const std::string dir = test::temp_dir("blend_run");
  MvsNet init = small_model(3);
  save_checkpoint(dir + "/init.pt", init);
  const std::string common = "train --data " + data + " --width 96 --height 64 --num-depth 8 --views-loss 3 --top-k 2 "
                             "--threads 1 --steps 2 --save-every 2 --init " + dir + "/init.pt";

  // Without --init a blend has nothing to blend with; a share outside (0, 1] is refused. Nothing is written.
  const test::Result no_init = test::run_umvs("train --data " + data + " --width 96 --height 64 --num-depth 8 "
                                              "--views-loss 3 --top-k 2 --steps 2 --fine-tuned-share 0.5 --out " + dir + "/a");
  EXPECT_EQ(no_init.status, 2) << no_init.output;
  EXPECT_TRUE(test::contains(no_init.output, "--fine-tuned-share blends best.pt with the model the run starts from: "
                                               "give --init")) << no_init.output;
  const test::Result zero = test::run_umvs(common + " --fine-tuned-share 0 --out " + dir + "/b");
  EXPECT_EQ(zero.status, 2) << zero.output;
  EXPECT_TRUE(test::contains(zero.output, "--fine-tuned-share must be in (0, 1] (1 = no blend), got 0")) << zero.output;
  EXPECT_FALSE(fs::exists(dir + "/a") || fs::exists(dir + "/b"));

  const test::Result r = test::run_umvs(common + " --fine-tuned-share 0.5 --out " + dir + "/run");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_TRUE(test::contains(r.output, dir + "/run/blended.pt")) << r.output;
  LoadedModel best = load_model(dir + "/run/best.pt", torch::kCPU);
  LoadedModel blended = load_model(dir + "/run/blended.pt", torch::kCPU);
  int changed = 0;
  for (const auto& p : blended.model->named_parameters()) {
    const torch::Tensor b = best.model->named_parameters()[p.key()];
    const torch::Tensor s = init->named_parameters()[p.key()];
    EXPECT_TRUE(torch::allclose(p.value(), 0.5 * b + 0.5 * s, 1e-6, 1e-7)) << p.key();
    changed += !torch::equal(b, s);
  }
  EXPECT_GT(changed, 0) << "two steps changed no weight: the test proves nothing";
  EXPECT_TRUE(blended.meta.optimizer_state.empty()) << "the blend carries best.pt's optimiser state";

  // Without the option no blend is written (the default), and replacing the run leaves no blend of
  // the old one behind.
  ASSERT_EQ(test::run_umvs(common + " --out " + dir + "/plain").status, 0);
  EXPECT_FALSE(fs::exists(dir + "/plain/blended.pt"));
  ASSERT_EQ(test::run_umvs(common + " --overwrite --out " + dir + "/run").status, 0);
  EXPECT_TRUE(fs::exists(dir + "/run/best.pt"));
  EXPECT_FALSE(fs::exists(dir + "/run/blended.pt")) << "--overwrite kept the replaced run's blend";
}

}  // namespace
}  // namespace umvs
