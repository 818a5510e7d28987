#include "unsup_mvs/core/depth_estimator.h"

#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <stdexcept>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/core/losses.h"

namespace umvs {

Camera depth_map_camera(const Camera& network_camera, double scale) {
  Camera c = network_camera;
  c.K.topRows<2>() *= scale;
  c.width = static_cast<int>(network_camera.width * scale);
  c.height = static_cast<int>(network_camera.height * scale);
  return c;
}

const char* to_string(SourceCombination c) {
  switch (c) {
    case SourceCombination::kMostConfident: return "most_confident";
    case SourceCombination::kAuto: return "auto";
    case SourceCombination::kVariance: break;
  }
  return "variance";
}

SourceCombination source_combination_from_string(const std::string& s) {
  if (s == "variance") return SourceCombination::kVariance;
  if (s == "most_confident") return SourceCombination::kMostConfident;
  if (s == "auto") return SourceCombination::kAuto;
  throw std::invalid_argument("unknown source combination '" + s + "' (expected variance|most_confident|auto)");
}

namespace {
MvsNet moved_to(MvsNet model, const torch::Device& device) {
  model->to(device);
  return model;
}

// A 3x3 window whose intensities spread less than one grey level tells the turn search nothing.
constexpr double kMinTextureStd = 1.0 / 255;

// views[0] is the reference. Throws std::invalid_argument naming the view for an invalid camera,
// an image that is not uint8 [H,W,3] of its camera's size, or one of another size than the reference.
void validate_views(const std::vector<ViewInput>& views) {
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
    if (v.camera.width != views.front().camera.width || v.camera.height != views.front().camera.height) {
      throw std::invalid_argument(name + " has another image size than the reference");
    }
  }
}
}  // namespace

RotationSearch search_rotation(const std::function<double(const Eigen::Vector3d& degrees)>& score, double limit_deg) {
  RotationSearch result;
  result.degrees = Eigen::Vector3d::Zero();
  result.start_score = result.score = score(result.degrees);
  result.evaluations = 1;
  for (const double step : {0.4, 0.2, 0.1}) {
    for (bool rising = true; rising;) {
      rising = false;
      for (int axis = 0; axis < 3; ++axis) {
        for (const double sign : {1.0, -1.0}) {
          Eigen::Vector3d candidate = result.degrees;
          candidate[axis] += sign * step;
          if (std::abs(candidate[axis]) > limit_deg + 1e-9) continue;
          const double s = score(candidate);
          ++result.evaluations;
          if (s > result.score) {
            result.score = s;
            result.degrees = candidate;
            rising = true;
          }
        }
      }
    }
  }
  return result;
}

void DepthEstimatorConfig::validate() const {
  if (num_depth != 0 && (num_depth < 8 || num_depth % 8 != 0)) {
    throw std::invalid_argument("num_depth must be 0 (the model's) or a positive multiple of 8, got " +
                                std::to_string(num_depth));
  }
  if (!std::isfinite(source_rotation_search_deg) || source_rotation_search_deg < 0) {
    throw std::invalid_argument("source_rotation_search_deg must be an angle >= 0 (0 = off), got " +
                                std::to_string(source_rotation_search_deg));
  }
  if (!std::isfinite(min_parallax_px) || min_parallax_px < 0) {
    throw std::invalid_argument("min_parallax_px must be >= 0 pixels (0 = off), got " + std::to_string(min_parallax_px));
  }
  completion.validate();
  fine.validate();
}

int first_pass_size(const DepthEstimatorConfig& config, int network_side) {
  return config.fine.enabled() ? network_side / config.fine.first_pass_downscale : network_side;
}

