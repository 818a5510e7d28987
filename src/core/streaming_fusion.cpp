// Streaming fusion (StreamingFusion in unsup_mvs/core/fusion.h): a ring of recent depth estimates,
// points emitted as soon as enough estimates agree, and free-space clearing of what moved.
#include <ATen/Parallel.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "fusion_internal.h"
#include "unsup_mvs/core/fusion.h"

namespace umvs {

using namespace fusion_detail;

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
