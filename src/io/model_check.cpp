#include "unsup_mvs/io/model_check.h"

#include <stdexcept>

#include "unsup_mvs/core/depth_estimator.h"

namespace umvs {

void check_model_forward(const MvsNet& model, const torch::Device& device) {
  Camera cam;
  cam.width = cam.height = 64;
  cam.K << 50, 0, 31.5, 0, 50, 31.5, 0, 0, 1;
  Camera cam2 = cam;
  cam2.T_cam_world(0, 3) = -0.1;
  const auto image = torch::randint(0, 255, {64, 64, 3}, torch::kUInt8);
  DepthEstimator probe(model, device, DepthEstimatorConfig{0, 0, 8});
  const DepthMap test = probe.estimate({{image, cam}, {image, cam2}}, 1.0, 2.0);
  if (!torch::isfinite(test.depth).all().item<bool>() || !torch::isfinite(test.confidence).all().item<bool>()) {
    throw std::runtime_error("a test forward pass gives non-finite depth or confidence");
  }
}

}  // namespace umvs
