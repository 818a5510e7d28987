// umvs train: unsupervised training / fine-tuning of MVSNet with the robust photometric loss. The
// command turns its options into a TrainingRunConfig and opens the data; io/training_run runs it.
#include <torch/torch.h>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <optional>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/distributed.h"
#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/fine_tune_job.h"
#include "unsup_mvs/io/local_ranks.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/io/training_data.h"
#include "unsup_mvs/io/training_run.h"
#ifdef UMVS_HAVE_ROS
#include "unsup_mvs/io/ros/bag_training_data.h"
#endif
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"
#include "unsup_mvs/tools/progress.h"

namespace fs = std::filesystem;

namespace {

umvs::TrainingData open_folders(const umvs::Args& args, const umvs::TupleConfig& config) {
  umvs::TrainingData d;
  umvs::TupleConfig train_config = config;
  train_config.supervised = args.str("loss") == "supervised";
  d.train = std::make_unique<umvs::MvsFolderSource>(args.all("data"), train_config);
  if (args.given("val")) d.held_out = std::make_unique<umvs::MvsFolderSource>(args.all("val"), config);
  return d;
}

umvs::TrainingData open_bags(const umvs::Args& args, const umvs::TupleConfig& config, bool eval_only) {
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
  umvs::TrainingData d;
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
                                                     "threads", "nproc", "master", "dist-timeout", "fine-tuned-share"};

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

// The options the run in OUT was made with (its run_config.txt), if it has one; read only to resume
// it as it was made (check_run_folder still compares every option).
std::optional<umvs::RunConfig> recorded_run_config(const std::string& out) {
  const std::string path = (fs::path(out) / umvs::kRunConfigFile).string();
  if (!fs::is_regular_file(path)) return std::nullopt;
  return umvs::read_run_config(path);
}

// Whether OUT holds an anchored run recorded without a floor: made by a version before
// --anchor-min-confidence defaulted to 0.5, or with 0.
bool anchored_without_recorded_floor(const std::string& out) {
  const auto stored = recorded_run_config(out);
  if (!stored) return false;
  const auto anchored = stored->find("anchor-unconfirmed");
  return anchored != stored->end() && anchored->second == "1" && stored->count("anchor-min-confidence") == 0;
}

// The planes a run sweeps: --num-depth, else those the run in OUT was made with (a --resume), else
// the default for the network width that infer and the inference node also use (the shipped model
// was trained so at each of its sizes: 160 wide with 32, 320 with 64, 640 with 128).
umvs::PlaneCount training_plane_count(const umvs::Args& args) {
  const int requested = args.integer("num-depth");
  if (requested != 0) return {requested, "--num-depth " + std::to_string(requested)};
  const auto stored = args.on("resume") ? recorded_run_config(args.str("out")) : std::nullopt;
  if (stored && stored->count("num-depth")) {
    const std::string& recorded = stored->at("num-depth");
    try {
      return {std::stoi(recorded), "as the run in --out was made"};
    } catch (const std::exception&) {
      throw std::invalid_argument("the run in --out records num-depth '" + recorded + "': give --num-depth");
    }
  }
  const int width = args.integer("width");
  if (width == 0) {
    throw std::invalid_argument("--num-depth 0 follows --width; with --width 0 (each image's own size) give "
                                "--num-depth (128 at 640 wide)");
  }
  const int planes = umvs::default_plane_count(width);
  return {planes, "default for " + std::to_string(width) + " wide: 128 at 640, scaled with the width; --num-depth to change"};
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
  if (args.given("feature-warp")) umvs::feature_warp_from_string(args.str("feature-warp"));
  if (args.given("against") && !args.given("eval-only")) {
    throw std::invalid_argument("--against is compared with the --eval-only checkpoint: give --eval-only too");
  }
  if (args.given("eval-only")) {
    if (args.on("resume") || args.on("overwrite")) throw std::invalid_argument("--eval-only trains nothing: no --resume or --overwrite");
    if (args.given("feature-warp")) {
      throw std::invalid_argument("--eval-only scores the checkpoint as saved: no --feature-warp (export a copy with "
                                  "--init CHECKPOINT --feature-warp ... --steps 0)");
    }
    return;
  }
  const double share = args.real("fine-tuned-share");
  if (!(share > 0 && share <= 1)) {
    throw std::invalid_argument("--fine-tuned-share must be in (0, 1] (1 = no blend), got " + args.str("fine-tuned-share"));
  }
  if (share < 1 && args.str("init").empty()) {
    throw std::invalid_argument("--fine-tuned-share blends best.pt with the model the run starts from: give --init");
  }
  if (args.str("out").empty()) throw std::invalid_argument("--out is required for training");
  if (args.on("resume") && args.on("overwrite")) {
    throw std::invalid_argument("--resume continues the run in --out, --overwrite replaces it: give one of them");
  }
}

// What the trainer node would do with `candidate` while serving `served` (decide_reload), for
// adaptations run by hand.
void print_reload_verdict(const umvs::EvalRow& candidate, const umvs::EvalRow& served) {
  const auto new_scores = umvs::eval_scores(candidate), served_scores = umvs::eval_scores(served);
  if (!new_scores || !served_scores) {
    throw std::runtime_error("no photometric loss or multi-view consistency to compare (no tuple evaluated?)");
  }
  const umvs::ReloadVerdict verdict = umvs::decide_reload(*new_scores, *served_scores);
  std::cout << "trainer rule: " << (verdict.reload ? "reload " + candidate.checkpoint : "keep " + served.checkpoint)
            << " (" << verdict.comparison << ")\n";
}

// --world-size/--rank/--master over the torchrun variables over the defaults.
umvs::DistributedConfig distributed_config_of(const umvs::Args& args) {
  umvs::DistributedConfig d = umvs::distributed_config_from_environment();
  if (!args.str("world-size").empty()) d.world_size = args.integer("world-size");
  if (!args.str("rank").empty()) d.rank = args.integer("rank");
  if (!args.str("master").empty()) {
    const std::string master = args.str("master");
    const auto colon = master.rfind(':');
    if (colon == std::string::npos || colon == 0) throw std::invalid_argument("--master must be HOST:PORT, got '" + master + "'");
    d.master_addr = master.substr(0, colon);
    try {
      d.master_port = std::stoi(master.substr(colon + 1));
    } catch (const std::exception&) {
      throw std::invalid_argument("--master must be HOST:PORT, got '" + master + "'");
    }
  }
  d.timeout_seconds = args.real("dist-timeout");
  try {
    d.validate();
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string("distributed training: ") + e.what());
  }
  if (d.enabled() && !umvs::distributed_available()) {
    throw std::invalid_argument("distributed training: this umvs was built without c10d/Gloo (Debian: libgloo-dev)");
  }
  return d;
}

