// umvs train: unsupervised training / fine-tuning of MVSNet with the robust photometric loss. The
// options are bound to the fields of TrainOptions (jobs/train_options.h), which checks them and turns
// them into the run; jobs/training_run runs it.
#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <stdexcept>
#include <string>

#include "unsup_mvs/core/device.h"
#include "unsup_mvs/io/local_ranks.h"
#include "unsup_mvs/jobs/train_options.h"
#include "unsup_mvs/jobs/training_run.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"
#include "unsup_mvs/tools/progress.h"

namespace {

// The progress line's loss terms.
std::string loss_terms(const umvs::TrainLogRow& row) {
  char text[160];
  std::snprintf(text, sizeof(text), "loss %.4f (photo %.4f ssim %.4f smooth %.4f sup %.3f", row.total.value_or(NAN),
                row.photometric.value_or(NAN), row.ssim.value_or(NAN), row.smoothness.value_or(NAN),
                row.supervised.value_or(NAN));
  std::string line = text;
  auto add_term = [&](const char* name, const std::optional<double>& value) {  // terms only some runs have
    if (!value) return;
    std::snprintf(text, sizeof(text), " %s %.4f", name, *value);
    line += text;
  };
  add_term("entropy", row.entropy);
  add_term("planes", row.plane_loss);
  return line + ")";
}

}  // namespace

