// The CPU network (core/sweep_net.h, MvsNetConfig::network = sweep2d): its cost volume against
// exact geometry, its shapes and gradients, its checkpoint, and its place in the depth estimator
// and the trainer (maps at 1/2 of the input).
#include <gtest/gtest.h>
#include <torch/torch.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "cli_test_util.h"
#include "test_util.h"
#include "training_test_fixtures.h"
#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/core/sweep_net.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/training_data.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {
namespace {

Camera pinhole(int width, int height, double focal, const Eigen::Vector3d& centre) {
  Camera c;
  c.width = width;
  c.height = height;
  c.K << focal, 0, width / 2.0, 0, focal, height / 2.0, 0, 0, 1;
  c.T_cam_world.topRightCorner<3, 1>() = -centre;
  return c;
}

MvsNet sweep_model(int planes = 16) {
  MvsNetConfig cfg;
  cfg.network = NetworkKind::kSweep2d;
  cfg.num_depth = planes;
  cfg.depth_sampling = DepthSampling::kUniformInverseDepth;
  return MvsNet(cfg);
}

// With the source camera on the reference's, every plane warps the source onto the reference:
// each plane's cost is the cosine of a feature with itself, 1.
TEST(SweepNet, CostOfAViewWithItselfIsOneOnEveryPlane) {
  torch::manual_seed(3);
  const Camera cam = pinhole(64, 48, 40.0, Eigen::Vector3d::Zero());
  const auto f = torch::randn({1, 1, 8, 12, 16}).repeat({1, 2, 1, 1, 1});  // reference == source
  const auto proj = mvsnet_projection_matrices({cam, cam}).unsqueeze(0);
  const auto planes = depth_hypotheses(1.0, 5.0, 8, DepthSampling::kUniformInverseDepth).unsqueeze(0);
  const auto cost = cosine_cost_volume(f, proj, planes, FeatureWarp::kExact);
  ASSERT_EQ(cost.sizes(), (std::vector<int64_t>{1, 8, 12, 16}));
  EXPECT_NEAR(cost.min().item<double>(), 1.0, 1e-4);
  EXPECT_NEAR(cost.max().item<double>(), 1.0, 1e-4);
}

// A fronto-parallel plane at 2 m seen by a source 0.1 m to the right: at feature resolution (focal
// 80 px) the source sees every reference feature shifted by f b / d = 4 pixels. The best plane of
// every pixel the source sees is the one at 2 m, at a cosine of 1; a plane two steps off is far below.
TEST(SweepNet, CostPeaksAtThePlaneOfTheTrueDepth) {
  torch::manual_seed(4);
  const double focal = 320.0, baseline = 0.1, depth = 2.0;  // image focal; features at 1/4: 80 px
  const Camera ref = pinhole(256, 128, focal, Eigen::Vector3d::Zero());
  const Camera src = pinhole(256, 128, focal, Eigen::Vector3d(baseline, 0, 0));
  const int shift = static_cast<int>(focal / 4 * baseline / depth);  // 4 feature pixels
  ASSERT_EQ(shift, 4);
  const auto reference = torch::randn({1, 16, 32, 64});
  // src(u) = ref(u + shift): the point at reference column u + shift lies at source column u.
  auto source = torch::zeros_like(reference);
  source.slice(3, 0, 64 - shift).copy_(reference.slice(3, shift, 64));
  const auto features = torch::stack({reference, source}, 1);
  const auto proj = mvsnet_projection_matrices({ref, src}).unsqueeze(0);
  // Planes in inverse depth with 2 m on plane 5 exactly: 1/d = 0.1 + 0.08 k.
  std::vector<float> values;
  for (int k = 0; k < 12; ++k) values.push_back(static_cast<float>(1.0 / (0.9 - 0.08 * k)));
  ASSERT_NEAR(values[5], 2.0, 1e-5);
  const auto planes = torch::tensor(values).unsqueeze(0);
  const auto cost = cosine_cost_volume(features, proj, planes, FeatureWarp::kExact);
  // Interior pixels (the source sees them at every plane's shift within the image).
  const auto inner = cost.slice(3, 8, 48);
  const auto best = inner.argmax(1);
  EXPECT_EQ((best == 5).all().item<bool>(), true);
  EXPECT_NEAR(inner.select(1, 5).mean().item<double>(), 1.0, 1e-4);
  EXPECT_LT(inner.select(1, 3).mean().item<double>(), 0.5);
}

// The inference path (no autograd, CPU) against the torch ops that training differentiates, on
// random features and cameras whose views partly leave the image.
TEST(SweepNet, InferenceCostVolumeMatchesTheAutogradOne) {
  torch::manual_seed(9);
  std::vector<Camera> cams = {pinhole(128, 96, 100.0, Eigen::Vector3d::Zero()),
                              pinhole(128, 96, 100.0, Eigen::Vector3d(0.3, 0.05, 0)),
                              pinhole(128, 96, 100.0, Eigen::Vector3d(-0.2, -0.1, 0.1))};
  cams[2].T_cam_world.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const auto features = torch::randn({2, 3, 16, 24, 32});
  const auto proj = mvsnet_projection_matrices(cams).unsqueeze(0).repeat({2, 1, 1, 1});
  const auto planes = depth_hypotheses(0.5, 8.0, 24, DepthSampling::kUniformInverseDepth).unsqueeze(0).repeat({2, 1});
  for (const FeatureWarp warp : {FeatureWarp::kExact, FeatureWarp::kMvsNetPytorch}) {
    torch::Tensor with_grad, fast;
    {
      torch::AutoGradMode grad(true);
      with_grad = cosine_cost_volume(features.clone().requires_grad_(), proj, planes, warp).detach();
    }
    {
      torch::NoGradGuard no_grad;
      fast = cosine_cost_volume(features, proj, planes, warp);
    }
    ASSERT_EQ(fast.sizes(), with_grad.sizes());
    EXPECT_LT((fast - with_grad).abs().max().item<double>(), 1e-5);
    EXPECT_GT((with_grad == 0).to(torch::kFloat32).mean().item<double>(), 0.01);  // some samples fell outside
    EXPECT_GT(with_grad.abs().mean().item<double>(), 0.05);
  }
}

TEST(SweepNet, MapsAtHalfTheInputWithGradientsEverywhere) {
  torch::manual_seed(5);
  MvsNet net = sweep_model(16);
  net->train();
  const Camera a = pinhole(96, 64, 80.0, Eigen::Vector3d::Zero());
  const Camera b = pinhole(96, 64, 80.0, Eigen::Vector3d(0.1, 0, 0));
  const Camera c = pinhole(96, 64, 80.0, Eigen::Vector3d(-0.1, 0.02, 0));
  const auto images = torch::rand({2, 3, 3, 64, 96});
  const auto proj = mvsnet_projection_matrices({a, b, c}).unsqueeze(0).repeat({2, 1, 1, 1});
  const auto planes = depth_hypotheses(0.5, 6.0, 16, DepthSampling::kUniformInverseDepth).unsqueeze(0).repeat({2, 1});
  const MvsOutput out = net->forward(images, proj, planes, /*keep_prob_volume=*/true);
  ASSERT_EQ(out.depth.sizes(), (std::vector<int64_t>{2, 32, 48}));
  ASSERT_EQ(out.prob_volume.sizes(), (std::vector<int64_t>{2, 16, 32, 48}));
  EXPECT_GE(out.depth.min().item<double>(), 0.5 - 1e-4);
  EXPECT_LE(out.depth.max().item<double>(), 6.0 + 1e-4);
  EXPECT_GE(out.confidence.min().item<double>(), 0.0);
  EXPECT_LE(out.confidence.max().item<double>(), 1.0 + 1e-5);
  out.depth.mean().backward();
  for (const auto& p : net->named_parameters()) {
    ASSERT_TRUE(p.value().grad().defined()) << p.key();
    EXPECT_GT(p.value().grad().abs().sum().item<double>(), 0.0) << p.key();
  }
  // Another plane count is refused by name: the weights fix it.
  const auto eight = depth_hypotheses(0.5, 6.0, 8, DepthSampling::kUniformInverseDepth).unsqueeze(0).repeat({2, 1});
  try {
    net->forward(images, proj, eight);
    FAIL() << "8 planes accepted by a 16-plane network";
  } catch (const c10::Error& e) {
    EXPECT_NE(std::string(e.what()).find("trained for 16 planes"), std::string::npos) << e.what();
  }
  EXPECT_THROW(net->set_num_depth(32), std::invalid_argument);
}

TEST(SweepNet, CheckpointSelectsTheNetwork) {
  torch::manual_seed(6);
  MvsNet net = sweep_model(24);
  const std::string path = test::temp_dir("sweep_checkpoint") + "/sweep.pt";
  save_checkpoint(path, net);
  LoadedModel loaded = load_model(path, torch::kCPU);
  EXPECT_EQ(loaded.model->config().network, NetworkKind::kSweep2d);
  EXPECT_EQ(loaded.model->config().num_depth, 24);
  EXPECT_EQ(loaded.model->config().map_divisor(), 2);
  EXPECT_FALSE(loaded.model->cost_regularization);
  net->eval();
  const Camera a = pinhole(64, 64, 60.0, Eigen::Vector3d::Zero());
  const Camera b = pinhole(64, 64, 60.0, Eigen::Vector3d(0.1, 0, 0));
  const auto images = torch::rand({1, 2, 3, 64, 64});
  const auto proj = mvsnet_projection_matrices({a, b}).unsqueeze(0);
  const auto planes = depth_hypotheses(0.5, 4.0, 24, DepthSampling::kUniformInverseDepth).unsqueeze(0);
  torch::NoGradGuard no_grad;
  EXPECT_TRUE(torch::equal(net->forward(images, proj, planes).depth, loaded.model->forward(images, proj, planes).depth));
  // Asked for MVSNet, the file says what it holds.
  const MvsNetConfig mvsnet;
  try {
    load_model(path, torch::kCPU, &mvsnet);
    FAIL() << "a sweep2d checkpoint loaded as MVSNet";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("network: mvsnet here, sweep2d"), std::string::npos) << e.what();
  }
}