// --nproc K: this command again as K ranks on this machine; fails as a whole when one rank fails.
int launch_local_ranks(int argc, char** argv, int ranks) {
  std::error_code ec;
  const std::string self = fs::read_symlink("/proc/self/exe", ec).string();
  if (ec) throw std::runtime_error("--nproc: cannot find this program (/proc/self/exe): " + ec.message());
  std::vector<std::string> child = {self, "train"};
  for (int i = 0; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--nproc") {
      ++i;  // and its value
      continue;
    }
    if (arg.rfind("--nproc=", 0) == 0) continue;
    child.push_back(arg);
  }
  std::cerr << "starting " << ranks << " ranks on this machine (rank 0's output follows)\n";
  const umvs::LocalRanksResult result = umvs::run_local_ranks(child, ranks, std::cerr);
  if (result.failed_rank >= 0) {  // the failing rank's exit status (2: bad usage), 1 when it was killed
    std::cerr << "umvs train: error: " << result.message << "\n";
    return result.exit_status > 0 ? result.exit_status : 1;
  }
  std::cout << "all " << ranks << " ranks finished\n";
  return 0;
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
      .option("fine-tuned-share", "1",
              "with --init: at the end also write OUT/blended.pt, this share of best.pt's weights plus the rest of "
              "--init's (weight-space interpolation toward the starting model; the trainer node's ~fine_tuned_share, "
              "docs/results.md); 1 = off")
      .flag("resume", "continue exactly from OUT/last.pt (with the options of OUT/run_config.txt)")
      .flag("overwrite", "replace the run in a non-empty OUT (its last.pt, best.pt, blended.pt, round_start.pt, anchor.pt, log, curve, run_config.txt)")
      .option("eval-only", "", "evaluate this checkpoint on --data and exit")
      .option("against", "",
              "with --eval-only: also evaluate this (served) checkpoint on the same data and say whether the "
              "trainer node's rule would serve the --eval-only one instead")
      .option("loss", "robust",
              "naive | first-order | robust (first-order + top-K) | supervised (smooth L1 on --data's depth_gt/)")
      .option("supervised-data", "",
              "rendered folder(s) with depth_gt/, trained on their ground truth in the same run as --data/--bag")
      .option("supervised-share", "0.5", "share of tuples drawn from --supervised-data")
      .option("supervised-weight", "0.1", "weight of the supervised term against the photometric total")
      .option("entropy-weight", "0",
              "weight of the depth planes' normalised entropy in the photometric loss: makes every pixel confident, "
              "right or not (tested and turned down, docs/training.md; 0 = the paper's loss)")
      .option("plane-loss-weight", "0",
              "weight of the photometric loss of every depth plane weighed by the network's probability of it: "
              "the probability volume learns where the views agree (better on the living room, worse on rendered "
              "scenes: docs/training.md; 0 = the paper's loss)")
      .option("self-training-every", "0",
              "self-training: every N steps (and at the start) the training tuples are labelled by the current model "
              "where several views agree (fusion thresholds) and train on those labels at --supervised-share, the "
              "others photometrically; no ground truth is read (0 = off)")
      .option("pseudo-label-tuples", "0", "self-training: label at most this many training tuples (0 = all)")
      .option("label-min-confidence", "0.5", "self-training: confidence a labelled pixel needs")
      .option("label-max-relative-depth", "0.03", "self-training: relative depth agreement with the other views")
      .option("label-min-views", "2", "self-training: other views that must agree")
      .option("anchor-unconfirmed", "1",
              "self-training: 1 = label the pixels no view confirms with the starting model's depth (kept as "
              "OUT/anchor.pt), so that adaptation changes what other views can check and keeps the rest; "
              "0 = leave them unlabelled (plain self-training)")
      .option("anchor-min-confidence", "0.5",
              "anchored self-training: anchor only the pixels the starting model gave at least this confidence "
              "(the others are left to the photometric loss; 0 = every unconfirmed pixel)")
      .option("anchor-unseen", "0",
              "anchored self-training with a confidence floor: 1 = also anchor, whatever their confidence, the "
              "pixels that no loss view sees at the starting model's depth (the photometric loss cannot judge them)")
      .option("source-combination", "variance",
              "how the model's depth maps are made for self-training labels and anchors and for the judge's "
              "multi-view consistency (--eval-only): variance | most_confident | auto, as umvs infer's option")
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
      .option("num-depth", "0",
              "depth hypotheses (multiple of 8; 0 = 128 at 640 wide, scaled with --width, as umvs infer and the "
              "shipped model's training; a --resume without it keeps the run's)")
      .option("depth-sampling", "depth", "depth | inverse_depth (new models only)")
      .option("feature-warp", "",
              "exact | mvsnet_pytorch: where the cost volume samples the source views (default: the --init "
              "model's; exact for new models)")
      .option("steps", "10000", "total optimisation steps (0: write the initial model and exit)")
      .option("batch", "1", "tuples per step")
      .option("micro-batch", "0",
              "tuples per forward pass, the step's gradient accumulated over them (0 = the whole batch); "
              "BatchNorm statistics are per micro-batch")
      .option("batchnorm", "train",
              "train (normalise with each batch's statistics and update the running ones) | frozen (normalise "
              "with the --init model's running statistics and keep them: small-batch fine-tuning)")
      .option("lr", "1e-3", "Adam learning rate (at the first step)")
      .option("lr-schedule", "constant",
              "constant | cosine (from --lr at the first step down to --lr-min at the last of --steps)")
      .option("lr-min", "0", "cosine schedule: learning rate at the last step")
      .option("beta1", "0.95", "Adam beta1")
      .option("val", "", "validation folder(s), comma-separated")
      .option("val-tuples", "0", "validate on at most this many tuples (0 = all)")
      .option("save-every", "500", "validate and checkpoint every this many steps (and at the end)")
      .option("max-minutes", "0", "stop after this much wall time (checkpoint, resumable with --resume; 0 = no limit)")
      .option("augment", "1", "1: random zoom/crop and photometric jitter; 0: none")
      .option("min-zoom", "1",
              "augmentation: smallest zoom of the random crop (1 = each image scaled to just cover --width x "
              "--height; the images' width / --width crops at their own pixel scale, e.g. 2 for 640x512 images "
              "at --width 320: the pixel scale of use, with a quarter of the pixels per step)")
      .option("max-zoom", "1.25", "augmentation: largest zoom of the random crop")
      .option("jitter", "0.1", "photometric jitter strength")
      .option("seed", "1", "seed of the initial weights and of the data order")
      .option("device", "cpu", "cpu | cuda | cuda:N")
      .option("threads", 0, "CPU threads (0 = all cores)")
      .option("nproc", "1", "data-parallel: start this many local ranks of this command (docs/training.md)")
      .option("world-size", "", "data-parallel: ranks in the job (default: $WORLD_SIZE, else 1)")
      .option("rank", "", "data-parallel: this process's rank (default: $RANK, else 0)")
      .option("master", "", "data-parallel: HOST:PORT of rank 0 (default: $MASTER_ADDR:$MASTER_PORT, else 127.0.0.1:29500)")
      .option("dist-timeout", "120", "data-parallel: seconds to wait for the other ranks (join, each exchange)");
  if (!args.parse(argc, argv)) return 0;
  // Every option is checked before anything is read or written: a refused call changes nothing.
  check_training_options(args);
  const umvs::DistributedConfig distributed = distributed_config_of(args);
  if (args.integer("nproc") > 1 && !args.given("eval-only")) {  // (an evaluation runs in one process)
    if (distributed.enabled()) throw std::invalid_argument("--nproc starts its own ranks: no --world-size, --rank or $WORLD_SIZE");
    return launch_local_ranks(argc, argv, args.integer("nproc"));
  }

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
  tcfg.entropy_weight = args.real("entropy-weight");
  tcfg.plane_loss_weight = args.real("plane-loss-weight");
  const umvs::PlaneCount planes = training_plane_count(args);
  tcfg.num_depth = planes.planes;
  tcfg.lr = args.real("lr");
  tcfg.lr_schedule = umvs::parse_lr_schedule(args.str("lr-schedule"));
  tcfg.lr_min = args.real("lr-min");
  tcfg.beta1 = args.real("beta1");
  tcfg.micro_batch = args.integer("micro-batch");
  const std::string batchnorm = args.str("batchnorm");
  if (batchnorm != "train" && batchnorm != "frozen") {
    throw std::invalid_argument("--batchnorm must be train or frozen, got '" + batchnorm + "'");
  }
  tcfg.freeze_batchnorm = batchnorm == "frozen";
  tcfg.sources = umvs::source_combination_from_string(args.str("source-combination"));
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
    if (loss == "supervised" || args.given("depth-topic")) {
      throw std::invalid_argument("--self-training-every learns from the model's own consistent depth: it reads no "
                                  "ground truth of the training images (--loss supervised, --depth-topic); rendered "
                                  "scenes with exact depth may join through --supervised-data");
    }
    data_cfg.read_ground_truth = false;  // label-free, also where the folders have depth_gt/
  } else if (args.given("anchor-unconfirmed")) {
    throw std::invalid_argument("--anchor-unconfirmed labels self-training's unconfirmed pixels: give --self-training-every N");
  }
  const std::string anchor = args.str("anchor-unconfirmed");
  if (anchor != "0" && anchor != "1") throw std::invalid_argument("--anchor-unconfirmed must be 0 or 1, got '" + anchor + "'");
  const double anchor_min_confidence = args.real("anchor-min-confidence");
  if (!(anchor_min_confidence >= 0.0 && anchor_min_confidence <= 1.0)) {
    throw std::invalid_argument("--anchor-min-confidence must be in [0, 1], got " + args.str("anchor-min-confidence"));
  }
  if (args.given("anchor-min-confidence") && !(self_training && anchor == "1")) {
    throw std::invalid_argument("--anchor-min-confidence chooses which pixels anchored self-training anchors: give "
                                "--self-training-every N (and not --anchor-unconfirmed 0)");
  }
  const std::string anchor_unseen = args.str("anchor-unseen");
  if (anchor_unseen != "0" && anchor_unseen != "1") {
    throw std::invalid_argument("--anchor-unseen must be 0 or 1, got '" + anchor_unseen + "'");
  }
  if (args.given("anchor-unseen") && !(self_training && anchor == "1" && anchor_min_confidence > 0.0)) {
    throw std::invalid_argument("--anchor-unseen adds pixels to the anchored ones of a run with a confidence floor: give "
                                "--self-training-every N and an --anchor-min-confidence above 0 (and not "
                                "--anchor-unconfirmed 0)");
  }
  const bool augment = args.integer("augment") != 0;
  if (!augment && (args.given("min-zoom") || args.given("max-zoom"))) {
    throw std::invalid_argument("--min-zoom/--max-zoom set the random crop of --augment 1; --augment 0 crops nothing");
  }
  data_cfg.min_zoom = augment ? args.real("min-zoom") : 1.0;
  data_cfg.max_zoom = augment ? args.real("max-zoom") : 1.0;
  data_cfg.validate();
  if (tcfg.loss.top_k > data_cfg.views_loss) {
    throw std::invalid_argument("--top-k " + std::to_string(tcfg.loss.top_k) + " exceeds --views-loss " +
                                std::to_string(data_cfg.views_loss));
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
  // The data, opened only after the run folder is checked: a refused run reads nothing.
  auto open_data = [&] {
    umvs::TrainingData data = from_bags ? open_bags(args, data_cfg, eval_only) : open_folders(args, data_cfg);
    if (args.given("supervised-data") && !eval_only) {
      umvs::TupleConfig supervised_cfg = data_cfg;
      supervised_cfg.supervised = true;
      supervised_cfg.read_ground_truth = true;  // also when self-training leaves --data's depth_gt/ unread
      data.supervised = std::make_unique<umvs::MvsFolderSource>(args.all("supervised-data"), supervised_cfg);
      std::cerr << "supervised data: " << data.supervised->description() << ", share "
                << args.real("supervised-share") << ", weight " << tcfg.supervised_weight << "\n";
    }
    // --eval-only scores held-out bag keyframes, or the --data folders themselves.
    std::cerr << "data: " << (eval_only && from_bags ? *data.held_out : *data.train).description()
              << "\nloss: " << tcfg.loss.to_string() << "\ndepth planes: " << tcfg.num_depth << " (" << planes.why
              << ")\n";
    return data;
  };

  if (eval_only) {
    const umvs::TrainingData data = open_data();
    auto evaluate = [&](const std::string& checkpoint) {
      umvs::EvalRow row = umvs::evaluate_checkpoint(checkpoint, from_bags ? *data.held_out : *data.train,
                                                    args.integer("val-tuples"), tcfg, device);
      std::cout << row.checkpoint << ": " << umvs::describe(row) << "\n";
      return row;
    };
    // Both checkpoints are checked before either is evaluated: a bad second path would otherwise
    // be found only after the first evaluation (47 s at 640x480).
    if (args.given("against")) {
      for (const char* option : {"against", "eval-only"}) umvs::load_model(args.str(option), torch::kCPU);
    }
    // The served model first, so that eval.csv's last row stays the --eval-only checkpoint's.
    std::vector<umvs::EvalRow> rows;
    if (args.given("against")) rows.push_back(evaluate(args.str("against")));
    rows.push_back(evaluate(args.str("eval-only")));
    if (args.given("against")) print_reload_verdict(rows.back(), rows.front());
    if (!args.str("out").empty()) {
      umvs::make_directories(args.str("out"));
      umvs::write_file_atomically(args.str("out") + "/eval.csv", [&](std::ostream& os) {
        os << umvs::csv_header(umvs::eval_columns()) << "\n";
        for (const auto& row : rows) os << umvs::format_csv_row(row) << "\n";
      });
    }
    return 0;
  }

  umvs::TrainingRunConfig run;
  run.out = args.str("out");
  run.start = args.on("resume") ? umvs::RunStart::kResume
              : args.on("overwrite") ? umvs::RunStart::kOverwrite
                                     : umvs::RunStart::kFresh;
  run.options = run_config_of(args);
  run.options["num-depth"] = std::to_string(tcfg.num_depth);  // the count, whether given or followed from --width
  run.may_change_on_resume = kMayChangeOnResume;
  run.init = args.str("init");
  run.fine_tuned_share = args.real("fine-tuned-share");
  run.new_model.depth_sampling = umvs::depth_sampling_from_string(args.str("depth-sampling"));
  run.new_model.input_normalization = umvs::input_normalization_from_string(args.str("input-normalization"));
  if (args.given("feature-warp")) run.feature_warp = umvs::feature_warp_from_string(args.str("feature-warp"));
  run.seed = static_cast<uint64_t>(args.integer("seed"));
  run.trainer = tcfg;
  run.data = data_cfg;
  run.steps = args.integer("steps");
  run.batch = args.integer("batch");
  run.save_every = args.integer("save-every");
  run.max_minutes = args.real("max-minutes");
  run.augment = augment;
  run.val_tuples = args.integer("val-tuples");
  run.supervised_share = args.real("supervised-share");
  run.self_training_every = self_training_every;
  run.pseudo_label_tuples = args.integer("pseudo-label-tuples");
  // Fusion's rule, loosened for the training size's few planes (32 planes over 0.5-8 m are ~9 %
  // apart in depth, so 1 % agreement would keep almost nothing).
  run.label_rule.min_confidence = args.real("label-min-confidence");
  run.label_rule.max_relative_depth = args.real("label-max-relative-depth");
  run.label_rule.min_agreeing_views = args.integer("label-min-views");
  run.anchor_unconfirmed = self_training && anchor == "1";
  // Recorded as what the run does, as the flag it was before anchoring became the default recorded
  // it ("1" anchored, "" otherwise), so that the runs of older versions still resume.
  run.options["anchor-unconfirmed"] = run.anchor_unconfirmed ? "1" : "";
  run.anchor_min_confidence = run.anchor_unconfirmed ? anchor_min_confidence : 0.0;
  // An anchored run of a version before the 0.5 default has no floor recorded: resumed without the
  // option, it continues with the floor it was made with (0) instead of being refused.
  if (run.anchor_unconfirmed && args.on("resume") && !args.given("anchor-min-confidence") &&
      anchored_without_recorded_floor(args.str("out"))) {
    run.anchor_min_confidence = 0.0;
    std::cerr << "--resume: the run in " << args.str("out")
              << " anchors every unconfirmed pixel (no floor recorded: made with --anchor-min-confidence 0 or "
                 "before it defaulted to 0.5): it continues so\n";
  }
  // Recorded only for an anchored run with a floor, so that runs without one (and those of versions
  // before the option) resume.
  run.options.erase("anchor-min-confidence");
  if (run.anchor_min_confidence > 0.0) run.options["anchor-min-confidence"] = args.str("anchor-min-confidence");
  run.anchor_unseen = run.anchor_min_confidence > 0.0 && anchor_unseen == "1";
  // Recorded only when on, so that runs of versions before the option resume.
  run.options.erase("anchor-unseen");
  if (run.anchor_unseen) run.options["anchor-unseen"] = "1";
  if (tcfg.sources == umvs::SourceCombination::kVariance) run.options.erase("source-combination");  // likewise
  if (tcfg.entropy_weight == 0) run.options.erase("entropy-weight");                                 // likewise
  if (tcfg.plane_loss_weight == 0) run.options.erase("plane-loss-weight");                           // likewise
  if (!tcfg.freeze_batchnorm) run.options.erase("batchnorm");                                        // likewise
  run.device = device;
  run.distributed = distributed;
  run.options["world-size"] = std::to_string(distributed.world_size);  // the job's size, however it was given
  run.options.erase("rank");
  // The zoom range is recorded only when it is not the default, so that runs of versions before
  // the options (which zoomed by 1-1.25) still resume.
  if (args.real("min-zoom") == 1.0 && args.real("max-zoom") == 1.25) {
    run.options.erase("min-zoom");
    run.options.erase("max-zoom");
  }
  umvs::TrainingRun training(run, open_data, std::cerr);

  const int64_t to_do = std::max<int64_t>(0, run.steps - training.step());
  if (to_do > 0) {  // (nothing to do: the model is checkpointed as it is)
    std::cerr << "training " << to_do << " steps (" << training.step() << " done), batch " << run.batch << ", "
              << data_cfg.width << "x" << data_cfg.height << ", D=" << tcfg.num_depth << ", device " << device << ", "
              << torch::get_num_threads() << " threads\n";
  }
  std::optional<umvs::Progress> progress;
  if (to_do > 0) progress.emplace("train", to_do, std::max<int64_t>(1, to_do / 50));
  const auto result = training.run([&](const umvs::TrainLogRow& row, int64_t done, int64_t) {
    char extra[160];
    std::snprintf(extra, sizeof(extra), "loss %.4f (photo %.4f ssim %.4f smooth %.4f sup %.3f", row.total.value_or(NAN),
                  row.photometric.value_or(NAN), row.ssim.value_or(NAN), row.smoothness.value_or(NAN),
                  row.supervised.value_or(NAN));
    std::string line = extra;
    auto add_term = [&](const char* name, const std::optional<double>& value) {  // terms only some runs have
      if (!value) return;
      std::snprintf(extra, sizeof(extra), " %s %.4f", name, *value);
      line += extra;
    };
    add_term("entropy", row.entropy);
    add_term("planes", row.plane_loss);
    line += ")";
    progress->update(done, line);
  });
  if (!progress) {
    std::cout << "wrote the model at step " << result.step << " to " << training.last_path() << " and "
              << training.best_path() << "\n";
    return 0;
  }
  progress->finish();
  if (result.out_of_time) {
    std::cerr << "--max-minutes " << run.max_minutes << " reached at step " << result.step
              << ": checkpointed; continue with --resume\n";
  }
  std::cout << "trained to step " << result.step << "; checkpoints " << training.last_path() << ", "
            << training.best_path() << " (best score " << result.best_score << "); log " << training.log_path()
            << (result.skipped_steps ? "; " + std::to_string(result.skipped_steps) + " steps skipped" : "")
            << (run.fine_tuned_share < 1 ? "; blended with --init: " + training.blended_path() : "") << "\n";
  return 0;
}