UMVS_COMMAND(train, "unsupervised training / fine-tuning with the robust photometric loss") {
  umvs::TrainOptions o;
  umvs::Args args("train",
                  "Trains MVSNet without ground truth: each step runs the network on a reference and its best\n"
                  "neighbours (pair.txt) and minimises the photometric loss of warping the best --views-loss\n"
                  "neighbours into the reference with the predicted depth. Writes into OUT:\n"
                  "  last.pt, best.pt     checkpoints (model, Adam state, step, RNG), written atomically\n"
                  "  train_log.csv        step, loss terms, lr, seconds, validation metrics\n"
                  "  loss_curve.png       training loss (raw, smoothed) and validation score (red), log scale\n"
                  "  run_config.json      the options of the run (versioned); --resume refuses to change them\n"
                  "                       (except --steps, --device, --threads); runs with an older\n"
                  "                       run_config.txt still resume\n"
                  "OUT must be new or empty, unless --resume continues the run in it or --overwrite replaces it.\n"
                  "best.pt is only replaced by a model with a lower validation score: GT depth error when the\n"
                  "--val folders have depth_gt/, else their photometric loss (without --val: the training loss\n"
                  "since the previous checkpoint). With --eval-only CHECKPOINT nothing is trained: the held-out\n"
                  "loss (and GT depth error) of that checkpoint on --data is printed (and written to OUT/eval.csv).\n"
                  "With --bag instead of --data, the keyframes of robot logs are the data (the keyframe_selector's\n"
                  "policy); every --holdout-every-th keyframe is held out for validation, and --eval-only scores\n"
                  "exactly those held-out keyframes.");
  args.bind("data", &o.data, "MVSNet-format folder(s), comma-separated (or --bag)")
      .bind_repeated("bag", &o.bag, "rosbag file(s) with posed images, instead of --data (repeat or comma-separate)")
      .bind("image-topic", &o.image_topic, "--bag: sensor_msgs/Image topic (rgb8, bgr8, mono8, ...)")
      .bind("camera-info-topic", &o.camera_info_topic, "--bag: sensor_msgs/CameraInfo topic")
      .bind("world-frame", &o.world_frame, "--bag: fixed tf frame of the camera poses")
      .bind("depth-topic", &o.depth_topic,
            "--bag: 32FC1 ground-truth depth topic, only for validation errors (\"\" = none)")
      // The camera stream is read as the keyframe_selector reads it: same options, same defaults (o.stream).
      .bind("rectified", &o.stream.rectified,
            "--bag: 1 = images are rectified (intrinsics from P), 0 = from K (keyframe_selector ~rectified)")
      .bind("min-translation", &o.stream.keyframes.min_translation,
            "--bag: metres between keyframes (keyframe_selector ~min_translation)")
      .bind("min-rotation-deg", &o.stream.keyframes.min_rotation_deg, "--bag: or degrees between keyframes")
      .bind("min-pose-distance", &o.stream.keyframes.min_pose_distance,
            "--bag: or combined pose distance (0 = off; ~min_pose_distance)")
      .bind("keyframe-buffer", &o.stream.keyframes.buffer_size,
            "--bag: keyframes searched for neighbours (~buffer_size)")
      .bind("min-view-score", &o.stream.keyframes.min_score,
            "--bag: view-selection score a neighbour needs (~min_view_score)")
      .bind("view-score-grid", &o.stream.keyframes.score_grid,
            "--bag: points per side sampled for the score (~view_score_grid)")
      .bind("depth-min", &o.stream.depth_min, "--bag: plane-sweep depth range near bound (m)")
      .bind("depth-max", &o.stream.depth_max, "--bag: far bound (m)")
      .bind("holdout-every", &o.holdout_every, "--bag: hold out every k-th keyframe for validation (0 = none)")
      .bind("out", &o.out, "output folder (required unless --eval-only)")
      .bind("init", &o.init, "start from this checkpoint (ours or MVSNet_pytorch weights); default random")
      .bind("fine-tuned-share", &o.fine_tuned_share,
            "with --init: at the end also write OUT/blended.pt, this share of best.pt's weights plus the rest of "
            "--init's (weight-space interpolation toward the starting model; the trainer node's ~fine_tuned_share, "
            "docs/results.md); 1 = off")
      .flag("resume", &o.resume, "continue exactly from OUT/last.pt (with the options of OUT/run_config.json)")
      .flag("overwrite", &o.overwrite,
            "replace the run in a non-empty OUT (its last.pt, best.pt, blended.pt, round_start.pt, anchor.pt, log, "
            "curve, run_config.json/.txt)")
      .bind("eval-only", &o.eval_only, "evaluate this checkpoint on --data and exit")
      .bind("against", &o.against,
            "with --eval-only: also evaluate this (served) checkpoint on the same data and say whether the "
            "trainer node's rule would serve the --eval-only one instead")
      .bind("loss", &o.loss,
            "naive | first-order | robust (first-order + top-K) | supervised (smooth L1 on --data's depth_gt/)")
      .bind("supervised-data", &o.supervised_data,
            "rendered folder(s) with depth_gt/, trained on their ground truth in the same run as --data/--bag")
      .bind("supervised-share", &o.supervised_share, "share of tuples drawn from --supervised-data")
      .bind("supervised-weight", &o.supervised_weight, "weight of the supervised term against the photometric total")
      .bind("entropy-weight", &o.entropy_weight,
            "weight of the depth planes' normalised entropy in the photometric loss: makes every pixel confident, "
            "right or not (tested and turned down, docs/training.md; 0 = the paper's loss)")
      .bind("plane-loss-weight", &o.plane_loss_weight,
            "weight of the photometric loss of every depth plane weighed by the network's probability of it: "
            "the probability volume learns where the views agree (better on the living room, worse on rendered "
            "scenes: docs/training.md; 0 = the paper's loss)")
      .bind("self-training-every", &o.self_training_every,
            "self-training: every N steps (and at the start) the training tuples are labelled by the current model "
            "where several views agree (fusion thresholds) and train on those labels at --supervised-share, the "
            "others photometrically; no ground truth is read (0 = off)")
      .bind("pseudo-label-tuples", &o.pseudo_label_tuples,
            "self-training: label at most this many training tuples (0 = all)")
      .bind("label-min-confidence", &o.label_min_confidence, "self-training: confidence a labelled pixel needs")
      .bind("label-max-relative-depth", &o.label_max_relative_depth,
            "self-training: relative depth agreement with the other views")
      .bind("label-min-views", &o.label_min_views, "self-training: other views that must agree")
      .bind("anchor-unconfirmed", &o.anchor_unconfirmed,
            "self-training: 1 = label the pixels no view confirms with the starting model's depth (kept as "
            "OUT/anchor.pt), so that adaptation changes what other views can check and keeps the rest; "
            "0 = leave them unlabelled (plain self-training)")
      .bind("anchor-min-confidence", &o.anchor_min_confidence,
            "anchored self-training: anchor only the pixels the starting model gave at least this confidence "
            "(the others are left to the photometric loss; 0 = every unconfirmed pixel)")
      .bind("anchor-unseen", &o.anchor_unseen,
            "anchored self-training with a confidence floor: 1 = also anchor, whatever their confidence, the "
            "pixels that no loss view sees at the starting model's depth (the photometric loss cannot judge them)")
      .bind("source-combination", &o.source_combination,
            "how the model's depth maps are made for self-training labels and anchors and for the judge's "
            "multi-view consistency (--eval-only): variance | most_confident | auto, as umvs infer's option")
      .bind("min-gain", &o.min_gain, "exposure augmentation: lowest gain applied to a whole tuple (log-uniform draw)")
      .bind("max-gain", &o.max_gain, "exposure augmentation: highest gain (clipped at white)")
      .bind("input-normalization", &o.input_normalization,
            "new models: none | per_image_channel (each image and channel to zero mean, unit variance)")
      .bind("preset", &o.preset, "loss weights: paper (0.8/0.2/0.0067) | authors (12/6/0.18, Huber, normalised)")
      .bind("views-in", &o.views_in, "views the network sees (reference + neighbours)")
      .bind("views-loss", &o.views_loss, "neighbours warped by the loss (M)")
      .bind("top-k", &o.top_k, "views kept per pixel by --loss robust (1..M)")
      .bind("width", &o.width, "network input width (multiple of 32; 0 = from the images)")
      .bind("height", &o.height, "network input height (multiple of 32; 0 = from the images)")
      .bind("num-depth", &o.num_depth,
            "depth hypotheses (multiple of 8; 0 = 128 at 640 wide, scaled with --width, as umvs infer and the "
            "shipped model's training; a --resume without it keeps the run's)")
      .bind("fine-planes", &o.fine_planes,
            "coarse to fine: a second pass of the network over this many per-pixel hypotheses around the first "
            "pass's depth, a loss on each pass (multiple of 8; 0 = one pass; infer with the same --fine-* options)")
      .bind("fine-span", &o.fine_span, "coarse to fine: first-pass plane intervals the fine hypotheses cover")
      .bind("fine-resolution", &o.fine_resolution,
            "coarse to fine: the map at 1/N of the input, 4 or 2 (the loss on that grid)")
      .bind("first-pass-downscale", &o.first_pass_downscale,
            "coarse to fine: 2 = the first pass on the images at half size (a quarter of its work; --width and "
            "--height multiples of 64), 1 = as given")
      .bind("first-pass-loss-weight", &o.first_pass_loss_weight,
            "coarse to fine: weight of the first pass's loss (its depth on the map's grid) against the map's")
      .bind("network", &o.network,
            "new models: mvsnet (3-D U-Net, maps at 1/4) | sweep2d (2-D encoder-decoder built for the CPU, maps "
            "at 1/2, 64 planes; docs/training.md); --init and --resume keep the checkpoint's")
      .bind("depth-sampling", &o.depth_sampling,
            "depth | inverse_depth (new models only; default inverse_depth for --network sweep2d, else depth)")
      .bind("feature-warp", &o.feature_warp,
            "exact | mvsnet_pytorch: where the cost volume samples the source views (default: the --init "
            "model's; exact for new models)")
      .bind("steps", &o.steps, "total optimisation steps (0: write the initial model and exit)")
      .bind("batch", &o.batch, "tuples per step")
      .bind("micro-batch", &o.micro_batch,
            "tuples per forward pass, the step's gradient accumulated over them (0 = the whole batch); "
            "BatchNorm statistics are per micro-batch")
      .bind("batchnorm", &o.batchnorm,
            "train (normalise with each batch's statistics and update the running ones) | frozen (normalise "
            "with the --init model's running statistics and keep them: small-batch fine-tuning); default: frozen "
            "with --fine-planes and --init, else train")
      .bind("lr", &o.lr, "Adam learning rate (at the first step)")
      .bind("lr-schedule", &o.lr_schedule,
            "constant | cosine (from --lr at the first step down to --lr-min at the last of --steps)")
      .bind("lr-min", &o.lr_min, "cosine schedule: learning rate at the last step")
      .bind("beta1", &o.beta1, "Adam beta1")
      .bind("val", &o.val, "validation folder(s), comma-separated")
      .bind("val-tuples", &o.val_tuples, "validate on at most this many tuples (0 = all)")
      .bind("save-every", &o.save_every, "validate and checkpoint every this many steps (and at the end)")
      .bind("max-minutes", &o.max_minutes,
            "stop after this much wall time (checkpoint, resumable with --resume; 0 = no limit)")
      .bind("augment", &o.augment, "1: random zoom/crop and photometric jitter; 0: none")
      .bind("min-zoom", &o.min_zoom,
            "augmentation: smallest zoom of the random crop (1 = each image scaled to just cover --width x "
            "--height; the images' width / --width crops at their own pixel scale, e.g. 2 for 640x512 images "
            "at --width 320: the pixel scale of use, with a quarter of the pixels per step)")
      .bind("max-zoom", &o.max_zoom, "augmentation: largest zoom of the random crop")
      .bind("jitter", &o.jitter, "photometric jitter strength")
      .bind("seed", &o.seed, "seed of the initial weights and of the data order")
      .bind("device", &o.device, "cpu | cuda | cuda:N")
      .bind("threads", &o.threads, "CPU threads (0 = all cores)")
      .bind("nproc", &o.nproc, "data-parallel: start this many local ranks of this command (docs/training.md)")
      .bind("world-size", &o.world_size, "data-parallel: ranks in the job (default: $WORLD_SIZE, else 1)")
      .bind("rank", &o.rank, "data-parallel: this process's rank (default: $RANK, else 0)")
      .bind("master", &o.master,
            "data-parallel: HOST:PORT of rank 0 (default: $MASTER_ADDR:$MASTER_PORT, else 127.0.0.1:29500)")
      .bind("dist-timeout", &o.dist_timeout,
            "data-parallel: seconds to wait for the other ranks (join, each exchange)");
  if (!args.parse(argc, argv)) return 0;
  o.given = args.given_names();
  // Every option is checked before anything is read or written: a refused call changes nothing.
  o.validate();
  const umvs::DistributedConfig distributed = o.distributed_config();
  if (o.nproc > 1 && !o.was_given("eval-only")) {  // (an evaluation runs in one process)
    if (distributed.enabled()) {
      throw std::invalid_argument("--nproc starts its own ranks: no --world-size, --rank or $WORLD_SIZE");
    }
    return umvs::rerun_as_local_ranks("train", argc, argv, o.nproc, std::cerr, std::cout);
  }
  umvs::configure_threads(o.threads);
  const auto device = umvs::parse_device(o.device);
  const umvs::TrainSetup setup = umvs::train_setup(o);
  // The data, opened only after the run folder is checked: a refused run reads nothing.
  auto open_data = [&] { return umvs::open_training_data(o, setup, std::cerr); };
  if (o.was_given("eval-only")) {
    umvs::evaluate_only(o, setup, open_data(), device, std::cout);
    return 0;
  }

  umvs::TrainingRun training(umvs::training_run_config(o, setup, distributed, device, std::cerr), open_data, std::cerr);
  const int64_t to_do = std::max<int64_t>(0, o.steps - training.step());
  std::optional<umvs::Progress> progress;
  if (to_do > 0) {  // (nothing to do: the model is checkpointed as it is)
    std::cerr << "training " << to_do << " steps (" << training.step() << " done), batch " << o.batch << ", "
              << setup.data.width << "x" << setup.data.height << ", D=" << setup.trainer.num_depth << ", device "
              << device << ", " << torch::get_num_threads() << " threads\n";
    progress.emplace("train", to_do, std::max<int64_t>(1, to_do / 50));
  }
  const auto result = training.run(
      [&](const umvs::TrainLogRow& row, int64_t done, int64_t) { progress->update(done, loss_terms(row)); });
  if (!progress) {
    std::cout << "wrote the model at step " << result.step << " to " << training.last_path() << " and "
              << training.best_path() << "\n";
    return 0;
  }
  progress->finish();
  if (result.out_of_time) {
    std::cerr << "--max-minutes " << o.max_minutes << " reached at step " << result.step
              << ": checkpointed; continue with --resume\n";
  }
  std::cout << "trained to step " << result.step << "; checkpoints " << training.last_path() << ", "
            << training.best_path() << " (best score " << result.best_score << "); log " << training.log_path()
            << (result.skipped_steps ? "; " + std::to_string(result.skipped_steps) + " steps skipped" : "")
            << (o.fine_tuned_share < 1 ? "; blended with --init: " + training.blended_path() : "") << "\n";
  return 0;
}
