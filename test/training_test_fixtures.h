// Helpers of the training tests (test_training.cpp, test_train_command.cpp) and of the tests of
// supervised and self-training and of the shipped model's inference (test_supervised_training.cpp,
// test_self_training.cpp, test_default_model.cpp, test_rotation_search.cpp, test_refine_poses.cpp).
#pragma once

#include <torch/torch.h>

#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "test_util.h"
#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/metrics.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/import.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/io/training_data.h"

namespace umvs::test {

// ---------------------------------------------------------------------------------------------
// Training runs

// The training tests' room: write_room supersampled 2x, with its ground truth.
inline std::string write_scene(const std::string& name, int width, int height, int views, uint64_t seed = 1) {
  return write_room(name, seed, true, width, height, views, 2);
}

// `umvs train ARGS`, its output discarded: std::system's status.
inline int run(const std::string& args) {
  const std::string cmd = umvs_binary() + " train " + args + " > /dev/null 2>&1";
  return std::system(cmd.c_str());
}

// ---------------------------------------------------------------------------------------------
// Supervised and self-training, and the shipped model

inline std::string default_model() { return std::string(UMVS_SOURCE_DIR) + "/models/unsup_mvsnet.pt"; }

// Tuples at 128x96, write_room's size, with views_loss loss views.
inline TupleConfig room_tuples(int views_loss, int width = 128, int height = 96) {
  TupleConfig cfg;
  cfg.views_loss = views_loss;
  cfg.width = width;
  cfg.height = height;
  return cfg;
}

// abs rel of a depth map against full-resolution ground truth, on the depth grid (4i, 4j)
inline double abs_rel_on_depth_grid(const torch::Tensor& est, const torch::Tensor& gt_full) {
  return evaluate_depth(est, gt_full.slice(0, 0, gt_full.size(0), 4).slice(1, 0, gt_full.size(1), 4), {}).abs_rel;
}

// A reference and its first `sources` neighbours of pair.txt, as `umvs infer` reads them.
struct PairInput {
  std::vector<ViewInput> views;
  double depth_min = 0, depth_max = 0;
};
inline PairInput pair_input(const MvsFolder& folder, int ref, int sources, int num_depth) {
  PairInput input;
  const MvsView reference = folder.load_view(ref);
  input.views.push_back({reference.image, reference.cam.camera});
  for (int s = 0; s < sources; ++s) {
    const MvsView source = folder.load_view(folder.pair_of(ref).sources.at(s));
    input.views.push_back({source.image, source.cam.camera});
  }
  input.depth_min = reference.cam.depth_min;
  input.depth_max = reference.cam.resolved_depth_max(num_depth);
  return input;
}

// The default model at 128 planes, searching source rotations within +-search_deg (0 = off).
inline DepthEstimator estimator_at_128_planes(double search_deg) {
  DepthEstimatorConfig config;
  config.num_depth = 128;
  config.source_rotation_search_deg = search_deg;
  return DepthEstimator(load_model(default_model(), torch::kCPU).model, torch::kCPU, config);
}

// The living room of ../shared/data imported into a new MVSNet folder named `name`.
inline std::string imported_living_room(const std::string& data, const std::string& name) {
  RgbdImportConfig import;
  import.data_dir = data;
  import.out_dir = temp_dir(name);
  import.intrinsics = living_room_intrinsics();
  import_rgbd(import);
  return import.out_dir;
}

}  // namespace umvs::test
