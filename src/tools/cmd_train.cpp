// umvs train: unsupervised training / fine-tuning of MVSNet with the robust photometric loss.
#include <torch/torch.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/core/memory_bounds.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/loss_curve.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/io/training_data.h"
#ifdef UMVS_HAVE_ROS
#include "unsup_mvs/io/ros/bag_training_data.h"
#endif
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"
#include "unsup_mvs/tools/progress.h"

namespace fs = std::filesystem;

namespace {

struct LogRow {
  int64_t step = 0;
  umvs::LossValues loss;
  double lr = 0, seconds = 0;
  bool has_val = false;
  umvs::Evaluation val;
};

// One row of train_log.csv, in the order of umvs::train_log_columns().
std::string csv_line(const LogRow& r) {
  std::ostringstream s;
  s.precision(7);
  s << r.step << "," << r.loss.total << "," << r.loss.photometric << "," << r.loss.ssim << "," << r.loss.smoothness
    << "," << r.loss.valid_fraction << "," << r.lr << "," << r.seconds << ",";
  if (r.has_val) {
    s << r.val.loss.photometric << "," << r.val.loss.total << ",";
    if (r.val.depth.pixels > 0) s << r.val.depth.mean_abs << "," << r.val.depth.within_1pct;
    else s << ",";
  } else {
    s << ",,,";
  }
  s << "," << r.loss.supervised;
  return s.str();
}

// Lower is better: GT depth error when the validation data has ground truth, else its photometric loss.
double val_score(const umvs::Evaluation& ev) {
  return ev.depth.pixels > 0 ? ev.depth.mean_abs : ev.loss.total;
}

std::string describe(const umvs::Evaluation& ev) {
  std::ostringstream s;
  s.precision(4);
  s << "photometric " << ev.loss.photometric << ", ssim " << ev.loss.ssim << ", total " << ev.loss.total;
  if (ev.depth.pixels > 0) {
    s << ", depth |err| mean " << ev.depth.mean_abs << ", abs rel "
      << ev.depth.abs_rel << ", within 1% "
      << 100.0 * ev.depth.within_1pct << "%";
  }
  s << " (" << ev.tuples << " tuples)";
  return s.str();
}

// The rng_state of a checkpoint: the sampler's text state, a NUL, then LibTorch's generator bytes.
std::string pack_rng(const umvs::MixedSampler& sampler) { return sampler.state() + '\0' + umvs::torch_rng_state(); }
void unpack_rng(const std::string& bytes, umvs::MixedSampler& sampler) {
  const auto nul = bytes.find('\0');
  if (nul == std::string::npos) throw std::runtime_error("checkpoint has no training RNG state: cannot resume exactly");
  sampler.set_state(bytes.substr(0, nul));
  umvs::set_torch_rng_state(bytes.substr(nul + 1));
}

std::vector<LogRow> read_log(const std::string& path, int64_t max_step, std::vector<std::string>* lines) {
  std::vector<LogRow> rows;
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) f.push_back(c);
    if (f.size() < 8) continue;
    LogRow r;
    r.step = std::stoll(f[0]);
    if (r.step > max_step) break;  // written after the checkpoint we resume from
    r.loss.total = std::stod(f[1]);
    if (f.size() > 9 && !f[9].empty()) {
      r.has_val = true;
      r.val.loss.total = std::stod(f[9]);
      if (f.size() > 10 && !f[10].empty()) {
        r.val.depth.mean_abs = std::stod(f[10]);
        r.val.depth.pixels = 1;
      }
    }
    rows.push_back(r);
    lines->push_back(line);
  }
  return rows;
}

void write_curve(const std::string& path, const std::vector<LogRow>& rows) {
  umvs::CurveSeries raw{{}, {}, 190, 190, 235}, smooth{{}, {}, 20, 60, 200}, val{{}, {}, 220, 40, 30};
  double ema = 0;
  for (size_t i = 0; i < rows.size(); ++i) {
    const double v = rows[i].loss.total;
    raw.x.push_back(rows[i].step);
    raw.y.push_back(v);
    ema = i == 0 ? v : 0.95 * ema + 0.05 * v;
    smooth.x.push_back(rows[i].step);
    smooth.y.push_back(ema);
    if (rows[i].has_val) {
      val.x.push_back(rows[i].step);
      val.y.push_back(val_score(rows[i].val));
    }
  }
  umvs::write_png(path, umvs::render_curves({raw, smooth, val}));
}

