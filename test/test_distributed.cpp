// Data-parallel training (core/distributed.h, jobs/training_run.h, io/local_ranks.h): two ranks over
// loopback with Gloo.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <torch/torch.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>
#include <thread>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/core/distributed.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/child_process.h"
#include "unsup_mvs/io/local_ranks.h"
#include "unsup_mvs/io/synth_writer.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {
namespace {

#define SKIP_WITHOUT_GLOO() \
  if (!distributed_available()) GTEST_SKIP() << "built without c10d/Gloo headers (libgloo-dev)"

struct Scene {
  std::string data, init;
};

// A small rendered scene and a fixed initial model, so that every run starts from the same weights.
const Scene& scene() {
  static const Scene s = [] {
    Scene out;
    out.data = test::temp_dir("distributed_scene");
    SynthConfig cfg;
    cfg.scene = SynthSceneType::kRoom;
    cfg.seed = 3;
    cfg.num_views = 5;
    cfg.width = 96;
    cfg.height = 64;
    cfg.lighting_change = false;
    cfg.supersample = 2;
    cfg.gt_cloud_samples = 0;
    write_synthetic_scene(out.data, render_synthetic_scene(cfg), cfg);
    torch::manual_seed(5);
    MvsNetConfig model;
    model.num_depth = 8;
    MvsNet net(model);
    out.init = out.data + "/init.pt";
    save_checkpoint(out.init, net);
    return out;
  }();
  return s;
}

TrainingRunConfig small_run(const std::string& out, int batch, int steps) {
  TrainingRunConfig c;
  c.out = out;
  c.init = scene().init;
  c.trainer.loss = LossConfig::paper();
  c.trainer.loss.top_k = 2;
  c.trainer.num_depth = 8;
  c.data.width = 96;
  c.data.height = 64;
  c.data.num_depth = 8;
  c.data.views_loss = 3;
  c.batch = batch;
  c.steps = steps;
  c.save_every = 2;
  c.seed = 7;
  return c;
}

std::function<TrainingData()> open_scene(const TupleConfig& config) {
  return [config] {
    TrainingData d;
    d.train = std::make_unique<MvsFolderSource>(std::vector<std::string>{scene().data}, config);
    d.held_out = std::make_unique<MvsFolderSource>(std::vector<std::string>{scene().data}, config);
    return d;
  };
}

std::vector<torch::Tensor> weights(MvsNet& model) {
  std::vector<torch::Tensor> w = model->parameters();
  for (const auto& b : model->buffers()) w.push_back(b);
  return w;
}

// Two ranks of one job as two threads of this process (each its own Gloo connection over loopback).
struct TwoRanks {
  std::unique_ptr<TrainingRun> rank[2];
  TrainingRun::Result result[2];
  std::string error[2];
};
using AdjustRun = std::function<void(TrainingRunConfig&)>;
std::unique_ptr<TwoRanks> start_two_ranks(const std::string& out, int steps, const AdjustRun& adjust = {}) {
  auto job = std::make_unique<TwoRanks>();
  const int port = free_local_port();
  std::ostringstream messages[2];
  auto rank_main = [&](int r) {
    try {
      TrainingRunConfig c = small_run(out, 1, steps);
      c.distributed.world_size = 2;
      c.distributed.rank = r;
      c.distributed.master_port = port;
      c.distributed.timeout_seconds = 60;
      if (adjust) adjust(c);
      job->rank[r] = std::make_unique<TrainingRun>(c, open_scene(c.data), messages[r]);
      job->result[r] = job->rank[r]->run();
    } catch (const std::exception& e) {
      job->error[r] = e.what();
    }
  };
  std::thread other(rank_main, 1);
  rank_main(0);
  other.join();
  return job;
}
std::unique_ptr<TwoRanks> run_two_ranks(const std::string& out, int steps, const AdjustRun& adjust = {}) {
  auto job = start_two_ranks(out, steps, adjust);
  EXPECT_EQ(job->error[0], "");
  EXPECT_EQ(job->error[1], "");
  return job;
}

TEST(Distributed, TwoRanksHoldBitIdenticalWeightsAndOnlyRankZeroWrites) {
  SKIP_WITHOUT_GLOO();
  const std::string out = test::temp_dir("distributed_two") + "/run";
  auto job = run_two_ranks(out, 3);
  ASSERT_TRUE(job->rank[0] && job->rank[1]);
  EXPECT_EQ(job->result[0].step, 3);
  EXPECT_EQ(job->result[1].step, 3);
  const auto a = weights(job->rank[0]->model()), b = weights(job->rank[1]->model());
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) ASSERT_TRUE(torch::equal(a[i], b[i])) << "tensor " << i << " differs";
  // The weights moved: the ranks did train.
  auto init = load_model(scene().init, torch::kCPU).model;
  EXPECT_FALSE(torch::equal(init->parameters().front(), job->rank[0]->model()->parameters().front()));
  // One log (rank 0's), one row per step, validation summed over both ranks' halves.
  const auto rows = read_csv_rows(out + "/train_log.csv");
  ASSERT_EQ(rows.size(), 3u);
  EXPECT_TRUE(train_log_row(rows[1]).val_abs_err.has_value());
  EXPECT_EQ(load_model(out + "/last.pt", torch::kCPU).meta.step, 3);
  EXPECT_EQ(job->result[0].best_score, job->result[1].best_score);
}

