#include "unsup_mvs/jobs/training_run.h"

#include <algorithm>
#include <exception>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <ostream>
#include <sstream>

#include "unsup_mvs/core/memory_bounds.h"
#include "unsup_mvs/core/weight_blend.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/loss_curve.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

TrainLogRow log_row(int64_t step, const LossValues& loss, double lr, double seconds) {
  TrainLogRow row;
  row.step = step;
  row.total = loss.total;
  row.photometric = loss.photometric;
  row.ssim = loss.ssim;
  row.smoothness = loss.smoothness;
  row.valid_fraction = loss.valid_fraction;
  row.lr = lr;
  row.seconds = seconds;
  row.supervised = loss.supervised;
  if (loss.entropy > 0) row.entropy = loss.entropy;  // measured only with an entropy weight
  if (loss.plane_loss > 0) row.plane_loss = loss.plane_loss;  // and with a plane loss weight
  return row;
}

void add_validation(const Evaluation& ev, TrainLogRow* row) {
  row->val_photometric = ev.loss.photometric;
  row->val_total = ev.loss.total;
  if (ev.depth.pixels > 0) {
    row->val_abs_err = ev.depth.mean_abs;
    row->val_within_1pct = ev.depth.within_1pct;
  }
}

// The metric best.pt is chosen by (lower is better): the held-out ground-truth depth error, the
// held-out photometric loss, or (without validation data) the training loss.
std::string score_metric(const CheckpointMeta& meta) {
  if (meta.metrics.count("val_abs_err")) return "val_abs_err";
  if (meta.metrics.count("val_total")) return "val_total";
  return "train_total";
}
std::string score_metric(bool validated, bool ground_truth) {
  if (!validated) return "train_total";
  return ground_truth ? "val_abs_err" : "val_total";
}

// A validation row's score (it has val_total).
double validation_score(const TrainLogRow& row) { return row.val_abs_err ? *row.val_abs_err : *row.val_total; }

std::string describe(const Evaluation& ev) {
  std::ostringstream s;
  s.precision(4);
  s << "photometric " << ev.loss.photometric << ", ssim " << ev.loss.ssim << ", total " << ev.loss.total;
  if (ev.depth.pixels > 0) {
    s << ", depth |err| mean " << ev.depth.mean_abs << ", abs rel " << ev.depth.abs_rel << ", within 1% "
      << 100.0 * ev.depth.within_1pct << "%";
  }
  s << " (" << ev.tuples << " tuples)";
  return s.str();
}

// The rng_state of a checkpoint: the sampler's text state, a NUL, then LibTorch's generator bytes.
std::string pack_rng(const MixedSampler& sampler) { return sampler.state() + '\0' + torch_rng_state(); }
void unpack_rng(const std::string& bytes, MixedSampler& sampler) {
  const auto nul = bytes.find('\0');
  if (nul == std::string::npos) throw std::runtime_error("checkpoint has no training RNG state: cannot resume exactly");
  sampler.set_state(bytes.substr(0, nul));
  set_torch_rng_state(bytes.substr(nul + 1));
}

void check_memory(const TrainingRunConfig& c, int width, int height) {
  check_training_memory(width, height, c.trainer.num_depth, c.data.views_in, c.data.views_loss, c.batch);
}

}  // namespace

void TrainingRunConfig::validate() const {
  auto at_least = [](const char* name, int64_t value, int64_t lowest) {
    if (value < lowest) {
      throw std::invalid_argument(std::string(name) + " must be >= " + std::to_string(lowest) + ", got " +
                                  std::to_string(value));
    }
  };
  if (out.empty()) throw std::invalid_argument("the run folder (out) is required");
  at_least("steps", steps, 0);
  at_least("batch", batch, 1);
  at_least("save_every", save_every, 1);
  at_least("val_tuples", val_tuples, 0);
  at_least("self_training_every", self_training_every, 0);
  at_least("pseudo_label_tuples", pseudo_label_tuples, 0);
  if (!(max_minutes >= 0)) throw std::invalid_argument("max_minutes must be >= 0 (0 = no limit)");
  if (!(supervised_share >= 0 && supervised_share <= 1)) throw std::invalid_argument("supervised_share must be in [0, 1]");
  trainer.validate();
  data.validate();
  if (trainer.loss.top_k > data.views_loss) {
    throw std::invalid_argument("top_k " + std::to_string(trainer.loss.top_k) + " exceeds views_loss " +
                                std::to_string(data.views_loss));
  }
  if (self_training_every > 0) label_rule.validate();
  if (!(fine_tuned_share > 0 && fine_tuned_share <= 1)) {
    throw std::invalid_argument("fine_tuned_share must be in (0, 1] (1 = no blend), got " + std::to_string(fine_tuned_share));
  }
  if (fine_tuned_share < 1 && init.empty()) {
    throw std::invalid_argument("fine_tuned_share < 1 blends with the starting checkpoint: give init");
  }
  distributed.validate();
}