std::vector<umvs::TrainingTuple> fixed_tuples(const umvs::TupleSource& source, int limit) {
  std::vector<umvs::TrainingTuple> out;
  const size_t n = source.size();
  const size_t count = limit > 0 ? std::min<size_t>(n, static_cast<size_t>(limit)) : n;
  for (size_t i = 0; i < count; ++i) out.push_back(source.tuple(i * n / count, nullptr));
  return out;
}

// The data: a training source and, when there is one, the held-out source validated on, and
// rendered folders trained on their ground truth in the same run.
struct Data {
  std::unique_ptr<umvs::TupleSource> train, held_out, supervised;
};

Data open_folders(const umvs::Args& args, const umvs::TupleConfig& config) {
  Data d;
  umvs::TupleConfig train_config = config;
  train_config.supervised = args.str("loss") == "supervised";
  d.train = std::make_unique<umvs::MvsFolderSource>(args.all("data"), train_config);
  if (args.given("val")) d.held_out = std::make_unique<umvs::MvsFolderSource>(args.all("val"), config);
  return d;
}

Data open_bags(const umvs::Args& args, const umvs::TupleConfig& config, bool eval_only) {
#ifdef UMVS_HAVE_ROS
  umvs::BagDataConfig bag;
  bag.topics.image = args.str("image-topic");
  bag.topics.camera_info = args.str("camera-info-topic");
  bag.topics.world_frame = args.str("world-frame");
  bag.topics.depth = args.str("depth-topic");
  bag.rectified = args.integer("rectified") != 0;
  bag.keyframes.min_translation = args.real("min-translation");
  bag.keyframes.min_rotation_deg = args.real("min-rotation-deg");
  bag.keyframes.min_pose_distance = args.real("min-pose-distance");
  bag.keyframes.buffer_size = args.integer("keyframe-buffer");
  bag.keyframes.min_score = args.real("min-view-score");
  bag.keyframes.score_grid = args.integer("view-score-grid");
  bag.depth_min = args.real("depth-min");
  bag.depth_max = args.real("depth-max");
  bag.holdout_every = args.integer("holdout-every");
  auto keyframes = std::make_shared<const std::vector<umvs::BagKeyframe>>(
      umvs::read_bag_keyframes(args.all("bag"), bag, &std::cerr));
  Data d;
  if (bag.holdout_every > 0) {
    d.held_out = std::make_unique<umvs::BagSource>(keyframes, umvs::BagSplit::kHeldOut, bag, config);
  }
  if (!eval_only) {
    d.train = std::make_unique<umvs::BagSource>(
        keyframes, bag.holdout_every > 0 ? umvs::BagSplit::kTraining : umvs::BagSplit::kAll, bag, config);
  } else if (!d.held_out) {
    d.held_out = std::make_unique<umvs::BagSource>(keyframes, umvs::BagSplit::kAll, bag, config);
  }
  return d;
#else
  (void)config;
  (void)eval_only;
  throw std::invalid_argument("--bag: this umvs was built without ROS (UMVS_WITH_ROS=OFF) and cannot read bags; "
                              "convert the log to an MVSNet folder elsewhere or rebuild with ROS");
#endif
}

// Options that a --resume may change: they do not change what the run computes. All others
// (data, sizes, loss, optimiser, seed, validation, ...) are the run's configuration.
const std::vector<std::string> kMayChangeOnResume = {"steps", "max-minutes", "out", "resume", "overwrite", "eval-only", "device",
                                                     "threads"};

// Every option as given or defaulted; file and folder paths made absolute, so that a resume from
// another working directory compares equal.
umvs::RunConfig run_config_of(const umvs::Args& args) {
  umvs::RunConfig config;
  for (const auto& name : args.names()) {
    const bool is_path = name == "data" || name == "val" || name == "bag" || name == "init" || name == "supervised-data";
    std::string joined;
    for (const auto& part : args.all(name)) {
      joined += (joined.empty() ? "" : ",") + (is_path ? fs::absolute(part).lexically_normal().string() : part);
    }
    config[name] = joined;
  }
  return config;
}

