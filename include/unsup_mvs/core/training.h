// Unsupervised training of MVSNet with the robust photometric loss (losses.h), independent of
// where the images come from: a data source (io/training_data.h: MVSNet folders; later rosbags)
// produces TrainingTuples, the Trainer turns them into batches and optimises.
//
// Where the loss is computed: on the network's depth grid (1/4 of the input), where depth pixel
// (i, j) sits on input pixel (4i, 4j) (depth_map_camera). Every loss image is box-filtered over
// 5x5 input pixels centred on (4i, 4j) and sampled there, so images, depth and intrinsics agree
// exactly; this keeps the loss as cheap as the network's output (see docs/training.md). A
// coarse-to-fine run (TrainerConfig::fine) at 1/2 takes the loss on that grid: pixel (i, j) on
// input pixel (2i, 2j), images box-filtered over 3x3.
#pragma once

#include <torch/nn/module.h>
#include <torch/optim/adam.h>
#include <torch/types.h>

#include <cstdint>
#include <string>
#include <vector>

#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/fine_pass.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/losses.h"
#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

// One training example. All images have the network input size (multiples of 32, the same for
// every view), cameras match their image.
struct TrainingTuple {
  std::vector<ViewInput> network_views;  // [0] reference, then the N-1 network source views
  std::vector<ViewInput> loss_views;     // M views warped into the reference by the loss
  double depth_min = 0.0, depth_max = 0.0;
  torch::Tensor depth_gt;                // optional float32 [H,W] on the input grid, 0 = unknown
  // Trained on depth_gt with the supervised loss (rendered data) instead of the photometric
  // loss; otherwise depth_gt, when present, only scores.
  bool supervised = false;
  std::string name;                      // for messages, e.g. "scan1/view 12"

  // Throws std::invalid_argument naming the tuple and the problem.
  void validate() const;
};

// Tensors of a batch of tuples (same sizes and counts), on the device.
struct TrainingBatch {
  torch::Tensor images;        // [B,N,3,H,W] in [0,1]
  torch::Tensor proj;          // [B,N,4,4] mvsnet_projection_matrices
  torch::Tensor proj_map;      // [B,N,4,4] the same on the depth grid (scale 1/map_divisor)
  torch::Tensor depth_values;  // [B,D]
  torch::Tensor loss_ref;      // [B,3,h,w] reference on the depth grid (h = H/4, or H/2: map_divisor)
  torch::Tensor loss_src;      // [B,M,3,h,w]
  torch::Tensor K_ref;         // [B,3,3] depth-grid intrinsics
  torch::Tensor K_src;         // [B,M,3,3]
  torch::Tensor T_src_ref;     // [B,M,4,4]
  torch::Tensor depth_gt;      // [B,h,w] (0 = unknown) or undefined when no tuple has GT
  std::vector<bool> supervised;  // [B]: the tuple is trained on depth_gt (TrainingTuple::supervised)
};
// map_divisor: the depth grid's, 4 (the network's) or 2 (a fine pass at half the input's size).
TrainingBatch make_training_batch(const std::vector<TrainingTuple>& tuples, int num_depth, DepthSampling sampling,
                                  const torch::Device& device, int map_divisor = 4);

// Box filter over the 5x5 input pixels centred on (4i, 4j), sampled there: the image on the
// network's depth grid.  [B,C,H,W] -> [B,C,H/4,W/4]; with map_divisor 2, over the 3x3 centred on
// (2i, 2j)  -> [B,C,H/2,W/2]
torch::Tensor downsample_to_depth_grid(const torch::Tensor& image, int map_divisor = 4);

// Depth errors on the pixels with ground truth (> 0), via evaluate_depth (metrics.h).  est, gt [B,h,w]
struct DepthErrors {
  double mean_abs = 0.0;    // mean |est - gt| (scene units)
  double abs_rel = 0.0;     // mean |est - gt| / gt (scale-free)
  double within_1pct = 0.0; // fraction with |est - gt| <= 1% of gt
  int64_t pixels = 0;
};
DepthErrors depth_errors(const torch::Tensor& est, const torch::Tensor& gt);

// Learning rate over a run: constant, or cosine from TrainerConfig::lr at the first step down to
// lr_min at the last (the decay a long run needs to settle instead of wandering).
enum class LrSchedule { kConstant, kCosine };
LrSchedule parse_lr_schedule(const std::string& name);  // "constant" | "cosine"