TEST(Distributed, TwoRanksOfBatchOneMatchOneProcessOfBatchTwoInMicroBatches) {
  SKIP_WITHOUT_GLOO();
  const std::string dir = test::temp_dir("distributed_equivalence");
  auto job = run_two_ranks(dir + "/two", 3);
  ASSERT_TRUE(job->rank[0]);
  // One process, batch 2, BatchNorm statistics per tuple as on the ranks.
  TrainingRunConfig c = small_run(dir + "/one", 2, 3);
  c.trainer.micro_batch = 1;
  std::ostringstream messages;
  TrainingRun one(c, open_scene(c.data), messages);
  one.run();
  // The learnt weights (BatchNorm's running averages differ by design: one process updates them
  // once per micro-batch, the ranks once per step and then average them).
  const auto a = job->rank[0]->model()->parameters(), b = one.model()->parameters();
  ASSERT_EQ(a.size(), b.size());
  double worst = 0;
  for (size_t i = 0; i < a.size(); ++i) worst = std::max(worst, (a[i] - b[i]).abs().max().item<double>());
  // Only the order of float sums differs (all-reduce vs autograd accumulation); Adam's steps are
  // 1e-3 here, so a wrong tuple, a missing average or a skipped update would differ by ~1e-3.
  EXPECT_LT(worst, 1e-5);
  // The logged losses agree too.
  const auto ra = read_csv_rows(dir + "/two/train_log.csv"), rb = read_csv_rows(dir + "/one/train_log.csv");
  ASSERT_EQ(ra.size(), rb.size());
  for (size_t i = 0; i < ra.size(); ++i) {
    EXPECT_NEAR(*train_log_row(ra[i]).total, *train_log_row(rb[i]).total, 1e-5) << "step " << i + 1;
  }
}