// The metric best.pt is chosen by, as a checkpoint's metrics show it: the held-out ground-truth
// depth error, the held-out photometric loss, or (without validation data) the training loss.
std::string score_metric(const umvs::CheckpointMeta& meta) {
  if (meta.metrics.count("val_abs_err")) return "val_abs_err";
  if (meta.metrics.count("val_total")) return "val_total";
  return "train_total";
}
std::string score_metric(const LogRow& row) {
  if (!row.has_val) return "train_total";
  return row.val.depth.pixels > 0 ? "val_abs_err" : "val_total";
}

// The integer options and option combinations, before anything is read or written.
void check_training_options(const umvs::Args& args) {
  auto at_least = [&](const char* name, int lowest) {
    if (args.integer(name) < lowest) {
      throw std::invalid_argument(std::string("--") + name + " must be >= " + std::to_string(lowest) + ", got " +
                                  std::to_string(args.integer(name)));
    }
  };
  at_least("steps", 0);
  at_least("batch", 1);
  at_least("save-every", 1);
  at_least("val-tuples", 0);
  at_least("seed", 0);
  if (!(args.real("max-minutes") >= 0)) {
    throw std::invalid_argument("--max-minutes must be >= 0 (0 = no limit), got " + args.str("max-minutes"));
  }
  if (args.integer("augment") != 0 && args.integer("augment") != 1) throw std::invalid_argument("--augment must be 0 or 1");
  umvs::depth_sampling_from_string(args.str("depth-sampling"));
  if (args.given("eval-only")) {
    if (args.on("resume") || args.on("overwrite")) throw std::invalid_argument("--eval-only trains nothing: no --resume or --overwrite");
    return;
  }
  if (args.str("out").empty()) throw std::invalid_argument("--out is required for training");
  if (args.on("resume") && args.on("overwrite")) {
    throw std::invalid_argument("--resume continues the run in --out, --overwrite replaces it: give one of them");
  }
}

}  // namespace

