// The geometric consistency test of depth maps (check_consistency in unsup_mvs/core/fusion.h): the
// CPU per-pixel loop, the tensor version for other devices, and the accumulation of agreeing
// sources that batch and streaming fusion share.
#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "fusion_internal.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/geometry.h"

namespace umvs {

namespace F = torch::nn::functional;

namespace fusion_detail {

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

}  // namespace fusion_detail

using namespace fusion_detail;

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

}  // namespace umvs