TrainingRun::TrainingRun(TrainingRunConfig config, const std::function<TrainingData()>& open_data,
                         std::ostream& messages)
    : config_(std::move(config)), messages_(messages) {
  config_.validate();
  if (config_.data.width > 0 && config_.data.height > 0) check_memory(config_, config_.data.width, config_.data.height);
  const bool resume = config_.start == RunStart::kResume;
  if (config_.distributed.enabled()) {
    const auto& d = config_.distributed;
    messages_ << "rank " << d.rank << " of " << d.world_size << ": joining the job at " << d.master_addr << ":"
              << d.master_port << "\n";
    group_ = std::make_unique<ProcessGroup>(d);
  }
  // Rank 0 checks the run folder and tells the others whether the run may start, whatever the
  // failure (a refusal or an unreadable file), so that they do not wait for it until --dist-timeout.
  std::string refusal;
  std::exception_ptr folder_error;
  if (writes_files()) {
    try {
      std::string warnings;
      check_run_folder(config_.out, config_.start, config_.options, config_.may_change_on_resume,
                       config_.upgrade_record, &warnings);
      messages_ << warnings;
    } catch (const std::exception& e) {
      if (!group_) throw;
      refusal = e.what();
      folder_error = std::current_exception();
    }
  }
  if (group_) refusal = group_->share_from_rank0(refusal);
  if (folder_error) std::rethrow_exception(folder_error);
  if (!refusal.empty()) throw std::invalid_argument("rank 0 refused the run: " + refusal);
  data_ = open_data();
  if (!data_.train) throw std::invalid_argument("a training run needs training data");

  const TupleSource& source = *data_.train;
  if (config_.self_training_every > 0) prepare_self_training();
  if (data_.held_out) {
    val_tuples_ = fixed_tuples(*data_.held_out, config_.val_tuples);
    messages_ << "validation: " << data_.held_out->description() << ", using " << val_tuples_.size() << "\n";
  }
  if (config_.data.width == 0 || config_.data.height == 0) {  // the size comes from the images
    const auto first = source.tuple(0, nullptr).network_views.at(0).image;
    check_memory(config_, static_cast<int>(first.size(-1)), static_cast<int>(first.size(-2)));
  }

  // The model: resumed, initialised from a checkpoint, or new.
  MvsNet model{nullptr};
  CheckpointMeta meta;
  best_ = INFINITY;
  if (resume) {
    auto loaded = load_model(last_path(), config_.device);
    model = loaded.model;
    meta = loaded.meta;
    if (meta.metrics.count("best_score")) best_ = meta.metrics.at("best_score");
    // best.pt candidates are only compared under one metric (a depth error is no loss value).
    best_metric_ = score_metric(meta);
    bool ground_truth = false;
    for (const auto& t : val_tuples_) ground_truth = ground_truth || t.depth_gt.defined();
    const std::string planned = score_metric(!val_tuples_.empty(), ground_truth);
    if (planned != best_metric_) {
      throw std::invalid_argument("--resume: best.pt of this run was chosen by " + best_metric_ +
                                  ", this call would score by " + planned + "; give the validation data of the run");
    }
    messages_ << "resuming " << last_path() << " at step " << meta.step << "\n";
  } else if (!config_.init.empty()) {
    auto loaded = load_model(config_.init, config_.device);
    model = loaded.model;
    messages_ << "initialised from " << config_.init << " (" << loaded.format << ")\n";
    if (config_.feature_warp) model->set_feature_warp(*config_.feature_warp);
  } else {
    torch::manual_seed(config_.seed);
    MvsNetConfig mcfg = config_.new_model;
    mcfg.num_depth = config_.trainer.num_depth;
    mcfg.num_views = config_.data.views_in;
    mcfg.feature_warp = config_.feature_warp.value_or(mcfg.feature_warp);
    model = MvsNet(mcfg);
  }
  model->set_num_depth(config_.trainer.num_depth);
  trainer_ = std::make_unique<Trainer>(model, config_.device, config_.trainer);
  if (group_) {
    // Every rank starts from rank 0's weights and averages the gradients of each step.
    std::vector<torch::Tensor> state = trainer_->model()->parameters();
    for (const auto& b : trainer_->model()->buffers()) state.push_back(b);
    group_->broadcast_from_rank0(state);
    int64_t values = 0;
    for (const auto& p : trainer_->model()->parameters()) values += p.numel();
    messages_ << "rank " << group_->rank() << ": each step all-reduces " << values << " gradient values ("
              << values * 4 / 1e6 << " MB)\n";
    trainer_->set_gradient_sync([this](const std::vector<torch::Tensor>& parameters, bool finite) {
      const bool all_finite = group_->sum({finite ? 0.0 : 1.0})[0] == 0.0;
      std::vector<torch::Tensor> gradients;
      for (const auto& p : parameters) gradients.push_back(p.grad());
      group_->average(gradients);
      return all_finite;
    });
  }
  const TupleSource* supervised = data_.supervised ? data_.supervised.get() : pseudo_.get();
  sampler_ = std::make_unique<MixedSampler>(supervised ? *supervised : source, supervised ? &source : nullptr,
                                            config_.supervised_share, config_.seed);
  if (resume) {
    trainer_->load_optimizer_state(meta.optimizer_state);
    unpack_rng(meta.rng_state, *sampler_);
    step_ = meta.step;
    // The log up to the resumed checkpoint (rows written after it are dropped).
    for (const auto& csv : writes_files() ? read_csv_rows(log_path()) : std::vector<CsvRow>{}) {
      TrainLogRow row = train_log_row(csv);
      if (row.step > step_) break;
      history_.push_back(row);
    }
  }
}

