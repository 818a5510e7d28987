#include "unsup_mvs/core/fusion.h"

#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/view_selection.h"

namespace umvs {

namespace F = torch::nn::functional;

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
  torch::Tensor depth;         // [H,W] float32
  torch::Tensor valid;         // [H,W] bool
  torch::Tensor confidence;    // [H,W] float32
  torch::Tensor color;         // [H,W,3] uint8
  torch::Tensor source_depth;  // [H,W] float32: what the view offers as a source (== depth, or
                               // with kMvsnetEval every finite positive depth, confident or not)
  torch::Tensor quad_valid;    // CPU, default rule: quad_validity(valid), for its use as a source
};

torch::Tensor quad_validity(const torch::Tensor& valid);

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

// Per source pixel (x, y): whether it and its right, lower and lower-right neighbours are all
// estimates (0 on the last row and column). One byte read replaces four in the common case of
// the bilinear read below. [H,W] uint8 on the CPU.
torch::Tensor quad_validity(const torch::Tensor& valid) {
  const auto v = valid.to(torch::kBool).contiguous();
  const int64_t H = v.size(0), W = v.size(1);
  auto quad = torch::zeros({H, W}, torch::kUInt8);
  const bool* ok = v.data_ptr<bool>();
  uint8_t* q = quad.data_ptr<uint8_t>();
  for (int64_t y = 0; y + 1 < H; ++y) {
    for (int64_t x = 0; x + 1 < W; ++x) {
      const int64_t i = y * W + x;
      q[i] = ok[i] && ok[i + 1] && ok[i + W] && ok[i + W + 1];
    }
  }
  return quad;
}

// The consistency test of one (reference, source) pair as a per-pixel loop on the CPU (float32
// geometry, float64 for MVSNet's rule), the same steps and thresholds as
// check_consistency_tensor_ops. rows() calls
// sink(pixel index, d') for every agreeing reference pixel of rows [y0, y1).
class PairTest {
 public:
  // src_quad: quad_validity(src_valid), or undefined (then computed here).
  PairTest(const torch::Tensor& ref_depth, const torch::Tensor& ref_valid, const Camera& ref_camera,
           const torch::Tensor& src_depth, const torch::Tensor& src_valid, const Camera& src_camera,
           const FusionConfig& config, const torch::Tensor& src_quad = {})
      : ref_depth_(ref_depth.to(torch::kFloat32).contiguous()),
        ref_valid_(ref_valid.to(torch::kBool).contiguous()),
        src_depth_(src_depth.to(torch::kFloat32).contiguous()),
        src_valid_(config.source_rule == FusionSourceRule::kMvsnetEval ? torch::Tensor()
                                                                       : src_valid.to(torch::kBool).contiguous()),
        src_quad_(config.source_rule == FusionSourceRule::kMvsnetEval ? torch::Tensor()
                  : src_quad.defined()                                 ? src_quad
                                                                       : quad_validity(src_valid_)),
        W_(ref_depth.size(1)),
        Hs_(src_depth.size(0)),
        Ws_(src_depth.size(1)),
        config_(config) {
    const Eigen::Matrix4d T_src_ref = src_camera.T_cam_world * ref_camera.T_world_cam();
    const Eigen::Matrix4d T_ref_src = ref_camera.T_cam_world * src_camera.T_world_cam();
    const Eigen::Matrix3d ray_ref = T_src_ref.topLeftCorner<3, 3>() * ref_camera.K.inverse();
    const Eigen::Matrix3d ray_src = T_ref_src.topLeftCorner<3, 3>() * src_camera.K.inverse();
    to_src_ = src_camera.K * ray_ref;
    to_src_offset_ = src_camera.K * T_src_ref.topRightCorner<3, 1>();
    to_src_z_ = ray_ref.row(2).transpose();
    to_src_z_offset_ = T_src_ref(2, 3);
    to_ref_ = ref_camera.K * ray_src;
    to_ref_offset_ = ref_camera.K * T_ref_src.topRightCorner<3, 1>();
    to_ref_z_ = ray_src.row(2).transpose();
    to_ref_z_offset_ = T_ref_src(2, 3);
    // (data_ptr<T>() checks the type on every call: the loop reads through plain pointers.)
    ref_depth_p_ = ref_depth_.data_ptr<float>();
    ref_valid_p_ = ref_valid_.data_ptr<bool>();
    src_depth_p_ = src_depth_.data_ptr<float>();
    src_valid_p_ = src_valid_.defined() ? src_valid_.data_ptr<bool>() : nullptr;
    src_quad_p_ = src_quad_.defined() ? src_quad_.data_ptr<uint8_t>() : nullptr;
  }