torch::Tensor parallax_shift_px(const torch::Tensor& depth, const Camera& depth_camera, const std::vector<Camera>& sources,
                                double relative_change) {
  if (depth.dim() != 2 || depth.size(0) != depth_camera.height || depth.size(1) != depth_camera.width) {
    throw std::invalid_argument("parallax_shift_px: the depth map must be [h,w] of its camera's size");
  }
  const auto f64 = torch::TensorOptions().dtype(torch::kFloat64);
  const int64_t h = depth.size(0), w = depth.size(1);
  const auto d = depth.to(torch::kFloat64).reshape({1, -1});
  const auto v = torch::arange(h, f64).view({h, 1}).expand({h, w}).reshape({1, -1});
  const auto u = torch::arange(w, f64).view({1, w}).expand({h, w}).reshape({1, -1});
  const auto eigen = [&](const auto& m) {
    const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> row_major = m;
    return torch::from_blob(const_cast<double*>(row_major.data()), {row_major.rows(), row_major.cols()}, f64).clone();
  };
  // Rays in the world: X(d) = C + d * ray, ray = R^T K^-1 (u, v, 1).
  const auto rays = eigen(depth_camera.R().transpose() * depth_camera.K.inverse()).matmul(torch::cat({u, v, torch::ones_like(u)}, 0));
  const auto center = eigen(depth_camera.center());
  auto largest = torch::zeros({1, h * w}, f64);
  const auto valid = (d > 0) & torch::isfinite(d);
  const auto d0 = d.where(valid, torch::ones_like(d));
  for (const auto& source : sources) {
    const auto P = eigen(source.K * source.T_cam_world.topRows<3>());  // 3x4
    const auto project = [&](const torch::Tensor& z) {
      const auto X = center + rays * z;
      const auto x = P.slice(1, 0, 3).matmul(X) + P.slice(1, 3, 4);
      return std::make_pair(x.slice(0, 0, 2) / x.slice(0, 2, 3), x.slice(0, 2, 3) > 0);
    };
    const auto [a, a_front] = project(d0);
    const auto [b, b_front] = project(d0 * (1.0 + relative_change));
    const auto shift = (a - b).norm(2, 0, true);
    largest = torch::maximum(largest, shift.where(a_front & b_front & torch::isfinite(shift), torch::zeros_like(shift)));
  }
  return largest.where(valid, torch::zeros_like(largest)).view({h, w}).to(torch::kFloat32);
}

DepthEstimator::DepthEstimator(MvsNet model, torch::Device device, DepthEstimatorConfig config)
    : device_(device), network_(moved_to(std::move(model), device)), config_(config) {
  config_.validate();
  const MvsNetConfig& net = network_.model()->config();
  if (net.planes_fixed_by_weights() && config_.num_depth != 0 && config_.num_depth != net.num_depth) {
    throw std::invalid_argument("num_depth: this " + std::string(to_string(net.network)) + " network sweeps the " +
                                std::to_string(net.num_depth) + " planes its weights were trained for, asked for " +
                                std::to_string(config_.num_depth) + " (0 = the network's own)");
  }
  if (net.network != NetworkKind::kMvsNet && config_.fine.enabled()) {
    throw std::invalid_argument(std::string("fine pass: runs MVSNet twice; this is a ") + to_string(net.network) +
                                " network (its map is at 1/2 of the input already)");
  }
}

std::function<double(const Eigen::Vector3d&)> DepthEstimator::source_warp_loss(const ViewInput& reference,
                                                                               const ViewInput& source,
                                                                               const NetworkResize& plan, int planes,
                                                                               double depth_min, double depth_max) {
  const Camera ref_camera = apply_network_resize(reference.camera, plan);
  const Camera source_camera = apply_network_resize(source.camera, plan);
  torch::NoGradGuard no_grad;
  const auto ref_image = apply_network_resize(rgb8_to_float(reference.image), plan).unsqueeze(0).to(device_);
  const auto source_image = apply_network_resize(rgb8_to_float(source.image), plan).unsqueeze(0).to(device_);
  const auto batch = torch::stack({ref_image[0], source_image[0]}).unsqueeze(0);
  const auto depth_values =
      depth_hypotheses(depth_min, depth_max, planes, network_.model()->config().depth_sampling).unsqueeze(0).to(device_);
  const auto K_ref = intrinsics_tensor(ref_camera).unsqueeze(0).to(device_);
  const auto K_source = intrinsics_tensor(source_camera).unsqueeze(0).to(device_);
  // How well the source, warped by the pass's own depth, matches the reference (SSIM, robust to
  // exposure), not the pass's confidence: a turn along the epipolar lines only moves the depth,
  // which keeps the warp as good, while confidence rises when depth moves away from the ends of the
  // range, and would pull exact poses off.
  const auto warp_loss_map = [=](const Eigen::Vector3d& degrees) {
    torch::NoGradGuard no_grad;
    const Camera turned = source_camera.turned(degrees * kRadiansPerDegree);
    const auto proj = mvsnet_projection_matrices({ref_camera, turned}).unsqueeze(0).to(device_);
    const auto depth = network_.forward(batch, proj, depth_values, false).depth;  // [1,h/s,w/s]
    const int64_t divisor = network_.model()->config().map_divisor();
    const auto full_depth = depth.repeat_interleave(divisor, 1).repeat_interleave(divisor, 2);
    const auto T = relative_pose_tensor(ref_camera, turned).unsqueeze(0).to(device_);
    const InverseWarp warp = inverse_warp(source_image, K_ref, K_source, T, full_depth);
    return ssim_loss_map(ref_image, warp.warped, warp.valid);
  };
  // Only windows with texture in the reference, and that the source sees at the pose as given, are
  // judged. A flat window's SSIM is perfect whatever the depth and the pose (templeRing's black
  // background), so averaging over them let a turn win by trading textured windows out of view.
  const SsimLossMap at_pose = warp_loss_map(Eigen::Vector3d::Zero());
  const auto judged = at_pose.window_valid * (local_std(ref_image) > kMinTextureStd).to(at_pose.loss.scalar_type());
  const auto mean_judged_loss = [judged](const SsimLossMap& map) {
    const auto weight = judged * map.window_valid;
    return (map.loss * weight).sum().item<double>() / std::max(weight.sum().item<double>(), 1.0);
  };
  const double loss_at_pose = mean_judged_loss(at_pose);
  return [=](const Eigen::Vector3d& degrees) {
    return degrees.isZero() ? loss_at_pose : mean_judged_loss(warp_loss_map(degrees));
  };
}

