#include "unsup_mvs/core/training.h"

#include <ATen/CPUGeneratorImpl.h>
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <mutex>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/core/metrics.h"

namespace umvs {

namespace F = torch::nn::functional;

void TrainingTuple::validate() const {
  auto bad = [&](const std::string& what) { throw std::invalid_argument("training tuple " + name + ": " + what); };
  if (network_views.size() < 2) bad("needs a reference and at least one network source view");
  if (loss_views.empty()) bad("needs at least one loss view");
  if (!(depth_min > 0) || !(depth_max > depth_min) || !std::isfinite(depth_max)) {
    bad("impossible depth range [" + std::to_string(depth_min) + ", " + std::to_string(depth_max) + "]");
  }
  const auto& ref = network_views.front().camera;
  if (ref.width % 32 != 0 || ref.height % 32 != 0) bad("image size must be a multiple of 32");
  auto check = [&](const ViewInput& v, const std::string& what) {
    v.camera.validate(name + " " + what);
    if (!v.image.defined() || v.image.dim() != 3 || v.image.size(2) != 3 || v.image.scalar_type() != torch::kUInt8) {
      bad(what + ": image must be uint8 [H,W,3]");
    }
    if (v.image.size(0) != ref.height || v.image.size(1) != ref.width || v.camera.width != ref.width ||
        v.camera.height != ref.height) {
      bad(what + ": image or camera size differs from the reference's " + std::to_string(ref.width) + "x" +
          std::to_string(ref.height));
    }
  };
  for (size_t i = 0; i < network_views.size(); ++i) check(network_views[i], "network view " + std::to_string(i));
  for (size_t i = 0; i < loss_views.size(); ++i) check(loss_views[i], "loss view " + std::to_string(i));
  if (depth_gt.defined() && (depth_gt.dim() != 2 || depth_gt.size(0) != ref.height || depth_gt.size(1) != ref.width)) {
    bad("ground-truth depth must be [H,W] like the reference image");
  }
  if (supervised && !depth_gt.defined()) bad("supervised training needs ground-truth depth, and there is none");
}

torch::Tensor downsample_to_depth_grid(const torch::Tensor& image, int map_divisor) {
  if (map_divisor != 2 && map_divisor != 4) {
    throw std::invalid_argument("depth grid: map divisor must be 2 or 4, got " + std::to_string(map_divisor));
  }
  const int64_t size = map_divisor + 1;  // odd, centred on the grid's pixel
  return F::avg_pool2d(image,
                       F::AvgPool2dFuncOptions(size).stride(map_divisor).padding(map_divisor / 2).count_include_pad(false));
}

TrainingBatch make_training_batch(const std::vector<TrainingTuple>& tuples, int num_depth, DepthSampling sampling,
                                  const torch::Device& device, int map_divisor) {
  if (tuples.empty()) throw std::invalid_argument("make_training_batch: empty batch");
  if (map_divisor != 2 && map_divisor != 4) {
    throw std::invalid_argument("make_training_batch: map divisor must be 2 or 4, got " + std::to_string(map_divisor));
  }
  const double map_scale = 1.0 / map_divisor;
  std::vector<torch::Tensor> images, proj, proj_map, depth_values, loss_ref, loss_src, K_ref, K_src, T, gt;
  std::vector<bool> b_supervised;
  bool any_gt = false;
  for (const auto& t : tuples) {
    t.validate();
    if (t.network_views.size() != tuples[0].network_views.size() || t.loss_views.size() != tuples[0].loss_views.size() ||
        t.network_views[0].camera.width != tuples[0].network_views[0].camera.width ||
        t.network_views[0].camera.height != tuples[0].network_views[0].camera.height) {
      throw std::invalid_argument("make_training_batch: tuple " + t.name + " differs in size or view count from " +
                                  tuples[0].name);
    }
    std::vector<torch::Tensor> imgs;
    std::vector<Camera> cams;
    for (const auto& v : t.network_views) {
      imgs.push_back(rgb8_to_float(v.image));
      cams.push_back(v.camera);
    }
    images.push_back(torch::stack(imgs));
    proj.push_back(mvsnet_projection_matrices(cams));
    proj_map.push_back(mvsnet_projection_matrices(cams, map_scale));
    depth_values.push_back(depth_hypotheses(t.depth_min, t.depth_max, num_depth, sampling));

    const Camera ref_cam = depth_map_camera(t.network_views[0].camera, map_scale);
    loss_ref.push_back(downsample_to_depth_grid(imgs[0].unsqueeze(0), map_divisor).squeeze(0));
    K_ref.push_back(intrinsics_tensor(ref_cam));
    std::vector<torch::Tensor> srcs, ks, ts;
    for (const auto& v : t.loss_views) {
      srcs.push_back(downsample_to_depth_grid(rgb8_to_float(v.image).unsqueeze(0), map_divisor).squeeze(0));
      const Camera c = depth_map_camera(v.camera, map_scale);
      ks.push_back(intrinsics_tensor(c));
      ts.push_back(relative_pose_tensor(ref_cam, c));
    }
    loss_src.push_back(torch::stack(srcs));
    K_src.push_back(torch::stack(ks));
    T.push_back(torch::stack(ts));
    const int H = ref_cam.height, W = ref_cam.width;
    b_supervised.push_back(t.supervised);
    if (t.depth_gt.defined()) {
      any_gt = true;
      gt.push_back(t.depth_gt.to(torch::kFloat32)
                       .slice(0, 0, H * map_divisor, map_divisor)
                       .slice(1, 0, W * map_divisor, map_divisor)
                       .contiguous());
    } else {
      gt.push_back(torch::zeros({H, W}));
    }
  }
  TrainingBatch b;
  b.images = torch::stack(images).to(device);
  b.proj = torch::stack(proj).to(device);
  b.proj_map = torch::stack(proj_map).to(device);
  b.depth_values = torch::stack(depth_values).to(device);
  b.loss_ref = torch::stack(loss_ref).to(device);
  b.loss_src = torch::stack(loss_src).to(device);
  b.K_ref = torch::stack(K_ref).to(device);
  b.K_src = torch::stack(K_src).to(device);
  b.T_src_ref = torch::stack(T).to(device);
  if (any_gt) b.depth_gt = torch::stack(gt).to(device);
  b.supervised = std::move(b_supervised);
  return b;
}

DepthErrors depth_errors(const torch::Tensor& est, const torch::Tensor& gt) {
  DepthMetricsConfig cfg;
  cfg.rel_thresholds = {0.01};
  const auto m = evaluate_depth(est.detach().reshape({1, -1}).cpu(), gt.detach().reshape({1, -1}).cpu(), {}, cfg);
  DepthErrors out;
  out.pixels = m.evaluated_pixels;
  if (out.pixels == 0) return out;
  out.mean_abs = m.mae;
  out.abs_rel = m.abs_rel;
  out.within_1pct = m.within_rel.at(0);
  return out;
}

double learning_rate_at(const TrainerConfig& config, int64_t step, int64_t total_steps) {
  if (config.lr_schedule == LrSchedule::kConstant || total_steps <= 1) return config.lr;
  const double progress = std::clamp(static_cast<double>(step) / static_cast<double>(total_steps - 1), 0.0, 1.0);
  return config.lr_min + 0.5 * (config.lr - config.lr_min) * (1.0 + std::cos(M_PI * progress));
}

LrSchedule parse_lr_schedule(const std::string& name) {
  if (name == "constant") return LrSchedule::kConstant;
  if (name == "cosine") return LrSchedule::kCosine;
  throw std::invalid_argument("learning-rate schedule must be constant or cosine, got '" + name + "'");
}

void TrainerConfig::validate() const {
  loss.validate();
  if (num_depth < 8 || num_depth % 8 != 0) {
    throw std::invalid_argument("num_depth must be a positive multiple of 8, got " + std::to_string(num_depth));
  }
  if (!(lr > 0) || !std::isfinite(lr)) throw std::invalid_argument("learning rate must be positive");
  if (!(lr_min >= 0) || !(lr_min <= lr)) {
    throw std::invalid_argument("the final learning rate (lr_min " + std::to_string(lr_min) + ") must be in [0, lr]");
  }
  if (!(beta1 >= 0 && beta1 < 1) || !(beta2 >= 0 && beta2 < 1)) throw std::invalid_argument("Adam betas must be in [0,1)");
  if (!(supervised_weight >= 0) || !std::isfinite(supervised_weight)) {
    throw std::invalid_argument("supervised weight must be finite and >= 0");
  }
  if (!(entropy_weight >= 0) || !std::isfinite(entropy_weight)) {
    throw std::invalid_argument("entropy weight must be finite and >= 0");
  }
  if (!(plane_loss_weight >= 0) || !std::isfinite(plane_loss_weight)) {
    throw std::invalid_argument("plane loss weight must be finite and >= 0");
  }
  if (micro_batch < 0) throw std::invalid_argument("micro batch must be >= 0 (0 = the whole batch), got " + std::to_string(micro_batch));
  fine.validate();
  if (fine.enabled() && (entropy_weight > 0 || plane_loss_weight > 0)) {
    throw std::invalid_argument("coarse-to-fine training takes neither the entropy nor the plane loss (weights 0)");
  }
  if (!(first_pass_loss_weight >= 0) || !std::isfinite(first_pass_loss_weight)) {
    throw std::invalid_argument("first pass loss weight must be finite and >= 0");
  }
}

void LossValues::add(const LossTerms& t) {
  total += t.total.item<double>();
  photometric += t.photometric.item<double>();
  ssim += t.ssim.item<double>();
  smoothness += t.smoothness.item<double>();
  valid_fraction += t.valid_fraction.item<double>();
  ++count;
}

LossValues LossValues::mean() const {
  if (count == 0) return *this;
  LossValues m = *this;
  for (double* v : {&m.total, &m.photometric, &m.ssim, &m.smoothness, &m.valid_fraction, &m.supervised, &m.entropy, &m.plane_loss}) *v /= count;
  m.count = 1;
  return m;
}

namespace {

// BatchNorm layers to eval mode: they normalise with their running statistics and update none.
void freeze_batchnorm_statistics(torch::nn::Module& model) {
  for (const auto& m : model.modules(/*include_self=*/false)) {
    if (dynamic_cast<torch::nn::BatchNorm2dImpl*>(m.get()) || dynamic_cast<torch::nn::BatchNorm3dImpl*>(m.get())) {
      m->eval();
    }
  }
}

}  // namespace

void Trainer::enter_training_mode() {
  model_->train();
  if (config_.freeze_batchnorm) freeze_batchnorm_statistics(*model_);
}

Trainer::Trainer(MvsNet model, torch::Device device, TrainerConfig config)
    : model_(std::move(model)), device_(device), config_(std::move(config)) {
  config_.validate();
  model_->to(device_);
  enter_training_mode();
  optimizer_ = std::make_unique<torch::optim::Adam>(
      model_->parameters(),
      torch::optim::AdamOptions(config_.lr).betas(std::make_tuple(config_.beta1, config_.beta2)));
}

LossValues Trainer::step(const std::vector<TrainingTuple>& tuples) {
  enter_training_mode();
  // BatchNorm (unless frozen) updates its running statistics in the forward pass: keep them, so
  // that a batch that turns out broken leaves no trace (NaN statistics would ruin every later
  // evaluation).
  std::vector<torch::Tensor> buffers_before;
  for (const auto& buffer : model_->buffers()) buffers_before.push_back(buffer.clone());
  optimizer_->zero_grad();
  // The gradient of the batch's mean loss, one micro-batch at a time (BatchNorm statistics per
  // micro-batch, as on the ranks of a distributed job).
  const size_t n = tuples.size();
  const size_t micro = config_.micro_batch > 0 ? static_cast<size_t>(config_.micro_batch) : n;
  LossValues values;
  values.count = 1;
  bool finite = true;
  for (size_t start = 0; start < n && finite; start += micro) {
    const std::vector<TrainingTuple> part(tuples.begin() + start, tuples.begin() + std::min(n, start + micro));
    const double weight = static_cast<double>(part.size()) / n;
    const LossValues v = forward_backward(part, weight);
    values.total += weight * v.total;
    values.photometric += weight * v.photometric;
    values.ssim += weight * v.ssim;
    values.smoothness += weight * v.smoothness;
    values.valid_fraction += weight * v.valid_fraction;
    values.supervised += weight * v.supervised;
    values.entropy += weight * v.entropy;
    values.plane_loss += weight * v.plane_loss;
    finite = std::isfinite(v.total);
  }
  if (!finite) values.total = NAN;
  bool all_finite = finite;
  if (gradient_sync_) {
    // Every rank takes part in the all-reduce, also with a broken batch (zero gradients), so that
    // none waits for it; a broken batch anywhere skips the update everywhere.
    auto parameters = model_->parameters();
    for (auto& p : parameters) {
      if (!p.grad().defined() || !finite) p.mutable_grad() = torch::zeros_like(p);
    }
    all_finite = gradient_sync_(parameters, finite);
  }
  if (!all_finite) {  // no update from a broken batch; the caller reports it
    torch::NoGradGuard no_grad;
    auto buffers = model_->buffers();
    for (size_t i = 0; i < buffers.size(); ++i) buffers[i].copy_(buffers_before[i]);
    values.updated = false;
    return values;
  }
  optimizer_->step();
  return values;
}

MvsOutput training_forward(MvsNetImpl& model, const TrainingBatch& b, const TrainerConfig& config,
                           bool keep_prob_volume) {
  if (!config.fine.enabled()) return model.forward(b.images, b.proj, b.depth_values, keep_prob_volume);
  return coarse_to_fine_forward(model, b.images, b.proj, b.depth_values, config.fine, b.proj_map);
}

torch::Tensor on_map_grid(const torch::Tensor& depth, int64_t map_height) {
  auto map = depth;
  while (map.size(1) < map_height) map = upsample2_naive(map.unsqueeze(1)).squeeze(1);
  TORCH_CHECK(map.size(1) == map_height, "on_map_grid: a ", depth.size(1), "-row depth does not double to ", map_height,
              " rows");
  return map;
}

LossValues Trainer::forward_backward(const std::vector<TrainingTuple>& tuples, double weight) {
  const auto b = make_training_batch(tuples, config_.num_depth, model_->config().depth_sampling, device_,
                                     config_.map_divisor(model_->config()));
  const bool entropy_term = config_.entropy_weight > 0, plane_term = config_.plane_loss_weight > 0;
  const auto out = training_forward(*model_, b, config_, /*keep_prob_volume=*/entropy_term || plane_term);
  // The depths that learn: the map, and with a fine pass also the first pass's (on the map's grid).
  std::vector<std::pair<torch::Tensor, double>> depths = {{out.depth, 1.0}};
  if (config_.fine.enabled() && config_.first_pass_loss_weight > 0) {
    depths.emplace_back(on_map_grid(out.depth_init, out.depth.size(1)), config_.first_pass_loss_weight);
  }
  // Which tuples learn from ground truth and which from photometric consistency.
  std::vector<int64_t> supervised_rows, photometric_rows;
  for (size_t i = 0; i < b.supervised.size(); ++i) {
    (b.supervised[i] ? supervised_rows : photometric_rows).push_back(static_cast<int64_t>(i));
  }
  const double batch_size = static_cast<double>(b.supervised.size());
  auto rows = [&](const torch::Tensor& t, const std::vector<int64_t>& r) {
    return r.size() == b.supervised.size() ? t : t.index_select(0, torch::tensor(r, torch::kLong).to(t.device()));
  };
  torch::Tensor total = torch::zeros({}, out.depth.options());
  LossValues values;  // the terms of the map's depth
  if (!photometric_rows.empty()) {
    const auto& r = photometric_rows;
    torch::Tensor photometric_total = torch::zeros({}, out.depth.options());
    for (size_t i = 0; i < depths.size(); ++i) {
      const auto& [depth, depth_weight] = depths[i];
      const auto terms = unsupervised_loss(rows(b.loss_ref, r), rows(b.loss_src, r), rows(b.K_ref, r),
                                           rows(b.K_src, r), rows(b.T_src_ref, r), rows(depth, r), config_.loss);
      if (i == 0) values.add(terms);
      photometric_total = photometric_total + depth_weight * terms.total;
    }
    if (entropy_term) {
      const auto entropy = normalized_plane_entropy(rows(out.prob_volume, r)).mean();
      values.entropy = entropy.item<double>();
      photometric_total = photometric_total + config_.entropy_weight * entropy;
    }
    if (plane_term) {
      const auto planes = plane_photometric_losses(rows(b.loss_ref, r), rows(b.loss_src, r), rows(b.K_ref, r),
                                                   rows(b.K_src, r), rows(b.T_src_ref, r), rows(b.depth_values, r),
                                                   config_.loss);
      const auto expected = expected_plane_loss(rows(out.prob_volume, r), planes);
      values.plane_loss = expected.item<double>();
      photometric_total = photometric_total + config_.plane_loss_weight * expected;
    }
    total = total + photometric_total * (r.size() / batch_size);
  }
  if (!supervised_rows.empty()) {
    const auto& r = supervised_rows;
    for (size_t i = 0; i < depths.size(); ++i) {
      const auto& [depth, depth_weight] = depths[i];
      const auto supervised = supervised_depth_loss(rows(depth, r), rows(b.depth_gt, r), rows(b.depth_values, r),
                                                    model_->config().depth_sampling);
      if (i == 0) values.supervised = supervised.item<double>();
      total = total + supervised * (depth_weight * config_.supervised_weight * r.size() / batch_size);
    }
  }
  values.total = total.item<double>();
  values.count = 1;
  if (std::isfinite(values.total)) (total * weight).backward();
  return values;
}

Evaluation evaluate_model(MvsNet& model, const std::vector<TrainingTuple>& tuples, const TrainerConfig& config,
                          const torch::Device& device) {
  config.validate();
  torch::NoGradGuard no_grad;
  const bool was_training = model->is_training();
  model->eval();
  Evaluation ev;
  LossValues sum;
  std::vector<torch::Tensor> est, gt;
  for (const auto& t : tuples) {
    const auto b = make_training_batch({t}, config.num_depth, model->config().depth_sampling, device,
                                       config.map_divisor(model->config()));
    const auto out = training_forward(*model, b, config, /*keep_prob_volume=*/false);
    sum.add(unsupervised_loss(b.loss_ref, b.loss_src, b.K_ref, b.K_src, b.T_src_ref, out.depth, config.loss));
    if (b.depth_gt.defined()) {
      est.push_back(out.depth.flatten().cpu());
      gt.push_back(b.depth_gt.flatten().cpu());
    }
    ++ev.tuples;
  }
  ev.loss = sum.mean();
  if (!est.empty()) ev.depth = depth_errors(torch::cat(est), torch::cat(gt));
  model->train(was_training);
  return ev;
}

Evaluation Trainer::evaluate(const std::vector<TrainingTuple>& tuples) {
  return evaluate_model(model_, tuples, config_, device_);
}

std::string Trainer::optimizer_state() const {
  torch::serialize::OutputArchive archive;
  optimizer_->save(archive);
  std::ostringstream os;
  archive.save_to(os);
  return os.str();
}

void Trainer::load_optimizer_state(const std::string& bytes) {
  if (bytes.empty()) return;
  torch::serialize::InputArchive archive;
  std::istringstream is(bytes);
  archive.load_from(is, device_);
  optimizer_->load(archive);
}

void Trainer::set_learning_rate(double lr) {
  for (auto& group : optimizer_->param_groups()) static_cast<torch::optim::AdamOptions&>(group.options()).lr(lr);
}

double Trainer::learning_rate() const {
  return static_cast<const torch::optim::AdamOptions&>(optimizer_->param_groups().at(0).options()).lr();
}

std::string torch_rng_state() {
  at::Generator gen = at::detail::getDefaultCPUGenerator();
  std::lock_guard<std::mutex> lock(gen.mutex());
  auto state = gen.get_state().contiguous();
  return std::string(reinterpret_cast<const char*>(state.data_ptr<uint8_t>()), state.numel());
}

void set_torch_rng_state(const std::string& bytes) {
  if (bytes.empty()) return;
  auto state = torch::empty({static_cast<int64_t>(bytes.size())}, torch::kUInt8);
  std::memcpy(state.data_ptr<uint8_t>(), bytes.data(), bytes.size());
  at::Generator gen = at::detail::getDefaultCPUGenerator();
  std::lock_guard<std::mutex> lock(gen.mutex());
  gen.set_state(state);
}

}  // namespace umvs
