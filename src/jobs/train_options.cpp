// TrainOptions (jobs/train_options.h): the checks of `umvs train`'s options, and the configurations
// they turn into.
#include "unsup_mvs/jobs/train_options.h"

#include <ostream>
#include <stdexcept>
#include <string>

#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/geometry.h"
#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/io/checkpoint.h"

namespace umvs {

namespace {

// The loss, optimiser and planes; throws std::invalid_argument naming a bad --preset, --loss,
// --lr-schedule, --batchnorm or --source-combination.
TrainerConfig trainer_config(const TrainOptions& o, int num_depth) {
  TrainerConfig t;
  if (o.preset == "paper") t.loss = LossConfig::paper();
  else if (o.preset == "authors") t.loss = LossConfig::authors_code();
  else throw std::invalid_argument("--preset must be paper or authors, got '" + o.preset + "'");
  if (o.loss == "naive") t.loss.term = PhotometricTerm::kNaive, t.loss.top_k = 0;
  else if (o.loss == "first-order") t.loss.term = PhotometricTerm::kFirstOrder, t.loss.top_k = 0;
  else if (o.loss == "robust" || o.loss == "supervised") {
    // supervised: the photometric loss still scores validation tuples.
    t.loss.term = PhotometricTerm::kFirstOrder, t.loss.top_k = o.top_k;
  } else {
    throw std::invalid_argument("--loss must be naive, first-order, robust or supervised, got '" + o.loss + "'");
  }
  t.supervised_weight = o.supervised_weight;
  t.entropy_weight = o.entropy_weight;
  t.plane_loss_weight = o.plane_loss_weight;
  t.num_depth = num_depth;
  t.lr = o.lr;
  t.lr_schedule = parse_lr_schedule(o.lr_schedule);
  t.lr_min = o.lr_min;
  t.beta1 = o.beta1;
  t.micro_batch = o.micro_batch;
  const std::string batchnorm = o.batchnorm_mode();
  if (batchnorm != "train" && batchnorm != "frozen") {
    throw std::invalid_argument("--batchnorm must be train or frozen, got '" + batchnorm + "'");
  }
  t.freeze_batchnorm = batchnorm == "frozen";
  t.sources = source_combination_from_string(o.source_combination);
  t.fine.planes = o.fine_planes;
  t.fine.span = o.fine_span;
  t.fine.resolution_divisor = o.fine_resolution;
  t.fine.first_pass_downscale = o.first_pass_downscale;
  t.first_pass_loss_weight = o.first_pass_loss_weight;
  return t;
}

TupleConfig tuple_config(const TrainOptions& o, int num_depth) {
  TupleConfig d;
  d.views_in = o.views_in;
  d.views_loss = o.views_loss;
  d.width = o.width;
  d.height = o.height;
  d.num_depth = num_depth;
  d.jitter = o.jitter;
  d.min_gain = o.min_gain;
  d.max_gain = o.max_gain;
  d.read_ground_truth = !o.self_training();  // label-free, also where the folders have depth_gt/
  d.min_zoom = o.augment ? o.min_zoom : 1.0;
  d.max_zoom = o.augment ? o.max_zoom : 1.0;
  return d;
}

// The planes a run sweeps: --num-depth, else those the run in --out was made with (a --resume),
// else the default for the network width that infer and the inference node also use (the shipped
// model was trained so at each of its sizes: 160 wide with 32, 320 with 64, 640 with 128).
PlaneCount training_plane_count(const TrainOptions& o, const std::optional<RunOptions>& recorded) {
  if (o.num_depth != 0) return {o.num_depth, "--num-depth " + std::to_string(o.num_depth)};
  if (recorded && recorded->contains("num-depth")) {
    const auto& planes = recorded->at("num-depth");
    if (!planes.is_number_integer()) {
      throw std::invalid_argument("the run in --out records num-depth '" + option_text(planes) + "': give --num-depth");
    }
    return {planes.get<int>(), "as the run in --out was made"};
  }
  // A network whose weights fix its planes (sweep2d) sweeps its own.
  const std::string& start = o.was_given("eval-only") ? o.eval_only : o.init;
  if (!start.empty()) {
    const MvsNetConfig network = load_model(start, torch::kCPU).model->config();
    if (network.planes_fixed_by_weights()) return {network.num_depth, "fixed by the network's weights"};
  }
  if (o.network == "sweep2d") {
    return {kSweep2dDefaultPlanes, "default for a new sweep2d network (its weights fix the count; --num-depth to change)"};
  }
  if (o.width == 0) {
    throw std::invalid_argument("--num-depth 0 follows --width; with --width 0 (each image's own size) give "
                                "--num-depth (128 at 640 wide)");
  }
  const int planes = default_plane_count(o.width);
  return {planes, "default for " + std::to_string(o.width) + " wide: 128 at 640, scaled with the width; --num-depth to change"};
}

}  // namespace

std::string TrainOptions::depth_sampling_mode() const {
  if (was_given("depth-sampling")) return depth_sampling;
  return network == "sweep2d" ? "inverse_depth" : "depth";
}

std::string TrainOptions::batchnorm_mode() const {
  if (was_given("batchnorm")) return batchnorm;
  return fine_planes > 0 && !init.empty() ? "frozen" : "train";
}

void TrainOptions::validate() const {
  auto at_least = [](const char* name, int value, int lowest) {
    if (value < lowest) {
      throw std::invalid_argument(std::string("--") + name + " must be >= " + std::to_string(lowest) + ", got " +
                                  std::to_string(value));
    }
  };
  at_least("steps", steps, 0);
  at_least("batch", batch, 1);
  at_least("save-every", save_every, 1);
  at_least("val-tuples", val_tuples, 0);
  at_least("seed", seed, 0);
  if (!(max_minutes >= 0)) {
    throw std::invalid_argument("--max-minutes must be >= 0 (0 = no limit), got " + option_text(max_minutes));
  }
  depth_sampling_from_string(depth_sampling);
  const NetworkKind kind = network_kind_from_string(network);
  if (kind != NetworkKind::kMvsNet && fine_planes > 0) {
    throw std::invalid_argument("--fine-planes: a fine pass runs MVSNet twice; --network " + network +
                                " maps at 1/2 of the input already");
  }
  if (was_given("feature-warp")) feature_warp_from_string(feature_warp);
  if (was_given("against") && !was_given("eval-only")) {
    throw std::invalid_argument("--against is compared with the --eval-only checkpoint: give --eval-only too");
  }
  const bool evaluating = was_given("eval-only");
  if (evaluating) {
    if (resume || overwrite) throw std::invalid_argument("--eval-only trains nothing: no --resume or --overwrite");
    if (was_given("feature-warp")) {
      throw std::invalid_argument("--eval-only scores the checkpoint as saved: no --feature-warp (export a copy with "
                                  "--init CHECKPOINT --feature-warp ... --steps 0)");
    }
  } else {
    if (!(fine_tuned_share > 0 && fine_tuned_share <= 1)) {
      throw std::invalid_argument("--fine-tuned-share must be in (0, 1] (1 = no blend), got " + option_text(fine_tuned_share));
    }
    if (fine_tuned_share < 1 && init.empty()) {
      throw std::invalid_argument("--fine-tuned-share blends best.pt with the model the run starts from: give --init");
    }
    if (out.empty()) throw std::invalid_argument("--out is required for training");
    if (resume && overwrite) {
      throw std::invalid_argument("--resume continues the run in --out, --overwrite replaces it: give one of them");
    }
  }
  // The count that follows --width or the run in --out is always a valid one (and TrainingRun
  // checks it again); a given count is checked here.
  const TrainerConfig trainer = trainer_config(*this, num_depth != 0 ? num_depth : 8);
  trainer.validate();
  if (self_training_every < 0) throw std::invalid_argument("--self-training-every must be >= 0");
  if (self_training()) {
    if (loss == "supervised" || was_given("depth-topic")) {
      throw std::invalid_argument("--self-training-every learns from the model's own consistent depth: it reads no "
                                  "ground truth of the training images (--loss supervised, --depth-topic); rendered "
                                  "scenes with exact depth may join through --supervised-data");
    }
  } else if (was_given("anchor-unconfirmed")) {
    throw std::invalid_argument("--anchor-unconfirmed labels self-training's unconfirmed pixels: give --self-training-every N");
  }
  if (!(anchor_min_confidence >= 0.0 && anchor_min_confidence <= 1.0)) {
    throw std::invalid_argument("--anchor-min-confidence must be in [0, 1], got " + option_text(anchor_min_confidence));
  }
  if (was_given("anchor-min-confidence") && !anchored()) {
    throw std::invalid_argument("--anchor-min-confidence chooses which pixels anchored self-training anchors: give "
                                "--self-training-every N (and not --anchor-unconfirmed 0)");
  }
  if (was_given("anchor-unseen") && !(anchored() && anchor_min_confidence > 0.0)) {
    throw std::invalid_argument("--anchor-unseen adds pixels to the anchored ones of a run with a confidence floor: give "
                                "--self-training-every N and an --anchor-min-confidence above 0 (and not "
                                "--anchor-unconfirmed 0)");
  }
  if (!augment && (was_given("min-zoom") || was_given("max-zoom"))) {
    throw std::invalid_argument("--min-zoom/--max-zoom set the random crop of --augment 1; --augment 0 crops nothing");
  }
  const TupleConfig tuples = tuple_config(*this, trainer.num_depth);
  tuples.validate();
  if (trainer.fine.enabled() && trainer.fine.first_pass_downscale == 2 && (width % 64 != 0 || height % 64 != 0)) {
    throw std::invalid_argument("--first-pass-downscale 2 halves the training images: --width and --height must be "
                                "multiples of 64, got " + std::to_string(width) + "x" + std::to_string(height));
  }
  if (trainer.loss.top_k > tuples.views_loss) {
    throw std::invalid_argument("--top-k " + std::to_string(trainer.loss.top_k) + " exceeds --views-loss " +
                                std::to_string(tuples.views_loss));
  }
  const bool from_bags = was_given("bag");
  if (from_bags == was_given("data")) throw std::invalid_argument("give either --data folders or --bag files");
  if (from_bags && was_given("val")) {
    throw std::invalid_argument("--val folders cannot be mixed with --bag (held-out keyframes validate; see --holdout-every)");
  }
  if (from_bags && loss == "supervised") {
    throw std::invalid_argument("--loss supervised needs --data folders with depth_gt/; bags train photometrically "
                                "(add rendered folders with --supervised-data)");
  }
  if (!evaluating) input_normalization_from_string(input_normalization);  // (of a new model)
}

DistributedConfig TrainOptions::distributed_config() const {
  DistributedConfig d = distributed_config_from_environment();
  if (world_size) d.world_size = *world_size;
  if (rank) d.rank = *rank;
  if (!master.empty()) {
    const auto colon = master.rfind(':');
    if (colon == std::string::npos || colon == 0) throw std::invalid_argument("--master must be HOST:PORT, got '" + master + "'");
    d.master_addr = master.substr(0, colon);
    try {
      d.master_port = std::stoi(master.substr(colon + 1));
    } catch (const std::exception&) {
      throw std::invalid_argument("--master must be HOST:PORT, got '" + master + "'");
    }
  }
  d.timeout_seconds = dist_timeout;
  try {
    d.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("distributed training: ") + e.what());
  }
  if (d.enabled() && !distributed_available()) {
    throw std::invalid_argument("distributed training: this umvs was built without c10d/Gloo (Debian: libgloo-dev)");
  }
  return d;
}