TrainingRun::~TrainingRun() = default;

void TrainingRun::checkpoint(TrainLogRow& row, std::ostream* log) {
  double score = interval_count_ > 0 ? interval_loss_ / interval_count_ : INFINITY;
  bool ground_truth = false;
  if (group_) {  // one model on every rank: the BatchNorm running averages of all ranks
    std::vector<torch::Tensor> buffers;
    for (const auto& b : trainer_->model()->buffers()) {
      if (b.is_floating_point()) buffers.push_back(b);
    }
    group_->average(buffers);
  }
  if (!val_tuples_.empty()) {
    const Evaluation ev = validate();
    add_validation(ev, &row);
    ground_truth = ev.depth.pixels > 0;
    score = validation_score(row);
    messages_ << "\nstep " << row.step << " validation: " << describe(ev) << "\n";
  }
  interval_loss_ = 0;
  interval_count_ = 0;
  const std::string metric = score_metric(!val_tuples_.empty(), ground_truth);
  if (best_metric_.empty()) best_metric_ = metric;
  const bool comparable = metric == best_metric_;
  if (!comparable) {
    messages_ << "\nstep " << row.step << ": scored by " << metric << ", best.pt by " << best_metric_
              << ": best.pt kept\n";
  }
  const bool improved = comparable && (std::isfinite(score) ? score < best_ : !fs::exists(best_path()));
  if (improved && std::isfinite(score)) best_ = score;
  CheckpointMeta m;
  m.step = row.step;
  m.optimizer_state = trainer_->optimizer_state();
  m.rng_state = pack_rng(*sampler_);
  m.metrics["score"] = score;
  m.metrics["best_score"] = best_;
  if (row.total) m.metrics["train_total"] = *row.total;
  if (row.val_photometric) m.metrics["val_photometric"] = *row.val_photometric;
  if (row.val_total) m.metrics["val_total"] = *row.val_total;
  if (row.val_abs_err) m.metrics["val_abs_err"] = *row.val_abs_err;
  if (!writes_files()) return;
  // The row first: killed at any moment, the log holds at least every step up to last.pt's (a
  // resume drops the rows after it), never fewer.
  if (log) *log << format_csv_row(row) << "\n" << std::flush;
  save_checkpoint(last_path(), trainer_->model(), m);
  if (improved) save_checkpoint(best_path(), trainer_->model(), m);
}

