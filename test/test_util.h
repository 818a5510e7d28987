// Helpers shared by the gtest files.
#pragma once

#include <gtest/gtest.h>
#include <torch/types.h>

#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>

#include "scratch_dirs.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/import.h"
#include "unsup_mvs/io/synth_writer.h"

namespace umvs::test {

// ../shared/data beside the repository (or $UMVS_SHARED_DATA); "" when absent.
inline std::string shared_data_dir() {
  if (const char* env = std::getenv("UMVS_SHARED_DATA")) return env;
  const auto p = std::filesystem::path(UMVS_SOURCE_DIR).parent_path() / "shared" / "data";
  return std::filesystem::is_directory(p) ? std::filesystem::canonical(p).string() : "";
}

// Writes `text` to `path`, replacing it.
inline void write_text(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

// A fresh, empty temporary folder for one test.
inline std::string temp_dir(const std::string& name) { return umvs_scratch::scratch_dir("umvs_test_", name); }

// A rendered room (core/synth.h, no lighting change) written as an MVSNet folder in a fresh
// temp_dir(name), with its exact depth in depth_gt/ unless keep_ground_truth is false.
inline std::string write_room(const std::string& name, uint64_t seed, bool keep_ground_truth, int width = 128,
                              int height = 96, int views = 6, int supersample = 1) {
  const std::string dir = temp_dir(name);
  SynthConfig cfg;
  cfg.scene = SynthSceneType::kRoom;
  cfg.seed = seed;
  cfg.num_views = views;
  cfg.width = width;
  cfg.height = height;
  cfg.lighting_change = false;
  cfg.supersample = supersample;
  cfg.gt_cloud_samples = 0;
  write_synthetic_scene(dir, render_synthetic_scene(cfg), cfg);
  if (!keep_ground_truth) std::filesystem::remove_all(dir + "/depth_gt");
  return dir;
}

// The rendered living room of ../shared/data (ICL-NUIM's camera: fy < 0, the image's y flipped).
inline CameraIntrinsics living_room_intrinsics() {
  CameraIntrinsics in;
  in.K << 481.2, 0, 319.5, 0, -480.0, 239.5, 0, 0, 1;
  return in;
}

inline std::string umvs_binary() { return std::string(UMVS_BIN_DIR) + "/umvs"; }

// Fraction of elements where |a - b| <= atol + rtol * |b|.
inline double fraction_close(const torch::Tensor& a, const torch::Tensor& b, double rtol, double atol) {
  return ((a - b).abs() <= atol + rtol * b.abs()).to(torch::kFloat64).mean().template item<double>();
}

}  // namespace umvs::test

// Skips the test with a clear message when ../shared/data/<sub> is missing (a user's clone).
#define UMVS_REQUIRE_SHARED(sub, var)                                                        \
  const std::string var = ::umvs::test::shared_data_dir().empty()                            \
                              ? std::string()                                                \
                              : ::umvs::test::shared_data_dir() + "/" + (sub);               \
  if (var.empty() || !std::filesystem::exists(var))                                          \
    GTEST_SKIP() << "../shared/data/" << (sub) << " not found: real-data test skipped "       \
                 << "(set UMVS_SHARED_DATA or clone next to shared/)"