TrainSetup train_setup(const TrainOptions& o) {
  TrainSetup s;
  if (o.resume) s.recorded = recorded_train_options(o.out);
  s.planes = training_plane_count(o, s.recorded);
  s.trainer = trainer_config(o, s.planes.planes);
  s.trainer.validate();
  s.data = tuple_config(o, s.planes.planes);
  s.data.validate();
  return s;
}

TrainingRunConfig training_run_config(const TrainOptions& options, const TrainSetup& setup,
                                      const DistributedConfig& distributed, const torch::Device& device,
                                      std::ostream& messages) {
  TrainOptions o = options;  // as the run uses them
  o.num_depth = setup.planes.planes;
  o.depth_sampling = o.depth_sampling_mode();
  // The network is the --init checkpoint's: record that one.
  if (!o.init.empty()) o.network = to_string(load_model(o.init, torch::kCPU).model->config().network);
  // An anchored run of a version before the 0.5 default recorded no floor (upgraded: 0), as one
  // made with 0: resumed without the option, it continues with that floor instead of being refused.
  const auto& recorded = setup.recorded;
  auto recorded_is = [&](const char* name, const nlohmann::json& value) {
    if (!recorded) return false;
    const auto it = recorded->find(name);
    return it != recorded->end() && *it == value;
  };
  if (o.anchored() && o.resume && !o.was_given("anchor-min-confidence") && recorded_is("anchor-unconfirmed", true) &&
      recorded_is("anchor-min-confidence", 0.0)) {
    o.anchor_min_confidence = 0.0;
    messages << "--resume: the run in " << o.out
             << " anchors every unconfirmed pixel (no floor recorded: made with --anchor-min-confidence 0 or "
                "before it defaulted to 0.5): it continues so\n";
  }
  TrainingRunConfig run;
  run.out = o.out;
  run.start = o.resume ? RunStart::kResume : o.overwrite ? RunStart::kOverwrite : RunStart::kFresh;
  run.options = train_run_options(o, distributed);
  run.may_change_on_resume = train_options_may_change_on_resume();
  run.upgrade_record = upgrade_train_record;
  run.init = o.init;
  run.fine_tuned_share = o.fine_tuned_share;
  run.new_model.network = network_kind_from_string(o.network);
  run.new_model.depth_sampling = depth_sampling_from_string(o.depth_sampling_mode());
  run.new_model.input_normalization = input_normalization_from_string(o.input_normalization);
  if (o.was_given("feature-warp")) run.feature_warp = feature_warp_from_string(o.feature_warp);
  run.seed = static_cast<uint64_t>(o.seed);
  run.trainer = setup.trainer;
  run.data = setup.data;
  run.steps = o.steps;
  run.batch = o.batch;
  run.save_every = o.save_every;
  run.max_minutes = o.max_minutes;
  run.augment = o.augment;
  run.val_tuples = o.val_tuples;
  run.supervised_share = o.supervised_share;
  run.self_training_every = o.self_training_every;
  run.pseudo_label_tuples = o.pseudo_label_tuples;
  // Fusion's rule, loosened for the training size's few planes (32 planes over 0.5-8 m are ~9 %
  // apart in depth, so 1 % agreement would keep almost nothing).
  run.label_rule.min_confidence = o.label_min_confidence;
  run.label_rule.max_relative_depth = o.label_max_relative_depth;
  run.label_rule.min_agreeing_views = o.label_min_views;
  run.anchor_unconfirmed = o.anchored();
  run.anchor_min_confidence = run.anchor_unconfirmed ? o.anchor_min_confidence : 0.0;
  run.anchor_unseen = run.anchor_min_confidence > 0.0 && o.anchor_unseen;
  run.device = device;
  run.distributed = distributed;
  return run;
}

}  // namespace umvs