SourceTurn DepthEstimator::best_source_turn(const ViewInput& reference, const ViewInput& source,
                                            double depth_min, double depth_max, double limit_deg) {
  if (!std::isfinite(limit_deg) || limit_deg <= 0) {
    throw std::invalid_argument("the rotation search needs a limit > 0 degrees, got " + std::to_string(limit_deg));
  }
  validate_views({reference, source});
  // The search runs at half the network's input size (but no less than 320 wide, or the input's
  // width) and with half its planes: a quarter of the work per pass, and a tenth of a degree is
  // still 0.4 px at 320 wide with a 60-degree field of view.
  const int width = reference.camera.width, height = reference.camera.height;
  const NetworkResize full = plan_network_resize(width, height, config_.max_width, config_.max_height);
  const int search_width = std::max(full.width / 2, std::min(full.width, 320));
  // The height bound follows the width's scale; + 31 so that rounding does not lose a 32-pixel row.
  const NetworkResize half =
      plan_network_resize(width, height, search_width, full.height * search_width / std::max(1, full.width) + 31);
  const int search_planes =
      network_.model()->config().planes_fixed_by_weights() ? num_depth() : std::max(8, num_depth() / 2 / 8 * 8);
  const auto half_size_loss = source_warp_loss(reference, source, half, search_planes, depth_min, depth_max);
  const RotationSearch search =
      search_rotation([&](const Eigen::Vector3d& d) { return -half_size_loss(d); }, limit_deg);
  const auto gain = [](double loss_at_pose, double loss_turned) {
    return (loss_at_pose - loss_turned) / std::max(loss_at_pose, 1e-12);
  };
  SourceTurn turn;
  turn.degrees = search.degrees;
  turn.search_gain = gain(-search.start_score, -search.score);
  // Keep the pose as given unless the turn is clearly better, in the search and again at the
  // network's full size and planes: on exact poses, noise turns gained up to 6 % in the half-size
  // search but at most 2.4 % at full size (rendered scenes, templeRing), while the living room's
  // sources, a few tenths of a degree off, gain 7-74 % and 7-46 % (docs/results.md).
  if (turn.search_gain >= kMinSourceTurnGain) {
    const auto full_size_loss = source_warp_loss(reference, source, full, num_depth(), depth_min, depth_max);
    turn.full_size_gain = gain(full_size_loss(Eigen::Vector3d::Zero()), full_size_loss(search.degrees));
  }
  turn.kept = turn.search_gain >= kMinSourceTurnGain && turn.full_size_gain >= kMinSourceTurnGain;
  return turn;
}

int DepthEstimator::num_depth() const {
  return config_.num_depth > 0 ? config_.num_depth : network_.model()->config().num_depth;
}

