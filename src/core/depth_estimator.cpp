#include "unsup_mvs/core/depth_estimator.h"

#include <torch/torch.h>

#include <chrono>
#include <stdexcept>

#include "unsup_mvs/core/image_ops.h"

namespace umvs {

Camera depth_map_camera(const Camera& network_camera, double scale) {
  Camera c = network_camera;
  c.K.topRows<2>() *= scale;
  c.width = static_cast<int>(network_camera.width * scale);
  c.height = static_cast<int>(network_camera.height * scale);
  return c;
}

const char* to_string(SourceCombination c) {
  return c == SourceCombination::kMostConfident ? "most_confident" : "variance";
}

SourceCombination source_combination_from_string(const std::string& s) {
  if (s == "variance") return SourceCombination::kVariance;
  if (s == "most_confident") return SourceCombination::kMostConfident;
  throw std::invalid_argument("unknown source combination '" + s + "' (expected variance|most_confident)");
}

namespace {
MvsNet moved_to(MvsNet model, const torch::Device& device) {
  model->to(device);
  return model;
}
}  // namespace

DepthEstimator::DepthEstimator(MvsNet model, torch::Device device, DepthEstimatorConfig config)
    : device_(device), network_(moved_to(std::move(model), device)), config_(config) {
  if (config_.num_depth != 0 && (config_.num_depth < 8 || config_.num_depth % 8 != 0)) {
    throw std::invalid_argument("num_depth must be a positive multiple of 8, got " + std::to_string(config_.num_depth));
  }
}

int DepthEstimator::num_depth() const {
  return config_.num_depth > 0 ? config_.num_depth : network_.model()->config().num_depth;
}

DepthMap DepthEstimator::estimate(const std::vector<ViewInput>& views, double depth_min, double depth_max) {
  if (views.size() < 2) throw std::invalid_argument("need a reference and at least one source view");
  const auto& ref = views.front();
  std::vector<torch::Tensor> images;
  std::vector<Camera> cameras;
  const NetworkResize plan = plan_network_resize(ref.camera.width, ref.camera.height, config_.max_width, config_.max_height);
  for (size_t i = 0; i < views.size(); ++i) {
    const auto& v = views[i];
    const std::string name = i == 0 ? "reference view" : "source view " + std::to_string(i);
    v.camera.validate(name);
    if (!v.image.defined() || v.image.dim() != 3 || v.image.size(2) != 3 || v.image.scalar_type() != torch::kUInt8) {
      throw std::invalid_argument(name + ": image must be uint8 [H,W,3]");
    }
    if (v.image.size(0) != v.camera.height || v.image.size(1) != v.camera.width) {
      throw std::invalid_argument(name + ": image is " + std::to_string(v.image.size(1)) + "x" + std::to_string(v.image.size(0)) +
                                  " but its camera says " + std::to_string(v.camera.width) + "x" + std::to_string(v.camera.height));
    }
    if (v.camera.width != ref.camera.width || v.camera.height != ref.camera.height) {
      throw std::invalid_argument(name + " has another image size than the reference");
    }
    images.push_back(apply_network_resize(rgb8_to_float(v.image), plan));
    cameras.push_back(apply_network_resize(v.camera, plan));
  }
  const int D = num_depth();
  auto depth_values = depth_hypotheses(depth_min, depth_max, D, network_.model()->config().depth_sampling);

  const auto t0 = std::chrono::steady_clock::now();
  DepthMap map;
  MvsOutput out;
  {
    torch::NoGradGuard no_grad;
    auto batch = torch::stack(images).unsqueeze(0).to(device_);
    auto proj = mvsnet_projection_matrices(cameras).unsqueeze(0).to(device_);
    const auto planes = depth_values.unsqueeze(0).to(device_);
    out = network_.forward(batch, proj, planes, false, &map.stages);
    const int64_t num_views = batch.size(1);
    if (config_.source_combination == SourceCombination::kMostConfident && num_views > 2) {
      for (int64_t s = 1; s < num_views; ++s) {
        const auto pair = torch::tensor({int64_t{0}, s}, torch::TensorOptions().dtype(torch::kLong).device(device_));
        const MvsOutput alone = network_.forward(batch.index_select(1, pair), proj.index_select(1, pair), planes, false);
        const auto better = alone.confidence > out.confidence;
        out.depth = torch::where(better, alone.depth, out.depth);
        out.confidence = torch::where(better, alone.confidence, out.confidence);
      }
    }
  }
  map.depth = out.depth.squeeze(0).to(torch::kCPU);
  map.confidence = out.confidence.squeeze(0).to(torch::kCPU);
  map.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  map.network_camera = cameras.front();
  map.camera = depth_map_camera(cameras.front());
  map.color = float_to_rgb8(images.front().slice(1, 0, plan.height, 4).slice(2, 0, plan.width, 4));
  map.depth_min = depth_min;
  map.depth_max = depth_max;
  return map;
}

}  // namespace umvs
