#include "unsup_mvs/core/fusion.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/view_selection.h"
#include "fusion_internal.h"

namespace umvs {

const char* to_string(FusionSourceRule rule) {
  return rule == FusionSourceRule::kConfidentNeighbours ? "neighbours" : "mvsnet";
}

FusionSourceRule fusion_source_rule_from_string(const std::string& s) {
  if (s == "neighbours") return FusionSourceRule::kConfidentNeighbours;
  if (s == "mvsnet") return FusionSourceRule::kMvsnetEval;
  throw std::invalid_argument("unknown fusion source rule '" + s + "' (expected neighbours|mvsnet)");
}

void FusionConfig::validate() const {
  auto fail = [](const std::string& m) { throw std::invalid_argument("fusion config: " + m); };
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) fail("min_confidence must be in [0,1], got " + std::to_string(min_confidence));
  if (!(max_reprojection_px > 0.0) || !std::isfinite(max_reprojection_px)) fail("max_reprojection_px must be > 0, got " + std::to_string(max_reprojection_px));
  if (!(max_relative_depth > 0.0) || !std::isfinite(max_relative_depth)) fail("max_relative_depth must be > 0, got " + std::to_string(max_relative_depth));
  if (min_agreeing_views < 0 || min_agreeing_views > 255) fail("min_agreeing_views must be in [0,255], got " + std::to_string(min_agreeing_views));
  if (max_source_views < 1) fail("max_source_views must be >= 1, got " + std::to_string(max_source_views));
  if (!(voxel_size >= 0.0) || !std::isfinite(voxel_size)) fail("voxel_size must be >= 0 (0 = off), got " + std::to_string(voxel_size));
  if (clear_after_views < 0 || clear_after_views > 255) fail("clear_after_views must be in [0,255] (0 = never clear), got " + std::to_string(clear_after_views));
  if (!(clear_margin > 0.0) || !std::isfinite(clear_margin)) fail("clear_margin must be > 0, got " + std::to_string(clear_margin));
}

namespace fusion_detail {

std::string view_name(const FusionView& v) { return "fusion view " + std::to_string(v.id); }

// Checks shapes and the camera; throws std::invalid_argument naming the view.
void validate_view(const FusionView& v) {
  const std::string name = view_name(v);
  if (!v.depth.defined() || v.depth.dim() != 2) throw std::invalid_argument(name + ": depth must be a [H,W] tensor");
  const int64_t H = v.depth.size(0), W = v.depth.size(1);
  if (H < 1 || W < 1) throw std::invalid_argument(name + ": empty depth map");
  if (v.camera.width != W || v.camera.height != H) {
    throw std::invalid_argument(name + ": camera is " + std::to_string(v.camera.width) + "x" + std::to_string(v.camera.height) +
                                " but the depth map is " + std::to_string(W) + "x" + std::to_string(H));
  }
  if (v.confidence.defined() && v.confidence.sizes() != v.depth.sizes()) {
    throw std::invalid_argument(name + ": confidence shape differs from the depth shape");
  }
  if (v.color.defined() && (v.color.dim() != 3 || v.color.size(0) != H || v.color.size(1) != W || v.color.size(2) != 3 ||
                            v.color.scalar_type() != torch::kUInt8)) {
    throw std::invalid_argument(name + ": color must be uint8 [H,W,3] matching the depth map");
  }
  v.camera.validate(name);
}


Prepared prepare(const FusionView& v, const FusionConfig& config, const torch::Device& device) {
  Prepared p;
  p.id = v.id;
  p.camera = v.camera;
  auto depth = v.depth.to(device, torch::kFloat32);
  p.confidence = v.confidence.defined() ? v.confidence.to(device, torch::kFloat32) : torch::ones_like(depth);
  p.color = v.color.defined() ? v.color.to(device)
                              : torch::full({depth.size(0), depth.size(1), 3}, 128,
                                            torch::TensorOptions().dtype(torch::kUInt8).device(device));
  p.valid = valid_estimate_mask(depth, p.confidence, config.min_confidence);
  if (device.is_cpu() && config.source_rule == FusionSourceRule::kConfidentNeighbours) p.quad_valid = quad_validity(p.valid);
  p.depth = torch::where(p.valid, depth, torch::zeros_like(depth));
  p.source_depth = p.depth;
  if (config.source_rule == FusionSourceRule::kMvsnetEval) {
    p.valid &= p.confidence > config.min_confidence;  // eval.py: confidence > threshold
    p.depth = torch::where(p.valid, depth, torch::zeros_like(depth));
    p.source_depth = torch::where(torch::isfinite(depth) & (depth > 0), depth, torch::zeros_like(depth));
  }
  return p;
}

torch::Tensor eigen_to_tensor(const Eigen::Matrix3d& m, const torch::Device& device) {
  auto t = torch::empty({3, 3}, torch::kFloat64);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) t[r][c] = m(r, c);
  return t.to(device, torch::kFloat32);
}

