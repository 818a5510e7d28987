#include "unsup_mvs/core/geometry.h"

#include <torch/torch.h>

#include <cmath>
#include <stdexcept>

namespace umvs {

namespace F = torch::nn::functional;

const char* to_string(DepthSampling s) {
  return s == DepthSampling::kUniformDepth ? "depth" : "inverse_depth";
}

DepthSampling depth_sampling_from_string(const std::string& s) {
  if (s == "depth") return DepthSampling::kUniformDepth;
  if (s == "inverse_depth") return DepthSampling::kUniformInverseDepth;
  throw std::invalid_argument("unknown depth sampling '" + s + "' (expected depth|inverse_depth)");
}

const char* to_string(FeatureWarp w) { return w == FeatureWarp::kExact ? "exact" : "mvsnet_pytorch"; }

FeatureWarp feature_warp_from_string(const std::string& s) {
  if (s == "exact") return FeatureWarp::kExact;
  if (s == "mvsnet_pytorch") return FeatureWarp::kMvsNetPytorch;
  throw std::invalid_argument("unknown feature warp '" + s + "' (expected exact|mvsnet_pytorch)");
}

torch::Tensor depth_hypotheses(double depth_min, double depth_max, int num_depth,
                               DepthSampling sampling) {
  if (!std::isfinite(depth_min) || !std::isfinite(depth_max) || depth_min <= 0.0 ||
      depth_max <= depth_min) {
    throw std::invalid_argument("impossible depth range [" + std::to_string(depth_min) + ", " +
                                std::to_string(depth_max) +
                                "]: need 0 < depth_min < depth_max, both finite");
  }
  if (num_depth < 2) throw std::invalid_argument("need at least 2 depth hypotheses, got " + std::to_string(num_depth));
  auto values = torch::empty({num_depth}, torch::kFloat64);
  auto* v = values.data_ptr<double>();
  for (int i = 0; i < num_depth; ++i) {
    const double f = static_cast<double>(i) / (num_depth - 1);
    v[i] = sampling == DepthSampling::kUniformDepth
               ? depth_min + i * (depth_max - depth_min) / (num_depth - 1)
               : 1.0 / (1.0 / depth_min + f * (1.0 / depth_max - 1.0 / depth_min));
  }
  return values.to(torch::kFloat32);
}

torch::Tensor depth_to_plane_index(const torch::Tensor& depth, const torch::Tensor& depth_values,
                                   DepthSampling sampling) {
  const int64_t B = depth.size(0), D = depth_values.size(1);
  std::vector<int64_t> shape(depth.dim(), 1);
  shape[0] = B;
  auto first = depth_values.select(1, 0).view(shape), last = depth_values.select(1, D - 1).view(shape);
  if (sampling == DepthSampling::kUniformInverseDepth) {
    return (1.0 / first - 1.0 / depth) / (1.0 / first - 1.0 / last) * static_cast<double>(D - 1);
  }
  return (depth - first) / (last - first) * static_cast<double>(D - 1);
}

torch::Tensor mvsnet_projection_matrix(const Camera& camera, double scale) {
  // float32 arithmetic exactly as MVSNet's data loaders (numpy: K4 = K with rows 0-1 scaled,
  // P = K4 @ E[:3,:4], each product and each sum rounded to float, left to right, no FMA), so
  // the same cameras give bit-identical cost volumes. Casting every step to float keeps the
  // compiler from fusing multiply-adds.
  const auto f = [](double x) { return static_cast<float>(x); };
  auto P = torch::zeros({4, 4}, torch::kFloat32);
  auto acc = P.accessor<float, 2>();
  for (int r = 0; r < 3; ++r) {
    const float row_scale = r < 2 ? f(scale) : 1.0f;
    const float k0 = f(f(camera.K(r, 0)) * row_scale), k1 = f(f(camera.K(r, 1)) * row_scale),
                k2 = f(f(camera.K(r, 2)) * row_scale);
    for (int c = 0; c < 4; ++c) {
      const float p0 = f(static_cast<double>(k0) * f(camera.T_cam_world(0, c)));
      const float p1 = f(static_cast<double>(k1) * f(camera.T_cam_world(1, c)));
      const float p2 = f(static_cast<double>(k2) * f(camera.T_cam_world(2, c)));
      acc[r][c] = f(static_cast<double>(f(static_cast<double>(p0) + p1)) + p2);
    }
  }
  acc[3][3] = 1.0f;
  return P;
}

torch::Tensor mvsnet_projection_matrices(const std::vector<Camera>& cameras, double scale) {
  std::vector<torch::Tensor> mats;
  for (const auto& c : cameras) mats.push_back(mvsnet_projection_matrix(c, scale));
  return torch::stack(mats);
}

namespace {
torch::Tensor to_tensor(const Eigen::MatrixXd& m) {
  auto out = torch::empty({m.rows(), m.cols()}, torch::kFloat64);
  auto acc = out.accessor<double, 2>();
  for (int r = 0; r < m.rows(); ++r)
    for (int c = 0; c < m.cols(); ++c) acc[r][c] = m(r, c);
  return out.to(torch::kFloat32);
}
}  // namespace

torch::Tensor intrinsics_tensor(const Camera& camera) { return to_tensor(camera.K); }

torch::Tensor relative_pose_tensor(const Camera& ref, const Camera& src) {
  return to_tensor(src.T_cam_world * ref.T_world_cam());
}

SourceProjection project_to_source(const torch::Tensor& K_ref, const torch::Tensor& K_src,
                                   const torch::Tensor& T_src_ref, const torch::Tensor& depth) {
  const int64_t B = depth.size(0), H = depth.size(1), W = depth.size(2);
  auto opts = depth.options();
  auto ys = torch::arange(H, opts).view({H, 1}).expand({H, W});
  auto xs = torch::arange(W, opts).view({1, W}).expand({H, W});
  auto pix = torch::stack({xs, ys, torch::ones_like(xs)}).view({1, 3, H * W});  // [1,3,HW]
  auto rays = torch::matmul(torch::inverse(K_ref), pix);                             // [B,3,HW]
  auto pts = rays * depth.reshape({B, 1, H * W});                                    // ref camera
  auto R = T_src_ref.slice(1, 0, 3).slice(2, 0, 3);
  auto t = T_src_ref.slice(1, 0, 3).slice(2, 3, 4);
  auto pts_src = torch::matmul(R, pts) + t;                                          // [B,3,HW]
  auto proj = torch::matmul(K_src, pts_src);
  auto z = proj.select(1, 2);                                                        // [B,HW]
  // Keep the division finite for points behind the camera; they are masked out by z > 0.
  auto z_safe = torch::where(z.abs() < 1e-6, torch::full_like(z, 1e-6), z);
  auto uv = proj.slice(1, 0, 2) / z_safe.unsqueeze(1);                               // [B,2,HW]
  return {uv.permute({0, 2, 1}).reshape({B, H, W, 2}), pts_src.select(1, 2).reshape({B, H, W})};
}

HomographyRays homography_rays(const torch::Tensor& src_proj, const torch::Tensor& ref_proj, int64_t height,
                               int64_t width) {
  torch::NoGradGuard no_grad;  // the rays depend on cameras only: no gradient needed
  const int64_t B = src_proj.size(0), H = height, W = width;
  auto proj = torch::matmul(src_proj, torch::inverse(ref_proj));
  auto rot = proj.slice(1, 0, 3).slice(2, 0, 3);    // [B,3,3]
  auto trans = proj.slice(1, 0, 3).slice(2, 3, 4);  // [B,3,1]
  auto opts = src_proj.options();
  auto grid = torch::meshgrid({torch::arange(H, opts), torch::arange(W, opts)}, "ij");
  auto y = grid[0].reshape({H * W}), x = grid[1].reshape({H * W});
  auto xyz = torch::stack({x, y, torch::ones_like(x)}).unsqueeze(0).expand({B, 3, H * W});
  return {torch::matmul(rot, xyz), trans};
}

torch::Tensor homography_warp(const torch::Tensor& src_fea, const torch::Tensor& src_proj,
                              const torch::Tensor& ref_proj, const torch::Tensor& depth_values, FeatureWarp warp) {
  const int64_t B = src_fea.size(0), C = src_fea.size(1), H = src_fea.size(2), W = src_fea.size(3);
  const int64_t D = depth_values.size(1);
  TORCH_CHECK(depth_values.dim() == 2 || (depth_values.dim() == 4 && depth_values.size(2) == H && depth_values.size(3) == W),
              "homography_warp: depth_values must be [B,D] or [B,D,H,W] at the features' size, got ", depth_values.sizes());
  torch::Tensor sample_grid;
  {
    torch::NoGradGuard no_grad;  // the sampling grid depends on cameras only: no gradient needed
    const auto rays = homography_rays(src_proj, ref_proj, H, W);
    const auto depth = depth_values.dim() == 2 ? depth_values.view({B, 1, D, 1}) : depth_values.reshape({B, 1, D, H * W});
    auto rot_depth_xyz = rays.rot_xyz.unsqueeze(2) * depth;  // [B,3,D,HW]
    auto proj_xyz = rot_depth_xyz + rays.trans.view({B, 3, 1, 1});
    auto proj_xy = proj_xyz.slice(1, 0, 2) / proj_xyz.slice(1, 2, 3);
    auto gx = proj_xy.select(1, 0) / ((W - 1) / 2.0) - 1;
    auto gy = proj_xy.select(1, 1) / ((H - 1) / 2.0) - 1;
    sample_grid = torch::stack({gx, gy}, 3);  // [B,D,HW,2]
    // A point on the source camera's plane (z = 0) divides to inf/NaN, and grid_sample turns that
    // into NaN features; send it outside the image instead (zero padding, like any point out of view).
    // Finite coordinates are left exactly as MVSNet computes them.
    sample_grid = torch::where(torch::isfinite(sample_grid), sample_grid, torch::full_like(sample_grid, -2.0));
  }
  auto warped = F::grid_sample(src_fea, sample_grid.view({B, D * H, W, 2}),
                               F::GridSampleFuncOptions()
                                   .mode(torch::kBilinear)
                                   .padding_mode(torch::kZeros)
                                   .align_corners(warp == FeatureWarp::kExact));
  return warped.view({B, C, D, H, W});
}

InverseWarp inverse_warp(const torch::Tensor& src_image, const torch::Tensor& K_ref,
                         const torch::Tensor& K_src, const torch::Tensor& T_src_ref,
                         const torch::Tensor& depth) {
  const int64_t H = src_image.size(2), W = src_image.size(3);
  auto p = project_to_source(K_ref, K_src, T_src_ref, depth);
  auto u = p.uv.select(3, 0), v = p.uv.select(3, 1);
  // Pixel centres: u = 0 is the centre of the first column -> -1 + 1/W with align_corners=false,
  // equivalently u / (W-1) * 2 - 1 with align_corners=true. We use the latter.
  auto grid = torch::stack({u / ((W - 1) / 2.0) - 1.0, v / ((H - 1) / 2.0) - 1.0}, 3);
  auto warped = F::grid_sample(src_image, grid,
                               F::GridSampleFuncOptions()
                                   .mode(torch::kBilinear)
                                   .padding_mode(torch::kZeros)
                                   .align_corners(true));
  return {warped, inside_source(p, W, H).unsqueeze(1).to(src_image.scalar_type())};
}

torch::Tensor inside_source(const SourceProjection& p, int64_t width, int64_t height) {
  auto u = p.uv.select(3, 0), v = p.uv.select(3, 1);
  return (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1) & (p.z > 1e-6);
}

}  // namespace umvs