Evaluation TrainingRun::validate() {
  if (!group_) return trainer_->evaluate(val_tuples_);
  std::vector<TrainingTuple> share;
  for (size_t i = static_cast<size_t>(group_->rank()); i < val_tuples_.size(); i += group_->size()) {
    share.push_back(val_tuples_[i]);
  }
  Evaluation mine;
  if (!share.empty()) mine = trainer_->evaluate(share);
  // Means weighted by tuples (losses) and by pixels (depth errors), summed over the ranks.
  const double n = mine.tuples, px = static_cast<double>(mine.depth.pixels);
  const auto s = group_->sum({n, n * mine.loss.total, n * mine.loss.photometric, n * mine.loss.ssim,
                              n * mine.loss.smoothness, n * mine.loss.valid_fraction, px, px * mine.depth.mean_abs,
                              px * mine.depth.abs_rel, px * mine.depth.within_1pct});
  Evaluation all;
  all.tuples = static_cast<int>(s[0]);
  if (s[0] > 0) {
    all.loss.total = s[1] / s[0];
    all.loss.photometric = s[2] / s[0];
    all.loss.ssim = s[3] / s[0];
    all.loss.smoothness = s[4] / s[0];
    all.loss.valid_fraction = s[5] / s[0];
    all.loss.count = 1;
  }
  all.depth.pixels = static_cast<int64_t>(s[6]);
  if (s[6] > 0) {
    all.depth.mean_abs = s[7] / s[6];
    all.depth.abs_rel = s[8] / s[6];
    all.depth.within_1pct = s[9] / s[6];
  }
  return all;
}

std::vector<TrainingTuple> TrainingRun::next_tuples() {
  std::vector<TrainingTuple> tuples;
  const int ranks = group_ ? group_->size() : 1, rank = group_ ? group_->rank() : 0;
  // The step's world_size * batch tuples in one process's order; this rank's are the rank-th batch.
  for (int i = 0; i < ranks * config_.batch; ++i) {
    if (i / config_.batch == rank) tuples.push_back(sampler_->next(config_.augment));
    else sampler_->skip();
  }
  return tuples;
}

void TrainingRun::write_curve() const {
  CurveSeries raw{{}, {}, 190, 190, 235}, smooth{{}, {}, 20, 60, 200}, val{{}, {}, 220, 40, 30};
  double ema = 0;
  bool first = true;
  for (const auto& row : history_) {
    if (row.total) {
      raw.x.push_back(row.step);
      raw.y.push_back(*row.total);
      ema = first ? *row.total : 0.95 * ema + 0.05 * *row.total;
      first = false;
      smooth.x.push_back(row.step);
      smooth.y.push_back(ema);
    }
    if (row.val_total) {
      val.x.push_back(row.step);
      val.y.push_back(validation_score(row));
    }
  }
  write_png(config_.out + "/loss_curve.png", render_curves({raw, smooth, val}));
}