DepthMap DepthEstimator::estimate(const std::vector<ViewInput>& views, double depth_min, double depth_max) {
  if (views.size() < 2) throw std::invalid_argument("need a reference and at least one source view");
  const auto& ref = views.front();
  std::vector<torch::Tensor> images;
  std::vector<Camera> cameras;
  // A first pass at half size needs the half-size input to be a multiple of 32 as well.
  const int multiple = config_.fine.enabled() && config_.fine.first_pass_downscale == 2 ? 64 : 32;
  const NetworkResize plan =
      plan_network_resize(ref.camera.width, ref.camera.height, config_.max_width, config_.max_height, multiple);
  validate_views(views);
  for (const auto& v : views) {
    images.push_back(apply_network_resize(rgb8_to_float(v.image), plan));
    cameras.push_back(apply_network_resize(v.camera, plan));
  }
  const int D = num_depth();
  // The map's resolution: the fine pass's, else the network's (1/4 for MVSNet, 1/2 for sweep2d).
  const int divisor = config_.fine.enabled() ? config_.fine.resolution_divisor : network_.model()->config().map_divisor();
  auto depth_values = depth_hypotheses(depth_min, depth_max, D, network_.model()->config().depth_sampling);

  const auto t0 = std::chrono::steady_clock::now();
  DepthMap map;
  if (config_.source_rotation_search_deg > 0) {
    for (size_t s = 1; s < views.size(); ++s) {
      const SourceTurn turn = best_source_turn(ref, views[s], depth_min, depth_max, config_.source_rotation_search_deg);
      if (turn.kept) cameras[s] = cameras[s].turned(turn.degrees * kRadiansPerDegree);
      map.source_turns.push_back(turn);
    }
  }
  MvsOutput out;
  {
    torch::NoGradGuard no_grad;
    auto batch = torch::stack(images).unsqueeze(0).to(device_);
    auto proj = mvsnet_projection_matrices(cameras).unsqueeze(0).to(device_);
    const auto planes = depth_values.unsqueeze(0).to(device_);
    const auto proj_fine = mvsnet_projection_matrices(cameras, 1.0 / divisor).unsqueeze(0).to(device_);
    const auto run = [&](const torch::Tensor& views, const torch::Tensor& p, const torch::Tensor& p_fine, MvsStageTimes* t) {
      return config_.fine.enabled() ? network_.forward_coarse_to_fine(views, p, planes, config_.fine, p_fine, t)
                                    : network_.forward(views, p, planes, false, t);
    };
    out = run(batch, proj, proj_fine, &map.stages);
    const int64_t num_views = batch.size(1);
    const auto unsure_map = [&] {
      return (out.confidence >= kAutoConfidentLevel).to(torch::kFloat32).mean().item<double>() < kAutoMinConfidentShare;
    };
    map.per_source_passes =
        num_views > 2 && (config_.source_combination == SourceCombination::kMostConfident ||
                          (config_.source_combination == SourceCombination::kAuto && unsure_map()));
    if (map.per_source_passes) {
      for (int64_t s = 1; s < num_views; ++s) {
        const auto pair = torch::tensor({int64_t{0}, s}, torch::TensorOptions().dtype(torch::kLong).device(device_));
        const MvsOutput alone =
            run(batch.index_select(1, pair), proj.index_select(1, pair), proj_fine.index_select(1, pair), nullptr);
        const auto better = alone.confidence > out.confidence;
        out.depth = torch::where(better, alone.depth, out.depth);
        out.confidence = torch::where(better, alone.confidence, out.confidence);
      }
    }
  }
  map.depth = out.depth.squeeze(0).to(torch::kCPU);
  map.confidence = out.confidence.squeeze(0).to(torch::kCPU);
  map.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  if (config_.min_parallax_px > 0) {
    const std::vector<Camera> sources(cameras.begin() + 1, cameras.end());
    const auto shift = parallax_shift_px(map.depth, depth_map_camera(cameras.front(), 1.0 / divisor), sources);
    map.unresolvable = shift < config_.min_parallax_px;
    map.confidence = map.confidence.masked_fill(map.unresolvable, 0.0f);
  }
  if (config_.completion.enabled()) {
    const auto t1 = std::chrono::steady_clock::now();
    // The guide is the reference's grey level averaged over the input pixels of each depth pixel.
    const auto guide = torch::avg_pool2d(images.front().unsqueeze(0), divisor).squeeze(0).mean(0);
    map.depth = complete_depth(map.depth, map.confidence, guide, config_.completion, &map.completion);
    map.completion_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
  }
  map.network_camera = cameras.front();
  map.camera = depth_map_camera(cameras.front(), 1.0 / divisor);
  map.color = float_to_rgb8(images.front().slice(1, 0, plan.height, divisor).slice(2, 0, plan.width, divisor));
  map.depth_min = depth_min;
  map.depth_max = depth_max;
  return map;
}

}  // namespace umvs