  template <class Sink>
  void rows(int64_t y0, int64_t y1, Sink&& sink) const {
    if (config_.source_rule == FusionSourceRule::kMvsnetEval) {
      rows_of_rule<true>(y0, y1, sink);
    } else {
      rows_of_rule<false>(y0, y1, sink);
    }
  }

 private:
  // The coefficients of the round trip in the precision T of the loop.
  template <typename T>
  struct Geometry {
    Eigen::Matrix<T, 3, 3> A, B;  // reference pixel -> source, source pixel -> reference (times K)
    Eigen::Matrix<T, 3, 1> a, b;  // their offsets
    Eigen::Matrix<T, 3, 1> za, zb;  // depth along the rays (third rows of the rotations)
    T za_offset, zb_offset;
  };
  template <typename T>
  Geometry<T> geometry() const {
    return {to_src_.cast<T>(), to_ref_.cast<T>(), to_src_offset_.cast<T>(), to_ref_offset_.cast<T>(),
            to_src_z_.cast<T>(), to_ref_z_.cast<T>(), static_cast<T>(to_src_z_offset_), static_cast<T>(to_ref_z_offset_)};
  }

  // The loop for one source rule. MVSNet's rule keeps float64 geometry (eval.py's clouds point
  // for point); the default rule runs in float32 like the tensor version used on CUDA (on
  // borderline pixels the two may decide differently). The products with y are hoisted out of
  // the row, a reciprocal replaces two divisions, the distance is compared squared and the
  // relative depth difference without a division.
  template <bool kMvsnet, class Sink>
  void rows_of_rule(int64_t y0, int64_t y1, Sink& sink) const {
    using T = std::conditional_t<kMvsnet, double, float>;
    const float* ref_depth = ref_depth_p_;
    const bool* ref_valid = ref_valid_p_;
    const Geometry<T> g = geometry<T>();
    const T max_px2 = static_cast<T>(config_.max_reprojection_px * config_.max_reprojection_px);
    const float max_rel = static_cast<float>(config_.max_relative_depth);
    const T u_max = static_cast<T>(Ws_ - 1), v_max = static_cast<T>(Hs_ - 1);
    for (int64_t y = y0; y < y1; ++y) {
      const T yd = static_cast<T>(y);
      const T ay0 = g.A(0, 1) * yd, ay1 = g.A(1, 1) * yd, ay2 = g.A(2, 1) * yd, zy = g.za(1) * yd;
      for (int64_t x = 0; x < W_; ++x) {
        const int64_t i = y * W_ + x;
        if (!ref_valid[i]) continue;
        const T d = ref_depth[i], xd = static_cast<T>(x);
        // 1. reference pixel -> source pixel (u, v) at depth z in the source camera.
        const T px = d * (g.A(0, 0) * xd + ay0 + g.A(0, 2)) + g.a(0);
        const T py = d * (g.A(1, 0) * xd + ay1 + g.A(1, 2)) + g.a(1);
        T pz = d * (g.A(2, 0) * xd + ay2 + g.A(2, 2)) + g.a(2);
        const T z = d * (g.za(0) * xd + zy + g.za(2)) + g.za_offset;
        if (std::abs(pz) < T(1e-6)) pz = T(1e-6);
        const T inv_pz = T(1) / pz;
        const T u = px * inv_pz, v = py * inv_pz;
        // 2. the source depth there.
        T d_src;
        if constexpr (kMvsnet) {
          d_src = remap_bilinear(u, v);
        } else {
          if (!(u >= 0 && u <= u_max && v >= 0 && v <= v_max && z > 0)) continue;
          bool all_valid;
          d_src = bilinear_of_estimates(u, v, &all_valid);
          if (!all_valid || !(d_src > 0)) continue;
        }
        // 3. source pixel with that depth -> reference pixel (u', v') at depth z'.
        const T qx = d_src * (g.B(0, 0) * u + g.B(0, 1) * v + g.B(0, 2)) + g.b(0);
        const T qy = d_src * (g.B(1, 0) * u + g.B(1, 1) * v + g.B(1, 2)) + g.b(1);
        T qz = d_src * (g.B(2, 0) * u + g.B(2, 1) * v + g.B(2, 2)) + g.b(2);
        const float z_back = static_cast<float>(d_src * (g.zb(0) * u + g.zb(1) * v + g.zb(2)) + g.zb_offset);
        if (std::abs(qz) < T(1e-9)) qz = T(1e-9);
        const T inv_qz = T(1) / qz;
        // 4. both errors (as eval.py: float32 coordinates and depths).
        const T du = static_cast<float>(qx * inv_qz) - xd;
        const T dv = static_cast<float>(qy * inv_qz) - yd;
        // (|z' - d| / d < max_rel as |z' - d| < max_rel d: d > 0 for every estimate)
        const bool depth_agrees = std::abs(z_back - static_cast<float>(d)) < max_rel * static_cast<float>(d);
        if (!kMvsnet && !(z_back > 0)) continue;
        if (du * du + dv * dv < max_px2 && depth_agrees) sink(i, z_back);
      }
    }
  }

