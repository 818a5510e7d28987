// The options of `umvs train` as one typed struct, their checks, and what they turn into: the
// TrainerConfig, TupleConfig and TrainingRunConfig of jobs/training_run.h, the data, and the record
// of the run (OUT/run_config.json) that a --resume is compared with. src/tools/cmd_train.cpp only
// declares the options (bound to these fields: each field's initialiser is the option's default)
// and calls these functions.
#pragma once

#include <iosfwd>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "unsup_mvs/core/distributed.h"
#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/io/training_data.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {

// One field per option of `umvs train`: the option's name with '_' for '-' (the camera stream's
// in `stream`); lists are comma-separated or repeated on the command line.
struct TrainOptions {
  // The data: MVSNet folders, or robot logs read as the keyframe_selector reads its stream.
  std::vector<std::string> data, bag, val, supervised_data;
  std::string image_topic = "/camera/image_rect_color", camera_info_topic = "/camera/camera_info";
  std::string world_frame = "world", depth_topic;
  KeyframeStreamConfig stream;  // --rectified, the keyframe policy, --depth-min/max: the selector's defaults
  int holdout_every = 5;
  // The run folder and the starting model.
  std::string out, init;
  double fine_tuned_share = 1;
  bool resume = false, overwrite = false;
  std::string eval_only, against;
  // The loss.
  std::string loss = "robust", preset = "paper";
  double supervised_share = 0.5, supervised_weight = 0.1, entropy_weight = 0, plane_loss_weight = 0;
  // Self-training.
  int self_training_every = 0, pseudo_label_tuples = 0;
  double label_min_confidence = 0.5, label_max_relative_depth = 0.03;
  int label_min_views = 2;
  bool anchor_unconfirmed = true;
  double anchor_min_confidence = 0.5;
  bool anchor_unseen = false;
  std::string source_combination = "variance";
  // The tuples and the network.
  double min_gain = 1, max_gain = 1;
  std::string input_normalization = "per_image_channel";
  int views_in = 3, views_loss = 6, top_k = 3, width = 640, height = 512;
  int num_depth = 0;  // 0: the run's own on --resume, else the default for --width
  // Coarse to fine (TrainerConfig::fine): fine planes 0 = one pass.
  int fine_planes = 0, fine_resolution = 4, first_pass_downscale = 1;
  double fine_span = 4, first_pass_loss_weight = 0.5;
  std::string depth_sampling = "depth", feature_warp;  // sampling when not given: depth_sampling_mode()
  std::string network = "mvsnet";  // of a new model: mvsnet | sweep2d
  // The optimisation.
  int steps = 10000, batch = 1, micro_batch = 0;
  std::string batchnorm = "train";  // when not given: batchnorm_mode()
  double lr = 1e-3;
  std::string lr_schedule = "constant";
  double lr_min = 0, beta1 = 0.95;
  int val_tuples = 0, save_every = 500;
  double max_minutes = 0;
  bool augment = true;
  double min_zoom = 1, max_zoom = 1.25, jitter = 0.1;
  int seed = 1;
  // Where it runs.
  std::string device = "cpu";
  int threads = 0, nproc = 1;
  std::optional<int> world_size, rank;  // unset: $WORLD_SIZE / $RANK, else 1 / 0
  std::string master;                   // HOST:PORT; "": $MASTER_ADDR:$MASTER_PORT
  double dist_timeout = 120;

  // The options given on the command line (by name); the others keep their defaults. Some checks
  // refuse an option only when it was given.
  std::set<std::string> given;
  bool was_given(const std::string& name) const { return given.count(name) > 0; }

  bool self_training() const { return self_training_every > 0; }
  // --batchnorm as given; when not given, frozen for a coarse-to-fine run from --init (training
  // statistics would average the two passes' volumes into one running mean that fits neither),
  // else train.
  std::string batchnorm_mode() const;
  // --depth-sampling, else inverse_depth for a new sweep2d network (planes for 0.3-8 m rooms) and
  // depth otherwise.
  std::string depth_sampling_mode() const;
  bool anchored() const { return self_training() && anchor_unconfirmed; }

  // Every check that needs no file, before anything is read or written. Throws
  // std::invalid_argument naming the option.
  void validate() const;
  // --world-size/--rank/--master over the torchrun variables over the defaults, checked.
  DistributedConfig distributed_config() const;
};

// The options a --resume may change: they do not change what the run computes.
const std::vector<std::string>& train_options_may_change_on_resume();

// The record of a run: every option as a typed value (paths absolute), with what the run does
// where an option follows another: num-depth (`options` as the run uses them: the count chosen),
// the anchors (off without self-training), world-size (`distributed`'s); no rank.
RunOptions train_run_options(const TrainOptions& options, const DistributedConfig& distributed);

// A run's record brought to this version (kRunRecordVersion): the text values of run_config.txt
// (version 1) typed as today's options, and the options that version 1 recorded only when they
// differed from how older versions ran (anchors, zoom, volume terms, batchnorm, source
// combination) given those values. Throws std::runtime_error for a version newer than this one.
RunOptions upgrade_train_record(const RunRecord& record);

// The options of the run in `out` (run_config.json, else run_config.txt), upgraded; nullopt
// when it has neither.
std::optional<RunOptions> recorded_train_options(const std::string& out);

// What the options turn into, once the planes are chosen.
struct TrainSetup {
  PlaneCount planes;  // --num-depth, else the run's own (--resume), else the default for --width
  TrainerConfig trainer;
  TupleConfig data;
  std::optional<RunOptions> recorded;  // --resume: the options of the run in --out
};
// Reads the run in --out for a --resume; throws std::invalid_argument for a plane count it
// cannot choose (--width 0 without --num-depth).
TrainSetup train_setup(const TrainOptions& options);

// The run: the setup, the record, and a --resume of an anchored run recorded without a floor
// continuing without one unless --anchor-min-confidence is given (said on `messages`).
TrainingRunConfig training_run_config(const TrainOptions& options, const TrainSetup& setup,
                                      const DistributedConfig& distributed, const torch::Device& device,
                                      std::ostream& messages);

// The data of the run (or of --eval-only): --data folders or --bag keyframes, --val, and
// --supervised-data; says what was opened on `messages`. Throws std::invalid_argument for --bag
// in a build without ROS.
TrainingData open_training_data(const TrainOptions& options, const TrainSetup& setup, std::ostream& messages);

// --eval-only (and --against first): one line per checkpoint on `out`, the trainer node's
// verdict with --against, and OUT/eval.csv when --out is given. Both checkpoints are loaded
// before either is evaluated.
void evaluate_only(const TrainOptions& options, const TrainSetup& setup, const TrainingData& data,
                   const torch::Device& device, std::ostream& out);

}  // namespace umvs
