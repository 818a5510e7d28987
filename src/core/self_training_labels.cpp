// Labels and scores from the model's own multi-view consistency: the self-training labels
// (pseudo_labelled_tuples), the adaptation judge's consistency (depth_consistency) and what the
// loss views see (seen_by_loss_views). Declared in training.h.
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/core/metrics.h"
#include "unsup_mvs/core/training.h"

namespace umvs {

namespace F = torch::nn::functional;

namespace {

// The reference and the loss views of a tuple, reference first.
std::vector<ViewInput> tuple_views(const TrainingTuple& t) {
  std::vector<ViewInput> views{t.network_views.front()};
  views.insert(views.end(), t.loss_views.begin(), t.loss_views.end());
  return views;
}

// The network's input with views[i] as the reference: its sources are the other views in order,
// as many as the tuple's network views have.
std::vector<ViewInput> input_with_reference(const TrainingTuple& t, const std::vector<ViewInput>& views, size_t i) {
  const size_t sources_per_view = t.network_views.size() - 1;
  std::vector<ViewInput> input{views[i]};
  for (size_t j = 0; j < views.size() && input.size() <= sources_per_view; ++j) {
    if (j != i) input.push_back(views[j]);
  }
  return input;
}

// Fusion's verdict on a tuple's reference: the reference and each loss view are inferred in turn
// as the reference (sources: the tuple's other views, reference first), and the reference's
// depth map is checked against the loss views' maps.
DepthFusion::Agreement reference_agreement(DepthEstimator& estimator, const TrainingTuple& t,
                                           const FusionConfig& fusion) {
  t.validate();
  const std::vector<ViewInput> views = tuple_views(t);
  std::vector<FusionView> maps;
  for (size_t i = 0; i < views.size(); ++i) {
    const DepthMap m = estimator.estimate(input_with_reference(t, views, i), t.depth_min, t.depth_max);
    maps.push_back(FusionView{static_cast<int64_t>(i), m.depth, m.confidence, {}, m.camera});
  }
  FusionConfig config = fusion;
  config.min_agreeing_views = std::min<int>(config.min_agreeing_views, static_cast<int>(t.loss_views.size()));
  config.max_source_views = static_cast<int>(t.loss_views.size());
  std::vector<std::vector<int>> sources(maps.size(), std::vector<int>{0});  // only the reference is used
  sources[0].clear();
  for (size_t j = 1; j < maps.size(); ++j) sources[0].push_back(static_cast<int>(j));
  return DepthFusion(config, estimator.device()).agreement(maps, sources)[0];
}

DepthEstimator eval_estimator(MvsNet& model, int num_depth, const torch::Device& device, SourceCombination sources) {
  DepthEstimatorConfig config;
  config.num_depth = num_depth;
  config.source_combination = sources;
  return DepthEstimator(model, device, config);  // eval mode, no gradients
}

}  // namespace

ConsistencyScore depth_consistency(MvsNet& model, const std::vector<TrainingTuple>& tuples, int num_depth,
                                   const FusionConfig& fusion, const torch::Device& device, SourceCombination sources) {
  const bool was_training = model->is_training();
  DepthEstimator estimator = eval_estimator(model, num_depth, device, sources);
  ConsistencyScore score;
  int64_t confirmed = 0;
  for (const auto& t : tuples) {
    const auto agreement = reference_agreement(estimator, t, fusion);
    confirmed += agreement.confirmed.sum().item<int64_t>();
    score.pixels += agreement.confirmed.numel();
    ++score.tuples;
  }
  model->train(was_training);
  if (score.pixels > 0) score.confirmed_fraction = static_cast<double>(confirmed) / static_cast<double>(score.pixels);
  return score;
}

FusionConfig adaptation_judge_rule() {
  FusionConfig rule;
  rule.min_confidence = 0.5;
  rule.max_reprojection_px = 1.0;
  rule.max_relative_depth = 0.01;
  rule.min_agreeing_views = 1;
  return rule;
}

std::vector<torch::Tensor> reference_depths(MvsNet& model, const std::vector<TrainingTuple>& tuples, int num_depth,
                                            const torch::Device& device, double min_confidence, bool keep_unseen,
                                            SourceCombination sources) {
  const bool was_training = model->is_training();
  DepthEstimator estimator = eval_estimator(model, num_depth, device, sources);
  std::vector<torch::Tensor> depths;
  for (const auto& t : tuples) {
    t.validate();
    const auto estimate = estimator.estimate(input_with_reference(t, tuple_views(t), 0), t.depth_min, t.depth_max);
    if (min_confidence <= 0.0) {
      depths.push_back(estimate.depth);
      continue;
    }
    auto kept = estimate.confidence >= min_confidence;
    if (keep_unseen) kept = kept | seen_by_loss_views(t, estimate.depth).logical_not().to(kept.device());
    depths.push_back(torch::where(kept, estimate.depth, torch::zeros_like(estimate.depth)));
  }
  model->train(was_training);
  return depths;
}

torch::Tensor seen_by_loss_views(const TrainingTuple& t, const torch::Tensor& depth) {
  // The map's grid (1/4 of the input for MVSNet, 1/2 for sweep2d) from its width.
  const int input_width = t.network_views.at(0).camera.width;
  const int divisor = depth.dim() == 2 && depth.size(1) > 0 && depth.size(1) * 2 == input_width ? 2 : 4;
  const Camera ref = depth_map_camera(t.network_views.at(0).camera, 1.0 / divisor);
  if (depth.dim() != 2 || depth.size(0) != ref.height || depth.size(1) != ref.width) {
    throw std::invalid_argument("seen_by_loss_views: tuple " + t.name + " has a " + std::to_string(ref.width) + "x" +
                                std::to_string(ref.height) + " depth grid, got a map of " +
                                std::to_string(depth.dim() == 2 ? depth.size(1) : -1) + "x" +
                                std::to_string(depth.dim() == 2 ? depth.size(0) : -1));
  }
  const auto d = depth.to(torch::kCPU, torch::kFloat32).unsqueeze(0);
  const auto K_ref = intrinsics_tensor(ref).unsqueeze(0);
  auto seen = torch::zeros({ref.height, ref.width}, torch::kBool);
  for (const auto& v : t.loss_views) {
    const Camera src = depth_map_camera(v.camera, 1.0 / divisor);
    const auto p = project_to_source(K_ref, intrinsics_tensor(src).unsqueeze(0),
                                     relative_pose_tensor(ref, src).unsqueeze(0), d);
    seen |= inside_source(p, src.width, src.height)[0];  // the photometric loss's own test
  }
  return seen;
}

std::vector<TrainingTuple> pseudo_labelled_tuples(MvsNet& model, const std::vector<TrainingTuple>& tuples,
                                                  int num_depth, const FusionConfig& fusion,
                                                  const torch::Device& device, ConsistencyScore* labelled,
                                                  const std::vector<torch::Tensor>* unconfirmed_depth,
                                                  SourceCombination sources) {
  if (unconfirmed_depth && unconfirmed_depth->size() != tuples.size()) {
    throw std::invalid_argument("pseudo_labelled_tuples: " + std::to_string(unconfirmed_depth->size()) +
                                " depth maps for the unconfirmed pixels of " + std::to_string(tuples.size()) + " tuples");
  }
  const bool was_training = model->is_training();
  DepthEstimator estimator = eval_estimator(model, num_depth, device, sources);
  std::vector<TrainingTuple> out;
  ConsistencyScore score;
  int64_t confirmed = 0;
  for (size_t k = 0; k < tuples.size(); ++k) {
    const TrainingTuple& t = tuples[k];
    const auto agreement = reference_agreement(estimator, t, fusion);
    const int64_t n = agreement.confirmed.sum().item<int64_t>();
    confirmed += n;
    score.pixels += agreement.confirmed.numel();
    ++score.tuples;
    // Depth pixel (i, j) sits on input pixel (4i, 4j), where make_training_batch reads labels.
    TrainingTuple p = t;
    const auto& ref = t.network_views.front().camera;
    p.depth_gt = torch::zeros({ref.height, ref.width}, torch::kFloat32);
    const int64_t h = agreement.depth.size(0), w = agreement.depth.size(1);
    torch::Tensor label = agreement.depth;
    if (unconfirmed_depth) {
      const torch::Tensor& kept = (*unconfirmed_depth)[k];
      if (kept.sizes() != agreement.depth.sizes()) {
        throw std::invalid_argument("pseudo_labelled_tuples: the unconfirmed pixels' depth map of " + t.name +
                                    " has another size than the reference's depth map");
      }
      label = torch::where(agreement.confirmed, agreement.depth, kept.to(agreement.depth.device()));
    }
    p.depth_gt.slice(0, 0, 4 * h, 4).slice(1, 0, 4 * w, 4).copy_(label);
    p.supervised = true;
    p.name = t.name + " (pseudo-labelled)";
    out.push_back(std::move(p));
  }
  model->train(was_training);
  if (score.pixels > 0) score.confirmed_fraction = static_cast<double>(confirmed) / static_cast<double>(score.pixels);
  if (labelled) *labelled = score;
  return out;
}

}  // namespace umvs