TEST(Distributed, ResumeRestartsEveryRankFromTheSameStepAndContinuesAsIfUninterrupted) {
  SKIP_WITHOUT_GLOO();
  const std::string dir = test::temp_dir("distributed_resume");
  auto straight = run_two_ranks(dir + "/straight", 4);
  run_two_ranks(dir + "/resumed", 2);
  auto resumed = run_two_ranks(dir + "/resumed", 4, [](TrainingRunConfig& c) { c.start = RunStart::kResume; });
  ASSERT_TRUE(straight->rank[0] && resumed->rank[0] && resumed->rank[1]);
  EXPECT_EQ(resumed->result[0].step, 4);
  EXPECT_EQ(resumed->result[1].step, 4);
  // Same shards, same augmentation and Adam's state restored: the same weights as a run that was
  // never stopped, on both ranks.
  for (int r = 0; r < 2; ++r) {
    const auto a = weights(straight->rank[r]->model()), b = weights(resumed->rank[r]->model());
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) ASSERT_TRUE(torch::equal(a[i], b[i])) << "rank " << r << " tensor " << i;
  }
  // The log continues where it stopped: steps 1..4 with the same losses.
  const auto ra = read_csv_rows(dir + "/straight/train_log.csv"), rb = read_csv_rows(dir + "/resumed/train_log.csv");
  ASSERT_EQ(ra.size(), 4u);
  ASSERT_EQ(rb.size(), 4u);
  for (size_t i = 0; i < ra.size(); ++i) {
    EXPECT_EQ(train_log_row(rb[i]).step, static_cast<int64_t>(i + 1));
    EXPECT_EQ(*train_log_row(ra[i]).total, *train_log_row(rb[i]).total) << "step " << i + 1;
  }
}

TEST(Distributed, AnyFailureOfRankZerosFolderCheckEndsTheOtherRanksAtOnce) {
  SKIP_WITHOUT_GLOO();
  const std::string out = test::temp_dir("distributed_bad_folder") + "/run";
  run_two_ranks(out, 2);
  // A damaged run_config.json: rank 0 fails reading it (a runtime_error, not a refusal).
  std::ofstream(out + "/" + kRunConfigFile, std::ios::app) << "this line is no JSON\n";
  const auto t0 = std::chrono::steady_clock::now();
  auto job = start_two_ranks(out, 4, [](TrainingRunConfig& c) { c.start = RunStart::kResume; });
  // Both fail long before the 60 s timeout of the group.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(30));
  const std::string damaged = "run configuration '" + out + "/" + kRunConfigFile + "' cannot be read: ";
  EXPECT_THAT(job->error[0], testing::HasSubstr(damaged));
  EXPECT_THAT(job->error[1], testing::HasSubstr("rank 0 refused the run: "));
  EXPECT_THAT(job->error[1], testing::HasSubstr(damaged));
}