TEST(SweepNet, EstimatorGivesHalfResolutionMapsAndRefusesWhatItCannotRun) {
  torch::manual_seed(7);
  const std::string room = test::write_room("sweep_estimator", 7, true, 128, 96, 3);
  const MvsFolder folder(room);
  const test::PairInput input = test::pair_input(folder, 0, 2, 16);
  DepthEstimator estimator(sweep_model(16), torch::kCPU);
  EXPECT_EQ(estimator.num_depth(), 16);
  const DepthMap map = estimator.estimate(input.views, input.depth_min, input.depth_max);
  EXPECT_EQ(map.depth.sizes(), (std::vector<int64_t>{48, 64}));
  EXPECT_EQ(map.camera.width, 64);
  EXPECT_EQ(map.camera.height, 48);
  EXPECT_DOUBLE_EQ(map.camera.K(0, 0), map.network_camera.K(0, 0) / 2);
  EXPECT_EQ(map.color.sizes(), (std::vector<int64_t>{48, 64, 3}));
  DepthEstimatorConfig other_planes;
  other_planes.num_depth = 32;
  EXPECT_THROW(DepthEstimator(sweep_model(16), torch::kCPU, other_planes), std::invalid_argument);
  DepthEstimatorConfig fine;
  fine.fine.planes = 8;
  EXPECT_THROW(DepthEstimator(sweep_model(16), torch::kCPU, fine), std::invalid_argument);
}