UMVS_COMMAND(train, "unsupervised training / fine-tuning with the robust photometric loss") {
  const umvs::KeyframeStreamConfig bag_defaults;
  umvs::Args args(
      "train",
      "Trains MVSNet without ground truth: each step runs the network on a reference and its best\n"
      "neighbours (pair.txt) and minimises the photometric loss of warping the best --views-loss\n"
      "neighbours into the reference with the predicted depth. Writes into OUT:\n"
      "  last.pt, best.pt     checkpoints (model, Adam state, step, RNG), written atomically\n"
      "  train_log.csv        step, loss terms, lr, seconds, validation metrics\n"
      "  loss_curve.png       training loss (raw, smoothed) and validation score (red), log scale\n"
      "  run_config.txt       the options of the run; --resume refuses to change them (except --steps,\n"
      "                       --device, --threads)\n"
      "OUT must be new or empty, unless --resume continues the run in it or --overwrite replaces it.\n"
      "best.pt is only replaced by a model with a lower validation score: GT depth error when the\n"
      "--val folders have depth_gt/, else their photometric loss (without --val: the training loss\n"
      "since the previous checkpoint). With --eval-only CHECKPOINT nothing is trained: the held-out\n"
      "loss (and GT depth error) of that checkpoint on --data is printed (and written to OUT/eval.csv).\n"
      "With --bag instead of --data, the keyframes of robot logs are the data (the keyframe_selector's\n"
      "policy); every --holdout-every-th keyframe is held out for validation, and --eval-only scores\n"
      "exactly those held-out keyframes.");
  args.option("data", "", "MVSNet-format folder(s), comma-separated (or --bag)")
      .repeated("bag", "rosbag file(s) with posed images, instead of --data (repeat or comma-separate)")
      .option("image-topic", "/camera/image_rect_color", "--bag: sensor_msgs/Image topic (rgb8, bgr8, mono8, ...)")
      .option("camera-info-topic", "/camera/camera_info", "--bag: sensor_msgs/CameraInfo topic")
      .option("world-frame", "world", "--bag: fixed tf frame of the camera poses")
      .option("depth-topic", "", "--bag: 32FC1 ground-truth depth topic, only for validation errors (\"\" = none)")
      // The camera stream is read as the keyframe_selector reads it: same options, same defaults.
      .option("rectified", bag_defaults.rectified ? 1 : 0,
              "--bag: 1 = images are rectified (intrinsics from P), 0 = from K (keyframe_selector ~rectified)")
      .option("min-translation", bag_defaults.keyframes.min_translation,
              "--bag: metres between keyframes (keyframe_selector ~min_translation)")
      .option("min-rotation-deg", bag_defaults.keyframes.min_rotation_deg, "--bag: or degrees between keyframes")
      .option("min-pose-distance", bag_defaults.keyframes.min_pose_distance,
              "--bag: or combined pose distance (0 = off; ~min_pose_distance)")
      .option("keyframe-buffer", bag_defaults.keyframes.buffer_size,
              "--bag: keyframes searched for neighbours (~buffer_size)")
      .option("min-view-score", bag_defaults.keyframes.min_score,
              "--bag: view-selection score a neighbour needs (~min_view_score)")
      .option("view-score-grid", bag_defaults.keyframes.score_grid,
              "--bag: points per side sampled for the score (~view_score_grid)")
      .option("depth-min", bag_defaults.depth_min, "--bag: plane-sweep depth range near bound (m)")
      .option("depth-max", bag_defaults.depth_max, "--bag: far bound (m)")
      .option("holdout-every", "5", "--bag: hold out every k-th keyframe for validation (0 = none)")
      .option("out", "", "output folder (required unless --eval-only)")
      .option("init", "", "start from this checkpoint (ours or MVSNet_pytorch weights); default random")
      .flag("resume", "continue exactly from OUT/last.pt (with the options of OUT/run_config.txt)")
      .flag("overwrite", "replace the run in a non-empty OUT (its last.pt, best.pt, log, curve, run_config.txt)")
      .option("eval-only", "", "evaluate this checkpoint on --data and exit")
      .option("loss", "robust",
              "naive | first-order | robust (first-order + top-K) | supervised (smooth L1 on --data's depth_gt/)")
      .option("supervised-data", "",
              "rendered folder(s) with depth_gt/, trained on their ground truth in the same run as --data/--bag")
      .option("supervised-share", "0.5", "share of tuples drawn from --supervised-data")
      .option("supervised-weight", "0.1", "weight of the supervised term against the photometric total")
      .option("self-training-every", "0",
              "self-training: every N steps (and at the start) the training tuples are labelled by the current model "
              "where several views agree (fusion thresholds) and train on those labels at --supervised-share, the "
              "others photometrically; no ground truth is read (0 = off)")
      .option("pseudo-label-tuples", "0", "self-training: label at most this many training tuples (0 = all)")
      .option("label-min-confidence", "0.5", "self-training: confidence a labelled pixel needs")
      .option("label-max-relative-depth", "0.03", "self-training: relative depth agreement with the other views")
      .option("label-min-views", "2", "self-training: other views that must agree")
      .option("min-gain", "1", "exposure augmentation: lowest gain applied to a whole tuple (log-uniform draw)")
      .option("max-gain", "1", "exposure augmentation: highest gain (clipped at white)")
      .option("input-normalization", "per_image_channel",
              "new models: none | per_image_channel (each image and channel to zero mean, unit variance)")
      .option("preset", "paper", "loss weights: paper (0.8/0.2/0.0067) | authors (12/6/0.18, Huber, normalised)")
      .option("views-in", "3", "views the network sees (reference + neighbours)")
      .option("views-loss", "6", "neighbours warped by the loss (M)")
      .option("top-k", "3", "views kept per pixel by --loss robust (1..M)")
      .option("width", "640", "network input width (multiple of 32; 0 = from the images)")
      .option("height", "512", "network input height (multiple of 32; 0 = from the images)")
      .option("num-depth", "128", "depth hypotheses during training (multiple of 8)")
      .option("depth-sampling", "depth", "depth | inverse_depth (new models only)")
      .option("steps", "10000", "total optimisation steps (0: write the initial model and exit)")
      .option("batch", "1", "tuples per step")
      .option("lr", "1e-3", "Adam learning rate")
      .option("beta1", "0.95", "Adam beta1")
      .option("val", "", "validation folder(s), comma-separated")
      .option("val-tuples", "0", "validate on at most this many tuples (0 = all)")
      .option("save-every", "500", "validate and checkpoint every this many steps (and at the end)")
      .option("max-minutes", "0", "stop after this much wall time (checkpoint, resumable with --resume; 0 = no limit)")
      .option("augment", "1", "1: random zoom/crop and photometric jitter; 0: none")
      .option("jitter", "0.1", "photometric jitter strength")
      .option("seed", "1", "seed of the initial weights and of the data order")
      .option("device", "cpu", "cpu | cuda | cuda:N")
      .option("threads", "0", "CPU threads (0 = all cores)");
  if (!args.parse(argc, argv)) return 0;
  // Every option is checked before anything is read or written: a refused call changes nothing.
  check_training_options(args);

  umvs::configure_threads(args.integer("threads"));
  const auto device = umvs::parse_device(args.str("device"));

  umvs::TrainerConfig tcfg;
  const std::string preset = args.str("preset");
  if (preset == "paper") tcfg.loss = umvs::LossConfig::paper();
  else if (preset == "authors") tcfg.loss = umvs::LossConfig::authors_code();
  else throw std::invalid_argument("--preset must be paper or authors, got '" + preset + "'");
  const std::string loss = args.str("loss");
  if (loss == "naive") tcfg.loss.term = umvs::PhotometricTerm::kNaive, tcfg.loss.top_k = 0;
  else if (loss == "first-order") tcfg.loss.term = umvs::PhotometricTerm::kFirstOrder, tcfg.loss.top_k = 0;
  else if (loss == "robust" || loss == "supervised") {
    // supervised: the photometric loss still scores validation tuples.
    tcfg.loss.term = umvs::PhotometricTerm::kFirstOrder, tcfg.loss.top_k = args.integer("top-k");
  } else {
    throw std::invalid_argument("--loss must be naive, first-order, robust or supervised, got '" + loss + "'");
  }
  tcfg.supervised_weight = args.real("supervised-weight");
  tcfg.num_depth = args.integer("num-depth");
  tcfg.lr = args.real("lr");
  tcfg.beta1 = args.real("beta1");
  tcfg.validate();

  umvs::TupleConfig data_cfg;
  data_cfg.views_in = args.integer("views-in");
  data_cfg.views_loss = args.integer("views-loss");
  data_cfg.width = args.integer("width");
  data_cfg.height = args.integer("height");
  data_cfg.num_depth = tcfg.num_depth;
  data_cfg.jitter = args.real("jitter");
  data_cfg.min_gain = args.real("min-gain");
  data_cfg.max_gain = args.real("max-gain");
  const int self_training_every = args.integer("self-training-every");
  const bool self_training = self_training_every > 0;
  if (self_training_every < 0) throw std::invalid_argument("--self-training-every must be >= 0");
  if (self_training) {
    if (loss == "supervised" || args.given("supervised-data") || args.given("depth-topic")) {
      throw std::invalid_argument("--self-training-every learns from the model's own consistent depth: it takes no "
                                  "ground truth (--loss supervised, --supervised-data, --depth-topic)");
    }
    data_cfg.read_ground_truth = false;  // label-free, also where the folders have depth_gt/
  }
  const bool augment = args.integer("augment") != 0;
  if (!augment) data_cfg.max_zoom = 1.0;
  data_cfg.validate();
  if (tcfg.loss.top_k > data_cfg.views_loss) {
    throw std::invalid_argument("--top-k " + std::to_string(tcfg.loss.top_k) + " exceeds --views-loss " +
                                std::to_string(data_cfg.views_loss));
  }
  if (data_cfg.width > 0 && data_cfg.height > 0) {
    umvs::check_training_memory(data_cfg.width, data_cfg.height, tcfg.num_depth, data_cfg.views_in,
                                data_cfg.views_loss, args.integer("batch"));
  }
  const bool from_bags = args.given("bag");
  if (from_bags == args.given("data")) throw std::invalid_argument("give either --data folders or --bag files");
  if (from_bags && args.given("val")) {
    throw std::invalid_argument("--val folders cannot be mixed with --bag (held-out keyframes validate; see --holdout-every)");
  }
  const bool eval_only = args.given("eval-only");
  if (from_bags && loss == "supervised") {
    throw std::invalid_argument("--loss supervised needs --data folders with depth_gt/; bags train photometrically "
                                "(add rendered folders with --supervised-data)");
  }
  const bool resume = args.on("resume");
  const std::string out = args.str("out");
  const umvs::RunConfig run_config = run_config_of(args);
  if (!eval_only) {
    std::string warnings;
    umvs::check_run_folder(out, resume ? umvs::RunStart::kResume
                                       : args.on("overwrite") ? umvs::RunStart::kOverwrite : umvs::RunStart::kFresh,
                           run_config, kMayChangeOnResume, &warnings);
    std::cerr << warnings;
  }
  Data data = from_bags ? open_bags(args, data_cfg, eval_only) : open_folders(args, data_cfg);
  if (args.given("supervised-data") && !eval_only) {
    umvs::TupleConfig supervised_cfg = data_cfg;
    supervised_cfg.supervised = true;
    data.supervised = std::make_unique<umvs::MvsFolderSource>(args.all("supervised-data"), supervised_cfg);
    std::cerr << "supervised data: " << data.supervised->description() << ", share "
              << args.real("supervised-share") << ", weight " << tcfg.supervised_weight << "\n";
  }
  // --eval-only scores held-out bag keyframes, or the --data folders themselves.
  std::cerr << "data: " << (eval_only && from_bags ? *data.held_out : *data.train).description()
            << "\nloss: " << tcfg.loss.to_string() << "\n";

  if (eval_only) {
    const umvs::TupleSource& eval_source = from_bags ? *data.held_out : *data.train;
    auto loaded = umvs::load_model(args.str("eval-only"), device);
    const auto tuples = fixed_tuples(eval_source, args.integer("val-tuples"));
    const auto ev = umvs::evaluate_model(loaded.model, tuples, tcfg, device);
    // Label-free judge besides the photometric loss: the share of depth that other views confirm.
    const auto consistency = umvs::depth_consistency(loaded.model, tuples, tcfg.num_depth, umvs::FusionConfig(), device);
    std::cout << args.str("eval-only") << ": " << describe(ev) << ", multi-view consistent "
              << 100.0 * consistency.confirmed_fraction << "%\n";
    if (!args.str("out").empty()) {
      umvs::make_directories(args.str("out"));
      umvs::write_file_atomically(args.str("out") + "/eval.csv", [&](std::ostream& os) {
        os << umvs::csv_header(umvs::eval_columns()) << "\n"
           << args.str("eval-only") << "," << ev.tuples << "," << ev.loss.photometric << "," << ev.loss.ssim << ","
           << ev.loss.smoothness << "," << ev.loss.total << ",";
        if (ev.depth.pixels > 0) {
          os << ev.depth.mean_abs << "," << ev.depth.abs_rel << "," << ev.depth.within_1pct;
        } else {
          os << ",,";
        }
        os << "," << consistency.confirmed_fraction << "\n";
      });
    }
    return 0;
  }

  const std::string last_path = out + "/last.pt", best_path = out + "/best.pt", log_path = out + "/train_log.csv";
  const umvs::TupleSource& source = *data.train;
  // Self-training: the training tuples labelled by the model (refreshed every round), mixed with
  // the photometric tuples like --supervised-data.
  std::unique_ptr<umvs::TupleList> pseudo;
  std::vector<umvs::TrainingTuple> to_label;
  if (self_training) {
    to_label = fixed_tuples(source, args.integer("pseudo-label-tuples"));
    pseudo = std::make_unique<umvs::TupleList>(to_label, "pseudo-labelled training tuples");
    data.supervised.reset();
  }
  std::vector<umvs::TrainingTuple> val_tuples;
  if (data.held_out) {
    val_tuples = fixed_tuples(*data.held_out, args.integer("val-tuples"));
    std::cerr << "validation: " << data.held_out->description() << ", using " << val_tuples.size() << "\n";
  }

  if (data_cfg.width == 0 || data_cfg.height == 0) {  // the size comes from the images
    const auto first = source.tuple(0, nullptr).network_views.at(0).image;
    umvs::check_training_memory(static_cast<int>(first.size(-1)), static_cast<int>(first.size(-2)), tcfg.num_depth,
                                data_cfg.views_in, data_cfg.views_loss, args.integer("batch"));
  }

  // The model: resumed, initialised from a checkpoint, or random.
  umvs::MvsNet model{nullptr};
  umvs::CheckpointMeta meta;
  double best = INFINITY;
  // best.pt candidates are only compared under one metric (a depth error is no loss value).
  std::string best_metric;
  if (resume) {
    auto loaded = umvs::load_model(last_path, device);
    model = loaded.model;
    meta = loaded.meta;
    if (meta.metrics.count("best_score")) best = meta.metrics.at("best_score");
    best_metric = score_metric(meta);
    LogRow planned;
    planned.has_val = !val_tuples.empty();
    for (const auto& t : val_tuples) planned.val.depth.pixels += t.depth_gt.defined() ? 1 : 0;
    if (score_metric(planned) != best_metric) {
      throw std::invalid_argument("--resume: best.pt of this run was chosen by " + best_metric + ", this call would score by " +
                                  score_metric(planned) + "; give the validation data of the run");
    }
    std::cerr << "resuming " << last_path << " at step " << meta.step << "\n";
  } else if (args.given("init")) {
    auto loaded = umvs::load_model(args.str("init"), device);
    model = loaded.model;
    std::cerr << "initialised from " << args.str("init") << " (" << loaded.format << ")\n";
  } else {
    torch::manual_seed(args.integer("seed"));
    umvs::MvsNetConfig mcfg;
    mcfg.num_depth = tcfg.num_depth;
    mcfg.num_views = data_cfg.views_in;
    mcfg.depth_sampling = umvs::depth_sampling_from_string(args.str("depth-sampling"));
    mcfg.input_normalization = umvs::input_normalization_from_string(args.str("input-normalization"));
    model = umvs::MvsNet(mcfg);
  }
  model->set_num_depth(tcfg.num_depth);
  umvs::Trainer trainer(model, device, tcfg);
  // Tuples come from --data/--bag, mixed with --supervised-data at --supervised-share.
  const umvs::TupleSource* supervised_source = self_training ? pseudo.get() : data.supervised.get();
  const bool mixed = supervised_source != nullptr;
  umvs::MixedSampler sampler(mixed ? *supervised_source : source, mixed ? &source : nullptr,
                             args.real("supervised-share"), static_cast<uint64_t>(args.integer("seed")));
  int64_t step = 0;
  std::vector<LogRow> history;
  std::vector<std::string> kept_lines;
  if (resume) {
    trainer.load_optimizer_state(meta.optimizer_state);
    unpack_rng(meta.rng_state, sampler);
    step = meta.step;
    history = read_log(log_path, step, &kept_lines);
  }
  // Everything is checked: from here on OUT changes.
  umvs::make_directories(out);
  if (args.on("overwrite")) umvs::remove_run_files(out);
  umvs::write_run_config(out + "/" + umvs::kRunConfigFile, run_config);
  // The log holds exactly the rows up to the starting step (rows after the resumed checkpoint are dropped).
  umvs::write_file_atomically(log_path, [&](std::ostream& os) {
    os << umvs::csv_header(umvs::train_log_columns()) << "\n";
    for (const auto& l : kept_lines) os << l << "\n";
  });
  std::ofstream log(log_path, std::ios::app);

  const int64_t total_steps = args.integer("steps");
  const int save_every = args.integer("save-every");
  const int batch = args.integer("batch");
  const double max_seconds = 60.0 * args.real("max-minutes");
  const auto started = std::chrono::steady_clock::now();
  double interval_loss = 0;
  int interval_count = 0;

  auto checkpoint = [&](LogRow& row) {
    double score = interval_count > 0 ? interval_loss / interval_count : INFINITY;
    if (!val_tuples.empty()) {
      row.val = trainer.evaluate(val_tuples);
      row.has_val = true;
      score = val_score(row.val);
      std::cerr << "\nstep " << row.step << " validation: " << describe(row.val) << "\n";
    }
    interval_loss = 0;
    interval_count = 0;
    const std::string metric = score_metric(row);
    if (best_metric.empty()) best_metric = metric;
    const bool comparable = metric == best_metric;
    if (!comparable) {
      std::cerr << "\nstep " << row.step << ": scored by " << metric << ", best.pt by " << best_metric
                << ": best.pt kept\n";
    }
    const bool improved = comparable && (std::isfinite(score) ? score < best : !fs::exists(best_path));
    if (improved && std::isfinite(score)) best = score;
    umvs::CheckpointMeta m;
    m.step = row.step;
    m.optimizer_state = trainer.optimizer_state();
    m.rng_state = pack_rng(sampler);
    m.metrics["score"] = score;
    m.metrics["best_score"] = best;
    m.metrics["train_total"] = row.loss.total;
    if (row.has_val) {
      m.metrics["val_photometric"] = row.val.loss.photometric;
      m.metrics["val_total"] = row.val.loss.total;
      if (row.val.depth.pixels > 0) m.metrics["val_abs_err"] = row.val.depth.mean_abs;
    }
    umvs::save_checkpoint(last_path, trainer.model(), m);
    if (improved) umvs::save_checkpoint(best_path, trainer.model(), m);
  };

  if (total_steps == 0 || step >= total_steps) {
    LogRow row;
    row.step = step;
    checkpoint(row);
    std::cout << "wrote the model at step " << step << " to " << last_path << " and " << best_path << "\n";
    return 0;
  }

  std::cerr << "training " << total_steps - step << " steps (" << step << " done), batch " << batch << ", "
            << data_cfg.width << "x" << data_cfg.height << ", D=" << tcfg.num_depth << ", device " << device << ", "
            << torch::get_num_threads() << " threads\n";
  umvs::Progress progress("train", total_steps - step, std::max<int64_t>(1, (total_steps - step) / 50));
  const int64_t first = step;
  int bad_steps = 0;
  // A self-training round starts at every multiple of --self-training-every: its labels come from
  // the model at that step (round_start.pt keeps it, so that a resumed run labels exactly alike).
  const std::string round_path = out + "/round_start.pt";
  // Fusion's rule, loosened for the training size's few planes (32 planes over 0.5-8 m are ~9 %
  // apart in depth, so 1 % agreement would keep almost nothing).
  umvs::FusionConfig label_rule;
  label_rule.min_confidence = args.real("label-min-confidence");
  label_rule.max_relative_depth = args.real("label-max-relative-depth");
  label_rule.min_agreeing_views = args.integer("label-min-views");
  label_rule.validate();
  auto label_round = [&](umvs::MvsNet& labeller) {
    umvs::ConsistencyScore score;
    pseudo->replace(umvs::pseudo_labelled_tuples(labeller, to_label, tcfg.num_depth, label_rule, device,
                                                 &score));
    std::cerr << "\nself-training round at step " << step << ": " << 100.0 * score.confirmed_fraction
              << "% of the reference pixels of " << score.tuples << " tuples confirmed by other views\n";
  };
  if (self_training && step % self_training_every != 0) {  // resumed within a round
    if (!fs::exists(round_path)) throw std::runtime_error("--resume: " + round_path + " is missing");
    auto round_model = umvs::load_model(round_path, device);
    if (round_model.meta.step != step / self_training_every * self_training_every) {
      throw std::runtime_error("--resume: " + round_path + " is from step " + std::to_string(round_model.meta.step) +
                               ", not from the start of the round of step " + std::to_string(step));
    }
    label_round(round_model.model);
  }
  while (step < total_steps) {
    if (self_training && step % self_training_every == 0) {
      label_round(trainer.model());
      umvs::CheckpointMeta m;
      m.step = step;
      umvs::save_checkpoint(round_path, trainer.model(), m);
    }
    const auto t0 = std::chrono::steady_clock::now();
    std::vector<umvs::TrainingTuple> tuples;
    for (int i = 0; i < batch; ++i) tuples.push_back(sampler.next(augment));
    LogRow row;
    row.loss = trainer.step(tuples).mean();
    row.step = ++step;
    row.lr = tcfg.lr;
    row.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!std::isfinite(row.loss.total)) {
      ++bad_steps;
      std::cerr << "\nstep " << step << ": non-finite loss on " << tuples[0].name << ", update skipped\n";
    } else {
      interval_loss += row.loss.total;
      ++interval_count;
    }
    const bool out_of_time =
        max_seconds > 0 && std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count() >= max_seconds;
    if (step % save_every == 0 || step == total_steps || out_of_time) {
      checkpoint(row);
    }
    log << csv_line(row) << "\n" << std::flush;
    history.push_back(row);
    if (row.has_val || step == total_steps || out_of_time) write_curve(out + "/loss_curve.png", history);
    char extra[160];
    std::snprintf(extra, sizeof(extra), "loss %.4f (photo %.4f ssim %.4f smooth %.4f sup %.3f)", row.loss.total,
                  row.loss.photometric, row.loss.ssim, row.loss.smoothness, row.loss.supervised);
    progress.update(step - first, extra);
    if (out_of_time) {
      std::cerr << "\n--max-minutes " << args.real("max-minutes") << " reached at step " << step
                << ": checkpointed; continue with --resume\n";
      break;
    }
  }
  progress.finish();
  std::cout << "trained to step " << step << "; checkpoints " << last_path << ", " << best_path << " (best score "
            << best << "); log " << log_path << (bad_steps ? "; " + std::to_string(bad_steps) + " steps skipped" : "")
            << "\n";
  return 0;
}