torch::Tensor eigen_to_tensor(const Eigen::Vector3d& v, const torch::Device& device) {
  return torch::tensor({v.x(), v.y(), v.z()}, torch::kFloat64).to(device, torch::kFloat32);
}

// World points of the pixels in `keep` with depth `depth`.  keep [H,W] bool, depth [H,W]
// -> xyz [N,3] float32 (world), and the flat indices [N] of those pixels.
torch::Tensor backproject_pixels(const torch::Tensor& flat_index, const torch::Tensor& depth_values, const Camera& camera,
                                 int64_t width) {
  const auto device = depth_values.device();
  auto xs = (flat_index % width).to(torch::kFloat32);
  auto ys = torch::div(flat_index, width, "floor").to(torch::kFloat32);
  auto pix = torch::stack({xs, ys, torch::ones_like(xs)});                            // [3,N]
  auto cam_pts = torch::matmul(eigen_to_tensor(Eigen::Matrix3d(camera.K.inverse()), device), pix) * depth_values;  // [3,N]
  // X_world = R^T (X_cam - t)
  auto Rt = eigen_to_tensor(Eigen::Matrix3d(camera.R().transpose()), device);
  auto world = torch::matmul(Rt, cam_pts - eigen_to_tensor(camera.t(), device).view({3, 1}));
  return world.t().contiguous();
}

// Points of the pixels `keep` of view p on the CPU: one pass over the pixels.
PointCloud make_points_cpu(const Prepared& p, const torch::Tensor& keep, const torch::Tensor& depth, const torch::Tensor& count) {
  const auto keep_c = keep.to(torch::kBool).contiguous();
  const auto depth_c = depth.to(torch::kFloat32).contiguous();
  const auto count_c = count.to(torch::kInt32).contiguous();
  const auto color_c = p.color.contiguous();
  const auto conf_c = p.confidence.contiguous();
  const bool* k = keep_c.data_ptr<bool>();
  const int64_t H = keep.size(0), W = keep.size(1);
  const int64_t n = keep_c.sum().item<int64_t>();
  PointCloud cloud;
  if (n == 0) return cloud;
  // world = R^T (d K^-1 (x, y, 1) - t), with K^-1 formed once (Camera::backproject inverts K
  // per call, too slow for every pixel).
  const Eigen::Matrix3d Rt = p.camera.R().transpose();
  const Eigen::Matrix3d M = Rt * p.camera.K.inverse();
  const Eigen::Vector3d c = -(Rt * p.camera.t());
  const float* d = depth_c.data_ptr<float>();
  const int32_t* views = count_c.data_ptr<int32_t>();
  const uint8_t* rgb = color_c.data_ptr<uint8_t>();
  const float* conf = conf_c.data_ptr<float>();
  cloud.points.reserve(n);
  cloud.colors.reserve(n);
  cloud.confidence.reserve(n);
  cloud.num_views.reserve(n);
  for (int64_t y = 0; y < H; ++y) {
    for (int64_t x = 0; x < W; ++x) {
      const int64_t i = y * W + x;
      if (!k[i]) continue;
      const Eigen::Vector3d world = static_cast<double>(d[i]) * (M * Eigen::Vector3d(static_cast<double>(x), static_cast<double>(y), 1.0)) + c;
      cloud.points.push_back(world.cast<float>());
      cloud.colors.push_back({rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2]});
      cloud.confidence.push_back(conf[i]);
      cloud.num_views.push_back(static_cast<uint8_t>(std::clamp(views[i], 0, 255)));
    }
  }
  return cloud;
}