// The trainer takes the loss on the network's own grid: a few steps on one rendered tuple lower
// its photometric loss.
TEST(SweepNet, TrainerLearnsOnTheHalfResolutionGrid) {
  torch::manual_seed(8);
  const std::string room = test::write_scene("sweep_trainer", 128, 96, 4);
  TupleConfig tuples_cfg = test::room_tuples(3);
  tuples_cfg.num_depth = 16;
  const auto tuples = fixed_tuples(MvsFolderSource({room}, tuples_cfg), 0);  // all, unaugmented
  ASSERT_FALSE(tuples.empty());
  TrainerConfig cfg;
  cfg.num_depth = 16;
  cfg.lr = 1e-3;
  Trainer trainer(sweep_model(16), torch::kCPU, cfg);
  const std::vector<TrainingTuple> one = {tuples.front()};
  const double before = trainer.evaluate(one).loss.total;
  for (int i = 0; i < 12; ++i) trainer.step(one);
  const double after = trainer.evaluate(one).loss.total;
  EXPECT_LT(after, before);
  const auto b = make_training_batch(one, 16, DepthSampling::kUniformInverseDepth, torch::kCPU,
                                     cfg.map_divisor(trainer.model()->config()));
  EXPECT_EQ(b.loss_ref.size(2), 48);  // 96 / 2
}

}  // namespace
}  // namespace umvs

