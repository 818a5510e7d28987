// The record of a `umvs train` run (jobs/train_options.h, io/run_folder.h): OUT/run_config.json with
// typed, versioned options; folders of the previous version (run_config.txt) still resume,
// upgraded; and the options bound to TrainOptions keep CLI11's checks and --help defaults.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <torch/torch.h>

#include <filesystem>
#include <regex>
#include <set>
#include <string>

#include "cli_test_util.h"
#include "test_util.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/jobs/train_options.h"

namespace umvs {
namespace {

namespace fs = std::filesystem;
using test::contains;
using test::file_bytes;
using test::kTrainFlags;
using test::Result;
using test::run_umvs;
using test::snapshot;
using test::write_bytes;

TEST(TrainRunConfig, ARunRecordsEveryOptionAsTypedVersionedJson) {
  const std::string data = test::scene("trc_json_data");
  const std::string out = test::temp_dir("trc_json") + "/run";
  ASSERT_EQ(run_umvs("train --data " + data + kTrainFlags + " --lr 5e-5 --steps 1 --out " + out).status, 0);
  EXPECT_FALSE(fs::exists(out + "/run_config.txt"));
  const auto doc = nlohmann::json::parse(file_bytes(out + "/run_config.json"));
  EXPECT_EQ(doc.at("format"), "umvs train run");
  EXPECT_EQ(doc.at("version"), kRunRecordVersion);
  const auto& options = doc.at("options");
  EXPECT_TRUE(options.at("width").is_number_integer()) << options;
  EXPECT_EQ(options.at("width"), 96);
  EXPECT_TRUE(options.at("lr").is_number_float()) << options;
  EXPECT_EQ(options.at("lr"), 5e-5);
  EXPECT_EQ(options.at("loss"), "robust");
  EXPECT_EQ(options.at("augment"), true);
  EXPECT_EQ(options.at("resume"), false);
  EXPECT_EQ(options.at("data"), nlohmann::json::array({fs::absolute(data).lexically_normal().string()}));
  EXPECT_EQ(options.at("val"), nlohmann::json::array());
  EXPECT_EQ(options.at("world-size"), 1);
  // Every option of --help but --rank (which process, not which run) is recorded.
  const Result help = run_umvs("train --help", "2>/dev/null");
  std::set<std::string> declared;
  const std::regex option_line("\n  --([a-z0-9-]+)");  // (wrapped descriptions are indented further)
  for (std::sregex_iterator it(help.output.begin(), help.output.end(), option_line), end; it != end; ++it) {
    declared.insert((*it)[1]);
  }
  declared.erase("help");
  declared.erase("rank");
  std::set<std::string> keys;
  for (const auto& entry : options.items()) keys.insert(entry.key());
  EXPECT_GT(declared.size(), 60u) << help.output;
  EXPECT_EQ(keys, declared);
}

// What the previous version wrote for `umvs train --data DATA` + kTrainFlags + `--steps 2 --out
// OUT` (the key set of a real run_config.txt of that version): options at the value older versions
// ran with left out (zoom, volume terms, batchnorm, source combination, anchor floor), anchoring
// recorded as "" (off), every value text.
std::string previous_version_record(const std::string& data, const std::string& out) {
  return "# the options of this umvs train run: umvs train --resume refuses to change them (docs/training.md)\n"
         "against=\nanchor-unconfirmed=\naugment=1\nbag=\nbatch=1\nbeta1=0.95\n"
         "camera-info-topic=/camera/camera_info\ndata=" + fs::absolute(data).lexically_normal().string() + "\n"
         "depth-max=10\ndepth-min=0.3\ndepth-sampling=depth\ndepth-topic=\ndevice=cpu\ndist-timeout=120\n"
         "eval-only=\nfeature-warp=\nfine-tuned-share=1\nheight=64\nholdout-every=5\n"
         "image-topic=/camera/image_rect_color\ninit=\ninput-normalization=per_image_channel\njitter=0.1\n"
         "keyframe-buffer=30\nlabel-max-relative-depth=0.03\nlabel-min-confidence=0.5\nlabel-min-views=2\n"
         "loss=robust\nlr=1e-3\nlr-min=0\nlr-schedule=constant\nmaster=\nmax-gain=1\nmax-minutes=0\n"
         "micro-batch=0\nmin-gain=1\nmin-pose-distance=0\nmin-rotation-deg=10\nmin-translation=0.1\n"
         "min-view-score=0.5\nnproc=1\nnum-depth=8\nout=" + out + "\noverwrite=\npreset=paper\n"
         "pseudo-label-tuples=0\nrectified=1\nresume=\nsave-every=2\nseed=1\nself-training-every=0\nsteps=2\n"
         "supervised-data=\nsupervised-share=0.5\nsupervised-weight=0.1\nthreads=1\ntop-k=2\nval=\n"
         "val-tuples=0\nview-score-grid=16\nviews-in=3\nviews-loss=3\nwidth=96\nworld-frame=world\nworld-size=1\n";
}

TEST(TrainRunConfig, AFolderOfThePreviousVersionResumesAndRefusesAChangedOption) {
  const std::string data = test::scene("trc_old_data");
  const std::string out = test::temp_dir("trc_old") + "/run";
  const std::string common = "train --data " + data + kTrainFlags + " --out " + out;
  ASSERT_EQ(run_umvs(common + " --steps 2").status, 0);
  // The folder as the previous version left it: run_config.txt instead of run_config.json.
  fs::remove(out + "/run_config.json");
  const std::string old_record = previous_version_record(data, out);
  write_bytes(out + "/run_config.txt", old_record);

  const auto before = snapshot(out);
  Result changed = run_umvs(common + " --lr 0.01 --steps 4 --resume");
  EXPECT_EQ(changed.status, 2) << changed.output;
  EXPECT_TRUE(contains(changed.output, "--resume must continue the same run: --lr: the run in this folder has "
                                       "'0.001', now '0.01' (" + out + "/run_config.txt)"))
      << changed.output;
  EXPECT_EQ(snapshot(out), before);

  Result resumed = run_umvs(common + " --steps 4 --resume");
  ASSERT_EQ(resumed.status, 0) << resumed.output;
  EXPECT_TRUE(contains(resumed.output, "depth planes: 8 (--num-depth 8)")) << resumed.output;
  EXPECT_EQ(load_model(out + "/last.pt", torch::kCPU).meta.step, 4);
  // The resumed run is recorded as this version records it; the old file stays as it was.
  const auto record = read_run_record(out);
  ASSERT_TRUE(record.has_value());
  EXPECT_EQ(record->path, out + "/run_config.json");
  EXPECT_EQ(record->version, kRunRecordVersion);
  EXPECT_EQ(record->options.at("min-zoom"), 1.0);
  EXPECT_EQ(file_bytes(out + "/run_config.txt"), old_record);
  ASSERT_EQ(run_umvs(common + " --steps 6 --resume").status, 0);
  EXPECT_EQ(load_model(out + "/last.pt", torch::kCPU).meta.step, 6);
  Result refused = run_umvs(common + " --width 128 --steps 8 --resume");
  EXPECT_EQ(refused.status, 2) << refused.output;
  EXPECT_TRUE(contains(refused.output, "--width: the run in this folder has '96', now '128' (" + out +
                                       "/run_config.json)"))
      << refused.output;
  // --overwrite removes both records.
  ASSERT_EQ(run_umvs(common + " --steps 1 --overwrite").status, 0);
  EXPECT_FALSE(fs::exists(out + "/run_config.txt"));
  EXPECT_TRUE(fs::exists(out + "/run_config.json"));
}

TEST(TrainRunConfig, UpgradeGivesLeftOutOptionsTheValuesOlderVersionsRanWith) {
  // A version 1 anchored self-training run without a recorded floor (made before the 0.5 default).
  RunRecord old;
  old.path = "run_config.txt";
  old.version = 1;
  old.options = {{"anchor-unconfirmed", "1"}, {"self-training-every", "100"}, {"lr", "5e-5"}, {"rank", "0"},
                 {"data", "/a,/b"},          {"rectified", "1"},             {"width", "320"}, {"seed", "x"}};
  const RunOptions up = upgrade_train_record(old);
  EXPECT_EQ(up.at("anchor-unconfirmed"), true);
  EXPECT_EQ(up.at("anchor-min-confidence"), 0.0);  // no floor
  EXPECT_EQ(up.at("anchor-unseen"), false);
  EXPECT_EQ(up.at("self-training-every"), 100);
  EXPECT_EQ(up.at("lr"), 5e-5);
  EXPECT_EQ(up.at("data"), RunOptions::array({"/a", "/b"}));
  EXPECT_EQ(up.at("rectified"), true);
  EXPECT_EQ(up.at("width"), 320);
  EXPECT_EQ(up.at("seed"), "x") << "text that is no number stays text (and differs, so a resume names it)";
  EXPECT_FALSE(up.contains("rank"));
  const RunOptions left_out = {{"source-combination", "variance"}, {"entropy-weight", 0.0}, {"plane-loss-weight", 0.0},
                               {"batchnorm", "train"}, {"min-zoom", 1.0}, {"max-zoom", 1.25}, {"world-size", 1},
                               {"fine-planes", 0}, {"fine-resolution", 4}, {"first-pass-downscale", 1}};
  for (const auto& entry : left_out.items()) EXPECT_EQ(up.at(entry.key()), entry.value()) << entry.key();
  // A plain run recorded anchoring as "".
  old.options = {{"anchor-unconfirmed", ""}};
  EXPECT_EQ(upgrade_train_record(old).at("anchor-unconfirmed"), false);
  // The record of today's defaults needs no upgrade, and a newer version is refused.
  RunRecord today;
  today.options = train_run_options(TrainOptions{}, DistributedConfig{});
  EXPECT_EQ(run_options_difference(upgrade_train_record(today), today.options, {}), "");
  // A record of this version made before coarse-to-fine training resumes as the one-pass run it was.
  RunRecord one_pass = today;
  for (const char* name : {"fine-planes", "fine-span", "fine-resolution", "first-pass-downscale", "first-pass-loss-weight"}) {
    one_pass.options.erase(name);
  }
  EXPECT_EQ(run_options_difference(upgrade_train_record(one_pass), today.options, {}), "");
  today.version = kRunRecordVersion + 1;
  EXPECT_THROW(upgrade_train_record(today), std::runtime_error);
}

TEST(TrainRunConfig, BoundOptionsKeepTheirChecksAndShowTheirDefaults) {
  const std::string out = test::temp_dir("trc_args") + "/run";
  struct Case {
    std::string args, says;
  };
  for (const auto& c : {Case{"--threads abc", "needs an integer, got 'abc'"},
                        Case{"--holdout-every 1.5", "needs an integer, got '1.5'"},
                        Case{"--lr fast", "needs a number, got 'fast'"},
                        Case{"--augment 2", "--augment must be 0 or 1, got '2'"},
                        Case{"--world-size two", "needs an integer, got 'two'"},
                        Case{"--steps 2 --lrr 0.1", "unknown option --lrr (did you mean --lr?)"}}) {
    const Result r = run_umvs("train --data x " + c.args + " --out " + out, "2>&1 >/dev/null");
    EXPECT_EQ(r.status, 2) << c.args << ": " << r.output;
    EXPECT_TRUE(contains(r.output, c.says)) << c.args << ": " << r.output;
  }
  EXPECT_FALSE(fs::exists(out));
  const Result help = run_umvs("train --help", "2>/dev/null");
  for (const std::string shown : {"--lr NUMBER=0.001", "--augment INT=1", "--max-zoom NUMBER=1.25",
                                  "--depth-min NUMBER=0.3", "--loss TEXT=robust", "--world-size INT "}) {
    EXPECT_TRUE(contains(help.output, shown)) << shown << "\n" << help.output;
  }
}

}  // namespace
}  // namespace umvs