struct TrainerConfig {
  LossConfig loss;
  int num_depth = 128;      // hypotheses per depth map during training (multiple of 8)
  double lr = 1e-3;         // Adam (the rate at step 0; see lr_schedule)
  LrSchedule lr_schedule = LrSchedule::kConstant;
  double lr_min = 0.0;      // the cosine schedule's rate at the last step
  double beta1 = 0.95;
  double beta2 = 0.999;
  // Weight of supervised_depth_loss (tuples marked supervised: rendered scenes) against the
  // photometric total (the other tuples: real images, bags) when both train in one optimisation.
  double supervised_weight = 1.0;
  // Weight of the probability volume's mean normalized_plane_entropy (losses.h) in the loss of the
  // photometric tuples: fine-tuning with that loss alone flattens the volume; this term makes every
  // pixel confident, right or not (turned down as a default, docs/training.md). 0 = the paper's loss.
  double entropy_weight = 0.0;
  // Weight of expected_plane_loss (losses.h) in the loss of the photometric tuples: the robust
  // photometric loss of every depth plane, weighed by the network's probability of it, so that the
  // volume itself learns where the views agree. 0 = the paper's loss.
  double plane_loss_weight = 0.0;
  // Tuples per forward pass (0 = the whole batch at once): a step's gradient is accumulated over
  // micro-batches, each with its own BatchNorm statistics, as on the ranks of a distributed job.
  int micro_batch = 0;
  // BatchNorm during training steps: false = normalise with each batch's statistics and update the
  // running ones (training from scratch); true = normalise with the running statistics, as at
  // inference, and leave them as they are (small-batch fine-tuning; scale and shift still learn).
  bool freeze_batchnorm = false;
  // How the model's depth maps are made outside the loss: self-training labels and anchors, and
  // the judge's multi-view consistency (`umvs infer --source-combination`).
  SourceCombination sources = SourceCombination::kVariance;
  // Coarse to fine (fine_pass.h): the network runs both passes (coarse_to_fine_forward) and learns
  // from the loss of each, the first pass's depth brought to the map's grid and weighed by
  // first_pass_loss_weight. Off (planes 0): one pass, as the paper.
  FinePassConfig fine;
  double first_pass_loss_weight = 0.5;
  // The loss's grid: the fine pass's, else the network's (MvsNetConfig::map_divisor).
  int map_divisor(const MvsNetConfig& network) const {
    return fine.enabled() ? fine.resolution_divisor : network.map_divisor();
  }
  void validate() const;
};

// The learning rate of step `step` (0-based) of a run of `total_steps` under config's schedule.
double learning_rate_at(const TrainerConfig& config, int64_t step, int64_t total_steps);

// Scalar results of one step or evaluation (averages over the batches).
struct LossValues {
  double total = 0, photometric = 0, ssim = 0, smoothness = 0, valid_fraction = 0;
  double supervised = 0;  // supervised_depth_loss of the tuples trained on ground truth
  double entropy = 0;     // normalized_plane_entropy of the photometric tuples (when entropy_weight > 0)
  double plane_loss = 0;  // expected_plane_loss of the photometric tuples (when plane_loss_weight > 0)
  int count = 0;
  bool updated = true;    // a step: false when no update was applied (a non-finite loss here or, distributed, on another rank)
  void add(const LossTerms& t);
  LossValues mean() const;
};

struct Evaluation {
  LossValues loss;              // photometric terms on the evaluated tuples
  DepthErrors depth;            // when the tuples have ground truth (depth.pixels > 0)
  int tuples = 0;
};

class Trainer {
 public:
  Trainer(MvsNet model, torch::Device device, TrainerConfig config);

  // One Adam step on a batch of tuples (the model in train mode; see TrainerConfig::freeze_batchnorm).
  LossValues step(const std::vector<TrainingTuple>& batch);
  // Loss (and depth errors when ground truth is present) without gradients, in eval mode; the
  // model is put back in train mode afterwards.
  Evaluation evaluate(const std::vector<TrainingTuple>& tuples);

  // Distributed training: called after every backward pass with the parameters (their grad() set,
  // zeros where a parameter had none) and whether this rank's loss was finite; averages the
  // gradients over the ranks and returns whether every rank's loss was finite (else no rank
  // updates). Unset: one process.
  using GradientSync = std::function<bool(const std::vector<torch::Tensor>& parameters, bool finite)>;
  void set_gradient_sync(GradientSync sync) { gradient_sync_ = std::move(sync); }

  // Adam state as bytes (torch::serialize::OutputArchive), for CheckpointMeta::optimizer_state.
  std::string optimizer_state() const;
  void load_optimizer_state(const std::string& bytes);
  // Sets Adam's learning rate for the following steps (learning_rate_at).
  void set_learning_rate(double lr);
  double learning_rate() const;

  MvsNet& model() { return model_; }
  const TrainerConfig& config() const { return config_; }

 private:
  MvsNet model_;
  torch::Device device_;
  TrainerConfig config_;
  // Train mode, with BatchNorm's statistics frozen when config_.freeze_batchnorm.
  void enter_training_mode();
  // Forward pass and backward of weight * the tuples' loss (gradients accumulate); the loss values.
  LossValues forward_backward(const std::vector<TrainingTuple>& tuples, double weight);