namespace umvs {
namespace {

// `umvs train --network sweep2d`: a new model records its network and planes (64 by default, in
// inverse depth), resumes bit for bit, and a run from it trains with its planes; what it cannot run
// is refused.
TEST(SweepNetTraining, NewRunResumesAndInitKeepsThePlanes) {
  const std::string data = test::write_scene("sweep_cli", 96, 64, 5, 2);
  const std::string out = test::temp_dir("sweep_cli_out");
  const std::string common = "--data " + data + " --width 96 --height 64 --views-loss 3 --top-k 2 --threads 1 --save-every 2";
  ASSERT_EQ(test::run(common + " --network sweep2d --out " + out + "/a --steps 4"), 0);
  ASSERT_EQ(test::run(common + " --network sweep2d --out " + out + "/b --steps 2"), 0);
  ASSERT_EQ(test::run(common + " --network sweep2d --out " + out + "/b --steps 4 --resume"), 0);
  const auto a = load_model(out + "/a/last.pt", torch::kCPU), b = load_model(out + "/b/last.pt", torch::kCPU);
  EXPECT_EQ(a.model->config().network, NetworkKind::kSweep2d);
  EXPECT_EQ(a.model->config().num_depth, kSweep2dDefaultPlanes);
  EXPECT_EQ(a.model->config().depth_sampling, DepthSampling::kUniformInverseDepth);
  EXPECT_EQ(b.meta.step, 4);
  for (const auto& item : a.model->named_parameters()) {
    EXPECT_TRUE(torch::equal(item.value(), b.model->named_parameters()[item.key()])) << item.key();
  }
  // From it: its 64 planes (the default for 96 wide would be 24), and the record says sweep2d.
  ASSERT_EQ(test::run(common + " --init " + out + "/a/last.pt --out " + out + "/c --steps 1"), 0);
  EXPECT_EQ(load_model(out + "/c/last.pt", torch::kCPU).model->config().num_depth, kSweep2dDefaultPlanes);
  std::ifstream record(out + "/c/run_config.json");
  const std::string text((std::istreambuf_iterator<char>(record)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("\"network\": \"sweep2d\""), std::string::npos) << text;
  // Refused: another plane count than its weights', a fine pass, an unknown network.
  EXPECT_NE(test::run(common + " --init " + out + "/a/last.pt --num-depth 32 --out " + out + "/d --steps 1"), 0);
  EXPECT_NE(test::run(common + " --network sweep2d --fine-planes 8 --out " + out + "/e --steps 1"), 0);
  EXPECT_NE(test::run(common + " --network unet --out " + out + "/f --steps 1"), 0);
  EXPECT_FALSE(std::filesystem::exists(out + "/d/last.pt"));
  // umvs bench times it at its own planes unless told otherwise.
  const auto bench = test::run_umvs("bench --case network --checkpoint " + out + "/a/last.pt --width 64 --height 64 "
                                    "--runs 1 --warmup 0 --threads 1 --json", "2>/dev/null");
  ASSERT_EQ(bench.status, 0) << bench.output;
  EXPECT_NE(bench.output.find("\"num_depth\":" + std::to_string(kSweep2dDefaultPlanes)), std::string::npos) << bench.output;
}

}  // namespace
}  // namespace umvs
