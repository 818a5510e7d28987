#include "unsup_mvs/core/fusion.h"

#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/view_selection.h"

namespace umvs {

namespace F = torch::nn::functional;

void FusionConfig::validate() const {
  auto fail = [](const std::string& m) { throw std::invalid_argument("fusion config: " + m); };
  if (!(min_confidence >= 0.0 && min_confidence <= 1.0)) fail("min_confidence must be in [0,1], got " + std::to_string(min_confidence));
  if (!(max_reprojection_px > 0.0) || !std::isfinite(max_reprojection_px)) fail("max_reprojection_px must be > 0, got " + std::to_string(max_reprojection_px));
  if (!(max_relative_depth > 0.0) || !std::isfinite(max_relative_depth)) fail("max_relative_depth must be > 0, got " + std::to_string(max_relative_depth));
  if (min_agreeing_views < 0 || min_agreeing_views > 255) fail("min_agreeing_views must be in [0,255], got " + std::to_string(min_agreeing_views));
  if (max_source_views < 1) fail("max_source_views must be >= 1, got " + std::to_string(max_source_views));
  if (!(voxel_size >= 0.0) || !std::isfinite(voxel_size)) fail("voxel_size must be >= 0 (0 = off), got " + std::to_string(voxel_size));
}

namespace {

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

// A view's tensors on the fusion device, cleaned: depth is 0 where it is no estimate.
struct Prepared {
  int64_t id = 0;
  Camera camera;
  torch::Tensor depth;       // [H,W] float32
  torch::Tensor valid;       // [H,W] bool
  torch::Tensor confidence;  // [H,W] float32
  torch::Tensor color;       // [H,W,3] uint8
};

Prepared prepare(const FusionView& v, const FusionConfig& config, const torch::Device& device) {
  Prepared p;
  p.id = v.id;
  p.camera = v.camera;
  auto depth = v.depth.to(device, torch::kFloat32);
  p.confidence = v.confidence.defined() ? v.confidence.to(device, torch::kFloat32) : torch::ones_like(depth);
  p.valid = valid_estimate_mask(depth, p.confidence, config.min_confidence);
  p.depth = torch::where(p.valid, depth, torch::zeros_like(depth));
  p.color = v.color.defined() ? v.color.to(device)
                              : torch::full({depth.size(0), depth.size(1), 3}, 128,
                                            torch::TensorOptions().dtype(torch::kUInt8).device(device));
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

// Points of the pixels `keep` of view p, at depth `depth` (averaged), with `count` agreeing views.
PointCloud make_points(const Prepared& p, const torch::Tensor& keep, const torch::Tensor& depth, const torch::Tensor& count) {
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

// Accumulates one source's agreement into `count` and `depth_sum` of reference `ref`.
void accumulate(const Prepared& ref, const Prepared& src, const FusionConfig& config, torch::Tensor& count,
                torch::Tensor& depth_sum) {
  auto c = check_consistency(ref.depth, ref.valid, ref.camera, src.depth, src.valid, src.camera, config);
  count += c.agree.to(torch::kInt32);
  depth_sum += torch::where(c.agree, c.depth, torch::zeros_like(c.depth));
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace

torch::Tensor valid_estimate_mask(const torch::Tensor& depth, const torch::Tensor& confidence, double min_confidence) {
  auto valid = torch::isfinite(depth) & (depth > 0);
  if (confidence.defined()) valid = valid & (confidence >= min_confidence);
  return valid;
}

ConsistencyCheck check_consistency(const torch::Tensor& ref_depth, const torch::Tensor& ref_valid, const Camera& ref_camera,
                                   const torch::Tensor& src_depth, const torch::Tensor& src_valid, const Camera& src_camera,
                                   const FusionConfig& config) {
  const auto device = ref_depth.device();
  const int64_t H = ref_depth.size(0), W = ref_depth.size(1);
  const int64_t Hs = src_depth.size(0), Ws = src_depth.size(1);
  // 1. reference pixels -> source pixels (invalid pixels get depth 1 to keep the maths finite).
  auto d_ref = torch::where(ref_valid, ref_depth, torch::ones_like(ref_depth)).to(torch::kFloat32);
  auto K_ref = intrinsics_tensor(ref_camera).to(device).unsqueeze(0);
  auto K_src = intrinsics_tensor(src_camera).to(device).unsqueeze(0);
  auto p = project_to_source(K_ref, K_src, relative_pose_tensor(ref_camera, src_camera).to(device).unsqueeze(0),
                             d_ref.unsqueeze(0));
  auto u = p.uv.select(3, 0)[0], v = p.uv.select(3, 1)[0];  // [H,W]
  auto inside = (u >= 0) & (u <= Ws - 1) & (v >= 0) & (v <= Hs - 1) & (p.z[0] > 0);

  // 2. source depth there (bilinear, pixel centres); all contributing pixels must be estimates.
  auto grid = torch::stack({u / std::max<double>(1.0, (Ws - 1) / 2.0) - 1.0, v / std::max<double>(1.0, (Hs - 1) / 2.0) - 1.0}, 2)
                  .unsqueeze(0);  // [1,H,W,2]
  auto sample = [&](const torch::Tensor& image) {
    return F::grid_sample(image.to(torch::kFloat32).view({1, 1, Hs, Ws}), grid,
                          F::GridSampleFuncOptions().mode(torch::kBilinear).padding_mode(torch::kZeros).align_corners(true))
        .view({H, W});
  };
  auto d_src = sample(torch::where(src_valid, src_depth, torch::zeros_like(src_depth)));
  auto src_ok = sample(src_valid) > 1.0 - 1e-4;

  // 3. source pixel with its depth -> reference camera.
  auto pix = torch::stack({u, v, torch::ones_like(u)}).view({3, H * W});
  auto pts_src = torch::matmul(torch::inverse(K_src[0]), pix) * d_src.view({1, H * W});  // [3,HW]
  auto T_ref_src = relative_pose_tensor(src_camera, ref_camera).to(device);
  auto pts_ref = torch::matmul(T_ref_src.slice(0, 0, 3).slice(1, 0, 3), pts_src) + T_ref_src.slice(0, 0, 3).slice(1, 3, 4);
  auto proj = torch::matmul(K_ref[0], pts_ref);
  auto z = pts_ref[2].view({H, W});
  auto zp = proj[2].view({H, W});
  auto zp_safe = torch::where(zp.abs() < 1e-9, torch::full_like(zp, 1e-9), zp);
  auto u_back = proj[0].view({H, W}) / zp_safe, v_back = proj[1].view({H, W}) / zp_safe;

  // 4. both errors.
  auto xs = torch::arange(W, d_ref.options()).view({1, W});
  auto ys = torch::arange(H, d_ref.options()).view({H, 1});
  auto reproj = torch::sqrt((u_back - xs).square() + (v_back - ys).square());
  auto rel = (z - d_ref).abs() / d_ref;
  auto agree = ref_valid & inside & src_ok & (d_src > 0) & (z > 0) & (reproj < config.max_reprojection_px) &
               (rel < config.max_relative_depth);
  return {agree, z};
}

DepthFusion::DepthFusion(FusionConfig config, torch::Device device) : config_(config), device_(device) { config_.validate(); }

namespace {

// What the batch rule decides for one reference view.
struct ReferenceResult {
  const Prepared* ref;
  int num_sources;
  torch::Tensor keep;   // [H,W] bool: valid and confirmed by enough sources
  torch::Tensor depth;  // [H,W] float32: mean of the view's and the agreeing depths
  torch::Tensor count;  // [H,W] int32: agreeing sources
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
    std::vector<int> src = (sources.empty() || sources[i].empty()) ? rank_sources_by_score(prepared, i) : sources[i];
    if (static_cast<int>(src.size()) > config.max_source_views) src.resize(config.max_source_views);
    auto count = torch::zeros_like(ref.depth, torch::kInt32);
    auto depth_sum = ref.depth.clone();
    for (int j : src) accumulate(ref, prepared[j], config, count, depth_sum);
    auto keep = ref.valid & (count >= config.min_agreeing_views);
    per_view(i, ReferenceResult{&ref, static_cast<int>(src.size()), keep, depth_sum / (count + 1).to(torch::kFloat32),
                                count});
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
    PointCloud points = make_points(*r.ref, r.keep, r.depth, r.count);
    if (config_.voxel_size > 0) points = voxel_filter(points, config_.voxel_size, voxels);
    cloud.append(points);
    if (stats) {
      FusionViewStats s;
      s.id = r.ref->id;
      s.num_sources = r.num_sources;
      s.valid_pixels = r.ref->valid.sum().item<int64_t>();
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

// ---------------------------------------------------------------------------------------------

struct StreamingFusion::Entry {
  Prepared view;
  torch::Tensor count;      // [H,W] int32: agreeing estimates met so far
  torch::Tensor depth_sum;  // [H,W] float32: own depth + agreeing depths
  torch::Tensor emitted;    // [H,W] bool: already a point
};

StreamingFusion::StreamingFusion(FusionConfig config, int window, size_t max_points, torch::Device device)
    : config_(config), window_(window), max_points_(max_points), device_(device) {
  config_.validate();
  if (window < 1) throw std::invalid_argument("streaming fusion: window must be >= 1, got " + std::to_string(window));
  if (max_points < 1) throw std::invalid_argument("streaming fusion: max_points must be >= 1");
}

StreamingFusion::~StreamingFusion() = default;

size_t StreamingFusion::num_views() const { return ring_.size(); }

void StreamingFusion::reset() {
  ring_.clear();
  cloud_.clear();
  voxels_.clear();
}

PointCloud StreamingFusion::add(const FusionView& view) {
  torch::NoGradGuard no_grad;
  validate_view(view);
  auto entry = std::make_unique<Entry>();
  entry->view = prepare(view, config_, device_);
  entry->count = torch::zeros_like(entry->view.depth, torch::kInt32);
  entry->depth_sum = entry->view.depth.clone();
  entry->emitted = torch::zeros_like(entry->view.valid);

  auto emit = [&](Entry& e, PointCloud& out) {
    auto fresh = e.view.valid & ~e.emitted & (e.count >= config_.min_agreeing_views);
    out.append(make_points(e.view, fresh, e.depth_sum / (e.count + 1).to(torch::kFloat32), e.count));
    e.emitted |= fresh;
  };
  PointCloud created;
  for (auto& stored : ring_) {
    accumulate(stored->view, entry->view, config_, stored->count, stored->depth_sum);
    emit(*stored, created);
    accumulate(entry->view, stored->view, config_, entry->count, entry->depth_sum);
  }
  emit(*entry, created);
  ring_.push_back(std::move(entry));
  while (static_cast<int>(ring_.size()) > window_) ring_.pop_front();
  append_points(created);
  return created;
}

void StreamingFusion::append_points(PointCloud& points) {
  if (config_.voxel_size > 0) points = voxel_filter(points, config_.voxel_size, voxels_);
  cloud_.append(points);
  if (cloud_.size() <= max_points_) return;
  // Drop the oldest points, leaving 10% headroom so that eviction is rare.
  const size_t keep = std::max<size_t>(1, max_points_ - max_points_ / 10);
  const size_t drop = cloud_.size() - keep;
  auto erase_front = [drop](auto& v) {
    if (!v.empty()) v.erase(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(drop));
  };
  erase_front(cloud_.points);
  erase_front(cloud_.colors);
  erase_front(cloud_.confidence);
  erase_front(cloud_.num_views);
  if (config_.voxel_size > 0) {
    voxels_.clear();
    for (const auto& p : cloud_.points) voxels_.insert(voxel_key(p, config_.voxel_size));
  }
}

}  // namespace umvs