  std::unique_ptr<torch::optim::Adam> optimizer_;
  GradientSync gradient_sync_;
};

// The model's depth on a batch made with config.map_divisor(model's config): one pass (MvsNetImpl::forward), or
// both passes of a coarse-to-fine run (coarse_to_fine_forward), with gradients unless disabled.
MvsOutput training_forward(MvsNetImpl& model, const TrainingBatch& batch, const TrainerConfig& config,
                           bool keep_prob_volume);

// A first pass's depth [B,h,w] on the map's grid of `map_height` rows (naive 2x steps,
// upsample2_naive, differentiable); throws c10::Error when the rows do not double to it.
torch::Tensor on_map_grid(const torch::Tensor& depth, int64_t map_height);

// The loss of `model` on `tuples` (eval mode, no gradients): the held-out photometric loss a
// service compares between a new and the served model, and GT depth errors where available.
Evaluation evaluate_model(MvsNet& model, const std::vector<TrainingTuple>& tuples, const TrainerConfig& config,
                          const torch::Device& device);

// Multi-view consistency of a model's depth on tuples, without ground truth: the reference and
// each loss view are inferred in turn as the reference (sources: the tuple's reference and its
// best other views), and a reference pixel counts as confirmed when fusion's rule accepts it
// against the loss views' depth maps (FusionConfig: confidence, reprojection and relative-depth
// thresholds, agreeing views; min_agreeing_views is capped at the number of loss views).
// A model whose depth got worse has fewer confirmed pixels, whatever its photometric loss.
struct ConsistencyScore {
  double confirmed_fraction = 0.0;  // confirmed reference pixels / all reference depth pixels
  int64_t pixels = 0;               // reference depth pixels evaluated
  int tuples = 0;
};
ConsistencyScore depth_consistency(MvsNet& model, const std::vector<TrainingTuple>& tuples, int num_depth,
                                   const FusionConfig& fusion, const torch::Device& device,
                                   SourceCombination sources = SourceCombination::kVariance);

// The rule that judges an adapted model without labels (eval.csv's `consistent`, hence the trainer
// node's reload decision): a reference pixel counts when at least one other view confirms it within
// fusion's 1 px / 1 % thresholds, at the fusion node's default confidence (0.5). A robot's keyframes
// are often far apart: demanding three confirming views gave every model 0 % on the living room's
// five frames (docs/results.md), which is no evidence either way.
FusionConfig adaptation_judge_rule();

// Self-training labels: each tuple's reference depth where depth_consistency's rule confirms it
// (several views agree within the fusion thresholds, confident), as depth_gt on the input grid
// (0 elsewhere), marked supervised; one output per input tuple (one without a confirmed pixel
// teaches nothing). The tuples' own depth_gt, if any, is never read. `labelled` (optional) receives the confirmed share.
// `unconfirmed_depth` (optional, one map per tuple, reference_depths' size): the label of every
// pixel no view confirms, e.g. the depth of the model a run started from, so that self-training
// keeps the depth it cannot check where it was (anchored self-training).
std::vector<TrainingTuple> pseudo_labelled_tuples(MvsNet& model, const std::vector<TrainingTuple>& tuples,
                                                  int num_depth, const FusionConfig& fusion,
                                                  const torch::Device& device, ConsistencyScore* labelled = nullptr,
                                                  const std::vector<torch::Tensor>* unconfirmed_depth = nullptr,
                                                  SourceCombination sources = SourceCombination::kVariance);

// Each tuple's reference depth map as `model` infers it for depth_consistency (eval mode, no gradients).
// Pixels whose confidence is below `min_confidence` get 0 (as a label: none); 0 keeps every pixel.
// With `keep_unseen`, a pixel that no loss view sees at that depth keeps it whatever its
// confidence: the photometric loss cannot judge such a pixel, so freeing it only lets it drift.
std::vector<torch::Tensor> reference_depths(MvsNet& model, const std::vector<TrainingTuple>& tuples, int num_depth,
                                            const torch::Device& device, double min_confidence = 0.0,
                                            bool keep_unseen = false,
                                            SourceCombination sources = SourceCombination::kVariance);

// The reference pixels that at least one of `t`'s loss views sees with depth `depth` (the
// reference depth map on the depth grid, [h,w]): inside that view's image and in front of it,
// the pixels the photometric loss compares. Occlusion is not tested.  -> bool [h,w]
torch::Tensor seen_by_loss_views(const TrainingTuple& t, const torch::Tensor& depth);

// LibTorch's default CPU generator state as bytes and back (exact resume).
std::string torch_rng_state();
void set_torch_rng_state(const std::string& bytes);

}  // namespace umvs