TrainingRun::Result TrainingRun::run(
    const std::function<void(const TrainLogRow& row, int64_t done, int64_t to_do)>& on_step) {
  const std::string out = config_.out;
  std::ofstream log;
  if (writes_files()) {
    // Everything is checked: from here on OUT changes.
    make_directories(out);
    if (config_.start == RunStart::kOverwrite) remove_run_files(out);
    remove_stale_temp_files(out);  // what a killed run was writing (its last complete files stay)
    write_run_record(out, config_.options);
    // The log holds exactly the rows up to the starting step.
    write_file_atomically(log_path(), [&](std::ostream& os) {
      os << csv_header(train_log_columns()) << "\n";
      for (const auto& row : history_) os << format_csv_row(row) << "\n";
    });
    log.open(log_path(), std::ios::app);
  }

  Result result;
  if (config_.steps == 0 || step_ >= config_.steps) {
    TrainLogRow row;
    row.step = step_;
    checkpoint(row);
    result.step = step_;
    result.best_score = best_;
    result.best_metric = best_metric_;
    return result;
  }

  const int64_t first = step_, to_do = config_.steps - step_;
  const double max_seconds = 60.0 * config_.max_minutes;
  const auto started = std::chrono::steady_clock::now();
  if (config_.self_training_every > 0) start_self_training();
  while (step_ < config_.steps) {
    if (config_.self_training_every > 0 && step_ % config_.self_training_every == 0) start_round();
    const auto t0 = std::chrono::steady_clock::now();
    const double lr = learning_rate_at(config_.trainer, step_, config_.steps);
    trainer_->set_learning_rate(lr);
    const std::vector<TrainingTuple> tuples = next_tuples();
    LossValues loss = trainer_->step(tuples).mean();
    ++step_;
    bool out_of_time =
        max_seconds > 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() >= max_seconds;
    if (group_) {  // the job's mean loss, and one decision to stop (rank clocks differ)
      const auto s = group_->sum({loss.total, loss.photometric, loss.ssim, loss.smoothness, loss.valid_fraction,
                                  loss.supervised, out_of_time ? 1.0 : 0.0, loss.entropy, loss.plane_loss});
      const double ranks = group_->size();
      loss.total = loss.updated ? s[0] / ranks : NAN;
      loss.photometric = s[1] / ranks;
      loss.ssim = s[2] / ranks;
      loss.smoothness = s[3] / ranks;
      loss.valid_fraction = s[4] / ranks;
      loss.supervised = s[5] / ranks;
      out_of_time = s[6] > 0;
      loss.entropy = s[7] / ranks;
      loss.plane_loss = s[8] / ranks;
    }
    result.out_of_time = out_of_time;
    TrainLogRow row = log_row(step_, loss, lr,
                              std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    if (!loss.updated || !std::isfinite(loss.total)) {
      ++result.skipped_steps;
      messages_ << "\nstep " << step_ << ": non-finite loss"
                << (tuples.empty() ? std::string() : " (this rank's first tuple: " + tuples[0].name + ")")
                << ", update skipped\n";
    } else {
      interval_loss_ += loss.total;
      ++interval_count_;
    }
    if (step_ % config_.save_every == 0 || step_ == config_.steps || result.out_of_time) {
      checkpoint(row, &log);
    } else if (writes_files()) {
      log << format_csv_row(row) << "\n" << std::flush;
    }
    history_.push_back(row);
    if (writes_files() && (row.val_total || step_ == config_.steps || result.out_of_time)) write_curve();
    if (on_step) on_step(row, step_ - first, to_do);
    if (result.out_of_time) break;
  }
  if (writes_files() && config_.fine_tuned_share < 1) write_blended();
  result.step = step_;
  result.best_score = best_;
  result.best_metric = best_metric_;
  return result;
}

void TrainingRun::write_blended() {
  LoadedModel best = load_model(best_path(), torch::kCPU);
  LoadedModel start = load_model(config_.init, torch::kCPU);
  blend_weights(best.model, start.model, config_.fine_tuned_share);
  CheckpointMeta meta;  // best.pt's step; not its optimiser state or scores, which are not the blend's
  meta.step = best.meta.step;
  save_checkpoint(blended_path(), best.model, meta);
  messages_ << "blended.pt: " << config_.fine_tuned_share << " x best.pt + " << 1 - config_.fine_tuned_share << " x "
            << config_.init << "\n";
}

std::vector<TrainingTuple> fixed_tuples(const TupleSource& source, int limit) {
  std::vector<TrainingTuple> out;
  const size_t n = source.size();
  const size_t count = limit > 0 ? std::min<size_t>(n, static_cast<size_t>(limit)) : n;
  for (size_t i = 0; i < count; ++i) out.push_back(source.tuple(i * n / count, nullptr));
  return out;
}

EvalRow evaluate_checkpoint(const std::string& checkpoint, const TupleSource& source, int max_tuples,
                            const TrainerConfig& config, const torch::Device& device) {
  auto loaded = load_model(checkpoint, device);
  const auto tuples = fixed_tuples(source, max_tuples);
  const Evaluation ev = evaluate_model(loaded.model, tuples, config, device);
  // Label-free judge besides the photometric loss: the share of depth that other views confirm.
  const ConsistencyScore consistency = depth_consistency(loaded.model, tuples, config.num_depth, adaptation_judge_rule(), device,
                                                                config.sources);
  EvalRow row;
  row.checkpoint = checkpoint;
  row.tuples = ev.tuples;
  row.photometric = ev.loss.photometric;
  row.ssim = ev.loss.ssim;
  row.smoothness = ev.loss.smoothness;
  row.total = ev.loss.total;
  if (ev.depth.pixels > 0) {
    row.abs_err = ev.depth.mean_abs;
    row.abs_rel = ev.depth.abs_rel;
    row.within_1pct = ev.depth.within_1pct;
  }
  row.consistent = consistency.confirmed_fraction;
  return row;
}

std::string describe(const EvalRow& row) {
  std::ostringstream s;
  s.precision(4);
  s << "photometric " << row.photometric.value_or(NAN) << ", ssim " << row.ssim.value_or(NAN) << ", total "
    << row.total.value_or(NAN);
  if (row.abs_err) {
    s << ", depth |err| mean " << *row.abs_err << ", abs rel " << row.abs_rel.value_or(NAN) << ", within 1% "
      << 100.0 * row.within_1pct.value_or(NAN) << "%";
  }
  s << " (" << row.tuples.value_or(0) << " tuples), multi-view consistent " << 100.0 * row.consistent.value_or(0) << "%";
  return s.str();
}

}  // namespace umvs