TEST(Distributed, AKilledRankEndsTheOtherWithAClearErrorInsteadOfAHang) {
  SKIP_WITHOUT_GLOO();
  const std::string dir = test::temp_dir("distributed_kill");
  const int port = free_local_port();
  const std::vector<std::string> argv = {test::umvs_binary(), "train", "--data", scene().data, "--init", scene().init,
                                         "--width", "96", "--height", "64", "--num-depth", "8", "--views-loss", "3",
                                         "--top-k", "2", "--threads", "1", "--steps", "100000", "--save-every", "100000",
                                         "--dist-timeout", "300", "--out", dir + "/run"};
  ChildProcess ranks[2];
  ::setenv("WORLD_SIZE", "2", 1);
  ::setenv("MASTER_ADDR", "127.0.0.1", 1);
  ::setenv("MASTER_PORT", std::to_string(port).c_str(), 1);
  for (int r = 0; r < 2; ++r) {
    ::setenv("RANK", std::to_string(r).c_str(), 1);
    ranks[r].start(argv);
  }
  for (const char* name : {"WORLD_SIZE", "RANK", "MASTER_ADDR", "MASTER_PORT"}) ::unsetenv(name);
  // Wait until rank 0 trains (its progress line), then kill rank 1.
  std::string output;
  bool training = false;
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!training && std::chrono::steady_clock::now() < deadline) {
    const bool alive = ranks[0].poll([&](const std::string& line) {
      output += line + "\n";
      training = training || line.rfind("training ", 0) == 0;
    });
    ASSERT_TRUE(alive) << output;
    ranks[1].poll([](const std::string&) {});
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_TRUE(training) << output;
  ::kill(ranks[1].pid(), SIGKILL);
  // Rank 0 ends on its own, with an error naming what failed, long before its 300 s timeout.
  const auto killed = std::chrono::steady_clock::now();
  while (ranks[0].poll([&](const std::string& line) { output += line + "\n"; })) {
    ASSERT_LT(std::chrono::steady_clock::now() - killed, std::chrono::seconds(120)) << "rank 0 hangs:\n" << output;
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_NE(ranks[0].exit_status(), 0);
  EXPECT_THAT(output, testing::HasSubstr("rank 0 of 2"));
  EXPECT_THAT(output, testing::HasSubstr("failed (another rank died or is unreachable?)"));
}

TEST(Distributed, NprocRunsTheJobAndAFailingRankFailsIt) {
  SKIP_WITHOUT_GLOO();
  const std::string dir = test::temp_dir("distributed_nproc");
  const auto r = test::run_umvs("train --nproc 2 --data " + scene().data + " --init " + scene().init +
                                " --width 96 --height 64 --num-depth 8 --views-loss 3 --top-k 2 --threads 1 --steps 2"
                                " --save-every 2 --out " + dir + "/run");
  ASSERT_EQ(r.status, 0) << r.output;
  EXPECT_THAT(r.output, testing::HasSubstr("all 2 ranks finished"));
  EXPECT_EQ(load_model(dir + "/run/last.pt", torch::kCPU).meta.step, 2);
  EXPECT_EQ(read_run_record(dir + "/run").value().options.at("world-size"), 2);

  // The launcher on its own: rank 1 fails at once, rank 0 would run for 300 s and is stopped.
  std::ostringstream out;
  const auto t0 = std::chrono::steady_clock::now();
  const auto result = run_local_ranks(
      {"/bin/sh", "-c", "if [ \"$RANK\" = 1 ]; then echo \"rank $RANK of $WORLD_SIZE at $MASTER_ADDR: boom\"; exit 3; fi; "
                        "echo started; exec sleep 300"},
      2, out);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(100));
  EXPECT_EQ(result.failed_rank, 1);
  EXPECT_EQ(result.exit_status, 3);
  EXPECT_THAT(result.message, testing::HasSubstr("rank 1 of 2 exited with status 3"));
  EXPECT_THAT(result.message, testing::HasSubstr("rank 1 of 2 at 127.0.0.1: boom"));
}

TEST(Distributed, TheTorchrunVariablesAreReadAndCheckedByName) {
  ::setenv("WORLD_SIZE", "4", 1);
  ::setenv("RANK", "3", 1);
  ::setenv("MASTER_ADDR", "10.0.0.2", 1);
  ::setenv("MASTER_PORT", "29600", 1);
  const DistributedConfig d = distributed_config_from_environment();
  EXPECT_EQ(d.world_size, 4);
  EXPECT_EQ(d.rank, 3);
  EXPECT_EQ(d.master_addr, "10.0.0.2");
  EXPECT_EQ(d.master_port, 29600);
  ::setenv("RANK", "three", 1);
  EXPECT_THAT([] { distributed_config_from_environment(); },
              testing::ThrowsMessage<std::invalid_argument>(testing::HasSubstr("RANK='three' is not a whole number")));
  for (const char* name : {"WORLD_SIZE", "RANK", "MASTER_ADDR", "MASTER_PORT"}) ::unsetenv(name);
  DistributedConfig bad;
  bad.world_size = 2;
  bad.rank = 2;
  EXPECT_THAT([&] { bad.validate(); },
              testing::ThrowsMessage<std::invalid_argument>(testing::HasSubstr("rank must be in 0..1, got 2")));
  const auto r = test::run_umvs("train --data x --out y --world-size 2 --rank 5");
  EXPECT_EQ(r.status, 2) << r.output;
  EXPECT_THAT(r.output, testing::HasSubstr("distributed training: rank must be in 0..1, got 5"));
}

}  // namespace
}  // namespace umvs