// Points of the pixels `keep` of view p, at depth `depth` (averaged), with `count` agreeing views.
PointCloud make_points(const Prepared& p, const torch::Tensor& keep, const torch::Tensor& depth, const torch::Tensor& count) {
  if (p.depth.device().is_cpu()) return make_points_cpu(p, keep, depth, count);
  const int64_t W = p.depth.size(1);
  auto idx = keep.reshape({-1}).nonzero().reshape({-1});
  PointCloud cloud;
  const int64_t n = idx.size(0);
  if (n == 0) return cloud;
  auto xyz = backproject_pixels(idx, depth.reshape({-1}).index_select(0, idx), p.camera, W).cpu();
  auto rgb = p.color.reshape({-1, 3}).index_select(0, idx).cpu().contiguous();
  auto conf = p.confidence.reshape({-1}).index_select(0, idx).cpu().contiguous();
  auto views = count.reshape({-1}).index_select(0, idx).clamp(0, 255).to(torch::kUInt8).cpu().contiguous();
  cloud.points.resize(n);
  cloud.colors.resize(n);
  cloud.confidence.assign(conf.data_ptr<float>(), conf.data_ptr<float>() + n);
  cloud.num_views.assign(views.data_ptr<uint8_t>(), views.data_ptr<uint8_t>() + n);
  const float* x = xyz.data_ptr<float>();
  const uint8_t* c = rgb.data_ptr<uint8_t>();
  for (int64_t i = 0; i < n; ++i) {
    cloud.points[i] = Eigen::Vector3f(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
    cloud.colors[i] = {c[3 * i], c[3 * i + 1], c[3 * i + 2]};
  }
  return cloud;
}

int64_t voxel_key(const Eigen::Vector3f& p, double voxel) {
  const auto cell = [&](float v) { return static_cast<int64_t>(std::floor(v / voxel)) & 0x1FFFFF; };
  return (cell(p.x()) << 42) | (cell(p.y()) << 21) | cell(p.z());
}

// Keeps the points whose voxel is not yet in `voxels` (first one wins), registering them.
PointCloud voxel_filter(const PointCloud& in, double voxel, std::unordered_set<int64_t>& voxels) {
  PointCloud out;
  for (size_t i = 0; i < in.size(); ++i) {
    if (!voxels.insert(voxel_key(in.points[i], voxel)).second) continue;
    out.points.push_back(in.points[i]);
    if (in.has_colors()) out.colors.push_back(in.colors[i]);
    if (!in.confidence.empty()) out.confidence.push_back(in.confidence[i]);
    if (!in.num_views.empty()) out.num_views.push_back(in.num_views[i]);
  }
  return out;
}

// Sources of view i ranked by the view-selection score on points of its own depth map.
std::vector<int> rank_sources_by_score(const std::vector<Prepared>& views, size_t i) {
  const auto& ref = views[i];
  auto depth = ref.depth.cpu();
  auto valid = ref.valid.cpu();
  const int grid = 24;
  const int64_t H = depth.size(0), W = depth.size(1);
  std::vector<Eigen::Vector3d> pts;
  auto d = depth.accessor<float, 2>();
  auto m = valid.accessor<bool, 2>();
  for (int gy = 0; gy < grid; ++gy) {
    for (int gx = 0; gx < grid; ++gx) {
      const int64_t y = std::min<int64_t>(H - 1, (2 * gy + 1) * H / (2 * grid));
      const int64_t x = std::min<int64_t>(W - 1, (2 * gx + 1) * W / (2 * grid));
      if (m[y][x]) pts.push_back(ref.camera.backproject(static_cast<double>(x), static_cast<double>(y), d[y][x]));
    }
  }
  std::vector<Camera> cams;
  std::vector<int> index;
  for (size_t j = 0; j < views.size(); ++j) {
    if (j == i) continue;
    cams.push_back(views[j].camera);
    index.push_back(static_cast<int>(j));
  }
  std::vector<int> out;
  for (const auto& s : rank_source_views(pts, ref.camera, cams)) out.push_back(index[s.index]);
  return out;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace fusion_detail

using namespace fusion_detail;

DepthFusion::DepthFusion(FusionConfig config, torch::Device device) : config_(config), device_(device) { config_.validate(); }

namespace {

// What the batch rule decides for one reference view.
struct ReferenceResult {
  const Prepared* ref;
  int num_sources;
  torch::Tensor keep;   // [H,W] bool: valid and confirmed by enough sources
  torch::Tensor depth;  // [H,W] float32: mean of the view's and the agreeing depths
  torch::Tensor count;  // [H,W] int32: agreeing sources
  double ranking_seconds;      // choosing the sources
  double consistency_seconds;  // checking them against the reference
};

// The batch rule over all views: checks the inputs (throwing std::invalid_argument naming the
// view), prepares the views on the device and calls per_view(i, result) for each reference.
template <typename PerView>
void for_each_reference(const std::vector<FusionView>& views, const std::vector<std::vector<int>>& sources,
                        const FusionConfig& config, const torch::Device& device, PerView&& per_view) {
  torch::NoGradGuard no_grad;
  if (!sources.empty() && sources.size() != views.size()) {
    throw std::invalid_argument("fusion: " + std::to_string(sources.size()) + " source lists for " + std::to_string(views.size()) +
                                " views (give one per view or none)");
  }
  for (size_t i = 0; i < views.size(); ++i) {
    validate_view(views[i]);
    if (sources.empty()) continue;
    for (int j : sources[i]) {
      if (j < 0 || j >= static_cast<int>(views.size()) || j == static_cast<int>(i)) {
        throw std::invalid_argument(view_name(views[i]) + ": source index " + std::to_string(j) + " is not another view (0.." +
                                    std::to_string(views.size() - 1) + ")");
      }
    }
  }
  std::vector<Prepared> prepared;
  prepared.reserve(views.size());
  for (const auto& v : views) prepared.push_back(prepare(v, config, device));
  for (size_t i = 0; i < prepared.size(); ++i) {
    const auto& ref = prepared[i];
    const auto t_rank = std::chrono::steady_clock::now();
    std::vector<int> src = (sources.empty() || sources[i].empty()) ? rank_sources_by_score(prepared, i) : sources[i];
    if (static_cast<int>(src.size()) > config.max_source_views) src.resize(config.max_source_views);
    const double ranking_seconds = seconds_since(t_rank);
    const auto t_check = std::chrono::steady_clock::now();
    auto count = torch::zeros_like(ref.depth, torch::kInt32);
    auto depth_sum = ref.depth.clone();
    std::vector<const Prepared*> src_views;
    for (int j : src) src_views.push_back(&prepared[j]);
    accumulate(ref, src_views, config, count, depth_sum);
    const double consistency_seconds = seconds_since(t_check);
    auto keep = ref.valid & (count >= config.min_agreeing_views);
    auto mean_depth = depth_sum / (count + 1).to(torch::kFloat32);
    per_view(i, ReferenceResult{&ref, static_cast<int>(src.size()), keep, mean_depth, count, ranking_seconds,
                                consistency_seconds});
  }
}

}  // namespace

PointCloud DepthFusion::fuse(const std::vector<FusionView>& views, const std::vector<std::vector<int>>& sources,
                             std::vector<FusionViewStats>* stats) {
  if (stats) stats->clear();
  PointCloud cloud;
  std::unordered_set<int64_t> voxels;
  auto t0 = std::chrono::steady_clock::now();
  for_each_reference(views, sources, config_, device_, [&](size_t, const ReferenceResult& r) {
    const auto t_points = std::chrono::steady_clock::now();
    PointCloud points = make_points(*r.ref, r.keep, r.depth, r.count);
    if (config_.voxel_size > 0) points = voxel_filter(points, config_.voxel_size, voxels);
    cloud.append(points);
    if (stats) {
      FusionViewStats s;
      s.id = r.ref->id;
      s.num_sources = r.num_sources;
      s.valid_pixels = r.ref->valid.sum().item<int64_t>();
      s.ranking_seconds = r.ranking_seconds;
      s.consistency_seconds = r.consistency_seconds;
      s.points_seconds = seconds_since(t_points);
      s.points = static_cast<int64_t>(points.size());
      s.seconds = seconds_since(t0);
      stats->push_back(s);
    }
    t0 = std::chrono::steady_clock::now();
  });
  return cloud;
}

std::vector<DepthFusion::Agreement> DepthFusion::agreement(const std::vector<FusionView>& views,
                                                           const std::vector<std::vector<int>>& sources) {
  std::vector<Agreement> out(views.size());
  for_each_reference(views, sources, config_, device_, [&](size_t i, const ReferenceResult& r) {
    out[i].confirmed = r.keep.cpu();
    out[i].depth = torch::where(r.keep, r.depth, torch::zeros_like(r.depth)).cpu();
  });
  return out;
}

}  // namespace umvs