  // Bilinear source depth at (u, v) inside the image (pixel centres); *all_valid: the taps with
  // weight > 0 are all estimates (their weighted validity > 1 - 1e-4, as the tensor version).
  template <typename T>
  T bilinear_of_estimates(T u, T v, bool* all_valid) const {
    const float* depth = src_depth_p_;
    const int64_t x0 = static_cast<int64_t>(u), y0 = static_cast<int64_t>(v);  // (u, v >= 0: the floor)
    const T fx = u - static_cast<T>(x0), fy = v - static_cast<T>(y0);
    const T weights[4] = {(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy};
    const int64_t at = y0 * Ws_ + x0;
    if (src_quad_p_[at]) {  // all four taps are estimates
      *all_valid = true;
      return ((weights[0] * depth[at] + weights[1] * depth[at + 1]) + weights[2] * depth[at + Ws_]) +
             weights[3] * depth[at + Ws_ + 1];
    }
    const bool* valid = src_valid_p_;
    T value = 0, validity = 0;
    for (int k = 0; k < 4; ++k) {
      const int64_t xx = x0 + (k & 1), yy = y0 + (k >> 1);
      if (xx >= Ws_ || yy >= Hs_) continue;  // only at the last column/row, with weight 0
      if (!valid[yy * Ws_ + xx]) continue;  // an invalid tap may hold anything: it reads 0
      value += weights[k] * depth[yy * Ws_ + xx];
      validity += weights[k];
    }
    *all_valid = validity > T(1) - T(1e-4);
    return value;
  }

  // cv2.remap(depth, u, v, INTER_LINEAR) with the default zero border: the coordinates are
  // rounded to 1/32 pixel (float32, round half to even) and the four float32 weights come from
  // that grid; taps outside the image read 0.
  double remap_bilinear(double u, double v) const {
    const float us = static_cast<float>(u) * 32.0f, vs = static_cast<float>(v) * 32.0f;
    if (!(std::abs(us) < 1e9f && std::abs(vs) < 1e9f)) return 0.0;
    const int64_t X = static_cast<int64_t>(std::nearbyint(us)), Y = static_cast<int64_t>(std::nearbyint(vs));
    const int64_t x0 = X >> 5, y0 = Y >> 5;  // floor division by 32
    const float fx = static_cast<float>(X & 31) / 32.0f, fy = static_cast<float>(Y & 31) / 32.0f;
    const float weights[4] = {(1.0f - fy) * (1.0f - fx), (1.0f - fy) * fx, fy * (1.0f - fx), fy * fx};
    const float* depth = src_depth_p_;
    float value = 0.0f;
    for (int k = 0; k < 4; ++k) {
      const int64_t xx = x0 + (k & 1), yy = y0 + (k >> 1);
      const float tap = xx >= 0 && xx < Ws_ && yy >= 0 && yy < Hs_ ? depth[yy * Ws_ + xx] : 0.0f;
      value += (std::isfinite(tap) ? tap : 0.0f) * weights[k];
    }
    return value;
  }

  torch::Tensor ref_depth_, ref_valid_, src_depth_, src_valid_, src_quad_;
  const float* ref_depth_p_ = nullptr;
  const bool* ref_valid_p_ = nullptr;
  const float* src_depth_p_ = nullptr;
  const bool* src_valid_p_ = nullptr;
  const uint8_t* src_quad_p_ = nullptr;
  int64_t W_, Hs_, Ws_;
  FusionConfig config_;
  Eigen::Matrix3d to_src_, to_ref_;
  Eigen::Vector3d to_src_offset_, to_ref_offset_;
  Eigen::Vector3d to_src_z_, to_ref_z_;  // third rows of the rotations: depth along the rays
  double to_src_z_offset_ = 0, to_ref_z_offset_ = 0;
};

// Rows per task of the per-pixel loop: small maps run on one thread (a parallel region costs
// more than it saves there).
int64_t row_grain(int64_t width, size_t num_sources) {
  const int64_t pixels_per_task = 8192 / static_cast<int64_t>(std::max<size_t>(1, num_sources));
  return std::max<int64_t>(1, pixels_per_task / std::max<int64_t>(1, width));
}

// Accumulates the agreement of `sources` into `count` and `depth_sum` of reference `ref`.
void accumulate(const Prepared& ref, const std::vector<const Prepared*>& sources, const FusionConfig& config,
                torch::Tensor& count, torch::Tensor& depth_sum) {
  if (!ref.depth.device().is_cpu()) {
    for (const Prepared* src : sources) {
      auto c = check_consistency_tensor_ops(ref.depth, ref.valid, ref.camera, src->source_depth, src->valid, src->camera, config);
      count += c.agree.to(torch::kInt32);
      depth_sum += torch::where(c.agree, c.depth, torch::zeros_like(c.depth));
    }
    return;
  }
  std::vector<PairTest> tests;
  for (const Prepared* src : sources) {
    tests.emplace_back(ref.depth, ref.valid, ref.camera, src->source_depth, src->valid, src->camera, config, src->quad_valid);
  }
  int32_t* n = count.data_ptr<int32_t>();
  float* sum = depth_sum.data_ptr<float>();
  at::parallel_for(0, ref.depth.size(0), row_grain(ref.depth.size(1), sources.size()), [&](int64_t y0, int64_t y1) {
    for (const auto& test : tests) {
      test.rows(y0, y1, [&](int64_t i, float z) {
        n[i] += 1;
        sum[i] += z;
      });
    }
  });
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
  if (!ref_depth.device().is_cpu()) {
    return check_consistency_tensor_ops(ref_depth, ref_valid, ref_camera, src_depth, src_valid, src_camera, config);
  }
  torch::NoGradGuard no_grad;
  const PairTest test(ref_depth, ref_valid, ref_camera, src_depth, src_valid, src_camera, config);
  ConsistencyCheck out{torch::zeros(ref_depth.sizes(), torch::kBool), torch::zeros(ref_depth.sizes(), torch::kFloat32)};
  bool* agree = out.agree.data_ptr<bool>();
  float* depth = out.depth.data_ptr<float>();
  at::parallel_for(0, ref_depth.size(0), row_grain(ref_depth.size(1), 1), [&](int64_t y0, int64_t y1) {
    test.rows(y0, y1, [&](int64_t i, float z) {
      agree[i] = true;
      depth[i] = z;
    });
  });
  return out;
}

ConsistencyCheck check_consistency_tensor_ops(const torch::Tensor& ref_depth, const torch::Tensor& ref_valid,
                                              const Camera& ref_camera, const torch::Tensor& src_depth,
                                              const torch::Tensor& src_valid, const Camera& src_camera,
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
  const bool mvsnet = config.source_rule == FusionSourceRule::kMvsnetEval;
  torch::Tensor d_src, src_ok;
  if (mvsnet) {
    // cv2.remap: coordinates rounded to 1/32 pixel, taps outside the image read 0.
    auto q = [](const torch::Tensor& c) { return torch::round(c * 32) / 32; };
    grid = torch::stack({q(u) / std::max<double>(1.0, (Ws - 1) / 2.0) - 1.0, q(v) / std::max<double>(1.0, (Hs - 1) / 2.0) - 1.0}, 2)
               .unsqueeze(0);
    d_src = sample(torch::where(torch::isfinite(src_depth), src_depth, torch::zeros_like(src_depth)));
  } else {
    d_src = sample(torch::where(src_valid, src_depth, torch::zeros_like(src_depth)));
    src_ok = sample(src_valid) > 1.0 - 1e-4;
  }

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
  auto agree = ref_valid & (reproj < config.max_reprojection_px) & (rel < config.max_relative_depth);
  if (!mvsnet) agree = agree & inside & src_ok & (d_src > 0) & (z > 0);
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
  seen_through_.clear();
  points_cleared_ = 0;
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
  clear_free_space(entry->view.depth.cpu(), entry->view.valid.cpu(), entry->view.camera);

  auto emit = [&](Entry& e, PointCloud& out) {
    auto fresh = e.view.valid & ~e.emitted & (e.count >= config_.min_agreeing_views);
    out.append(make_points(e.view, fresh, e.depth_sum / (e.count + 1).to(torch::kFloat32), e.count));
    e.emitted |= fresh;
  };
  PointCloud created;
  for (auto& stored : ring_) {
    accumulate(stored->view, {&entry->view}, config_, stored->count, stored->depth_sum);
    emit(*stored, created);
  }
  std::vector<const Prepared*> stored_views;
  for (const auto& stored : ring_) stored_views.push_back(&stored->view);
  accumulate(entry->view, stored_views, config_, entry->count, entry->depth_sum);
  emit(*entry, created);
  ring_.push_back(std::move(entry));
  while (static_cast<int>(ring_.size()) > window_) ring_.pop_front();
  append_points(created);
  return created;
}

void StreamingFusion::append_points(PointCloud& points) {
  if (config_.voxel_size > 0) points = voxel_filter(points, config_.voxel_size, voxels_);
  cloud_.append(points);
  seen_through_.resize(cloud_.size(), 0);
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
  erase_front(seen_through_);
  if (config_.voxel_size > 0) rebuild_voxel_index();
}

void StreamingFusion::clear_free_space(const torch::Tensor& depth, const torch::Tensor& valid, const Camera& camera) {
  if (config_.clear_after_views <= 0 || cloud_.empty()) return;
  const auto evidence = free_space_evidence(cloud_, depth, valid, camera, config_.clear_margin);
  std::vector<uint8_t> remove(cloud_.size(), 0);
  bool any = false;
  for (size_t i = 0; i < evidence.size(); ++i) {
    if (evidence[i] == FreeSpaceEvidence::kSeenAgain) {
      seen_through_[i] = 0;
    } else if (evidence[i] == FreeSpaceEvidence::kSeenThrough && ++seen_through_[i] >= config_.clear_after_views) {
      remove[i] = 1;
      any = true;
    }
  }
  if (!any) return;
  points_cleared_ += static_cast<int64_t>(cloud_.erase(remove));
  size_t kept = 0;
  for (size_t i = 0; i < remove.size(); ++i) {
    if (!remove[i]) seen_through_[kept++] = seen_through_[i];
  }
  seen_through_.resize(kept);
  rebuild_voxel_index();  // the freed voxels may take new points
}

std::vector<FreeSpaceEvidence> free_space_evidence(const PointCloud& cloud, const torch::Tensor& depth,
                                                   const torch::Tensor& valid, const Camera& camera, double margin) {
  const auto d = depth.to(torch::kFloat32).contiguous();
  const auto ok = valid.to(torch::kBool).contiguous();
  const auto da = d.accessor<float, 2>();
  const auto va = ok.accessor<bool, 2>();
  const int64_t H = d.size(0), W = d.size(1);
  std::vector<FreeSpaceEvidence> out(cloud.size(), FreeSpaceEvidence::kNone);
  // One 3x4 projection in float for every point (the cloud can hold millions).
  const Eigen::Matrix<float, 3, 4> P = camera.projection().cast<float>();
  at::parallel_for(0, static_cast<int64_t>(cloud.size()), 4096, [&](int64_t begin, int64_t end) {
    for (int64_t i = begin; i < end; ++i) {
      const Eigen::Vector3f q = P.leftCols<3>() * cloud.points[i] + P.col(3);
      const float z = q.z();  // K's last row is (0 0 1): the z-depth
      if (!(z > 0)) continue;
      const float u = q.x() / z, v = q.y() / z;
      // Pixel centres are at integer coordinates; the whole 3x3 around the nearest must be in the image.
      if (!(u >= 0.5f && v >= 0.5f && u < W - 1.5f && v < H - 1.5f)) continue;
      const int64_t x = std::lround(u), y = std::lround(v);
      if (va[y][x] && std::abs(da[y][x] - z) <= margin * z) {
        out[i] = FreeSpaceEvidence::kSeenAgain;
        continue;
      }
      bool through = true;
      for (int64_t dy = -1; dy <= 1 && through; ++dy) {
        for (int64_t dx = -1; dx <= 1 && through; ++dx) {
          through = va[y + dy][x + dx] && da[y + dy][x + dx] > (1.0 + margin) * z;
        }
      }
      if (through) out[i] = FreeSpaceEvidence::kSeenThrough;
    }
  });
  return out;
}

void StreamingFusion::rebuild_voxel_index() {
  voxels_.clear();
  if (config_.voxel_size <= 0) return;
  for (const auto& p : cloud_.points) voxels_.insert(voxel_key(p, config_.voxel_size));
}

void StreamingFusion::set_config(const FusionConfig& config) {
  config.validate();
  const bool new_voxels = config.voxel_size != config_.voxel_size;
  config_ = config;
  if (new_voxels) rebuild_voxel_index();
}

}  // namespace umvs
