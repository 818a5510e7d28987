// The record of a `umvs train` run (OUT/run_config.json, jobs/train_options.h): the options as typed
// values, and the records of older versions brought to this one, so that their runs still resume.
#include <algorithm>
#include <cerrno>
#include <climits>
#include <cstdlib>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "unsup_mvs/jobs/train_options.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

// Calls visit(name, value) for every option but --rank (which process this is, not the run).
template <class Visit>
void visit_options(const TrainOptions& o, Visit&& visit) {
  const KeyframeConfig& k = o.stream.keyframes;
  visit("data", o.data);
  visit("bag", o.bag);
  visit("image-topic", o.image_topic);
  visit("camera-info-topic", o.camera_info_topic);
  visit("world-frame", o.world_frame);
  visit("depth-topic", o.depth_topic);
  visit("rectified", o.stream.rectified);
  visit("min-translation", k.min_translation);
  visit("min-rotation-deg", k.min_rotation_deg);
  visit("min-pose-distance", k.min_pose_distance);
  visit("keyframe-buffer", k.buffer_size);
  visit("min-view-score", k.min_score);
  visit("view-score-grid", k.score_grid);
  visit("depth-min", o.stream.depth_min);
  visit("depth-max", o.stream.depth_max);
  visit("holdout-every", o.holdout_every);
  visit("out", o.out);
  visit("init", o.init);
  visit("fine-tuned-share", o.fine_tuned_share);
  visit("resume", o.resume);
  visit("overwrite", o.overwrite);
  visit("eval-only", o.eval_only);
  visit("against", o.against);
  visit("loss", o.loss);
  visit("supervised-data", o.supervised_data);
  visit("supervised-share", o.supervised_share);
  visit("supervised-weight", o.supervised_weight);
  visit("entropy-weight", o.entropy_weight);
  visit("plane-loss-weight", o.plane_loss_weight);
  visit("self-training-every", o.self_training_every);
  visit("pseudo-label-tuples", o.pseudo_label_tuples);
  visit("label-min-confidence", o.label_min_confidence);
  visit("label-max-relative-depth", o.label_max_relative_depth);
  visit("label-min-views", o.label_min_views);
  visit("anchor-unconfirmed", o.anchor_unconfirmed);
  visit("anchor-min-confidence", o.anchor_min_confidence);
  visit("anchor-unseen", o.anchor_unseen);
  visit("source-combination", o.source_combination);
  visit("min-gain", o.min_gain);
  visit("max-gain", o.max_gain);
  visit("input-normalization", o.input_normalization);
  visit("preset", o.preset);
  visit("views-in", o.views_in);
  visit("views-loss", o.views_loss);
  visit("top-k", o.top_k);
  visit("width", o.width);
  visit("height", o.height);
  visit("num-depth", o.num_depth);
  visit("fine-planes", o.fine_planes);
  visit("fine-span", o.fine_span);
  visit("fine-resolution", o.fine_resolution);
  visit("first-pass-downscale", o.first_pass_downscale);
  visit("first-pass-loss-weight", o.first_pass_loss_weight);
  visit("depth-sampling", o.depth_sampling);
  visit("feature-warp", o.feature_warp);
  visit("network", o.network);
  visit("steps", o.steps);
  visit("batch", o.batch);
  visit("micro-batch", o.micro_batch);
  visit("batchnorm", o.batchnorm_mode());
  visit("lr", o.lr);
  visit("lr-schedule", o.lr_schedule);
  visit("lr-min", o.lr_min);
  visit("beta1", o.beta1);
  visit("val", o.val);
  visit("val-tuples", o.val_tuples);
  visit("save-every", o.save_every);
  visit("max-minutes", o.max_minutes);
  visit("augment", o.augment);
  visit("min-zoom", o.min_zoom);
  visit("max-zoom", o.max_zoom);
  visit("jitter", o.jitter);
  visit("seed", o.seed);
  visit("device", o.device);
  visit("threads", o.threads);
  visit("nproc", o.nproc);
  visit("world-size", o.world_size.value_or(1));
  visit("master", o.master);
  visit("dist-timeout", o.dist_timeout);
}

// Absolute and normalised, so that a resume from another working directory compares equal.
std::string absolute_path(const std::string& path) {
  return path.empty() ? path : fs::absolute(path).lexically_normal().string();
}

// A value of run_config.txt (version 1) as the type `like` has; text that does not read as that
// type stays text (and differs from any value of today's option, so a resume names it).
nlohmann::json typed_like(const nlohmann::json& like, const std::string& text) {
  if (like.is_array()) {  // a list: comma-separated
    nlohmann::json items = nlohmann::json::array();
    for (size_t start = 0; start <= text.size();) {
      const size_t comma = std::min(text.find(',', start), text.size());
      if (comma > start) items.push_back(text.substr(start, comma - start));
      start = comma + 1;
    }
    return items;
  }
  if (like.is_string()) return text;
  char* end = nullptr;
  errno = 0;
  if (like.is_number_float()) {
    const double v = std::strtod(text.c_str(), &end);
    if (!text.empty() && *end == '\0') return v;
    return text;
  }
  if (like.is_boolean() && text.empty()) return false;  // a flag not given
  const long v = std::strtol(text.c_str(), &end, 10);
  if (text.empty() || *end != '\0' || errno != 0 || v < INT_MIN || v > INT_MAX) return text;
  if (like.is_boolean()) return v != 0;
  return static_cast<int>(v);
}

}  // namespace

const std::vector<std::string>& train_options_may_change_on_resume() {
  static const std::vector<std::string> names = {"steps",   "max-minutes", "out",    "resume",       "overwrite",
                                                 "eval-only", "device",    "threads", "nproc",       "master",
                                                 "dist-timeout", "fine-tuned-share"};
  return names;
}

RunOptions train_run_options(const TrainOptions& o, const DistributedConfig& distributed) {
  RunOptions options = RunOptions::object();
  visit_options(o, [&](const char* name, const auto& value) { options[name] = value; });
  for (const char* name : {"data", "val", "bag", "supervised-data"}) {
    for (auto& path : options[name]) path = absolute_path(path.get<std::string>());
  }
  options["init"] = absolute_path(o.init);
  // What the run does: anchors only with self-training, the floor only when anchored, the unseen
  // pixels only with a floor.
  options["anchor-unconfirmed"] = o.anchored();
  const double floor = o.anchored() ? o.anchor_min_confidence : 0.0;
  options["anchor-min-confidence"] = floor;
  options["anchor-unseen"] = floor > 0.0 && o.anchor_unseen;
  options["world-size"] = distributed.world_size;  // the job's size, however it was given
  return options;
}

namespace {

// Options newer than every record version: the runs recorded without them had these values.
RunOptions with_later_options(RunOptions options) {
  static const RunOptions later = {
      {"fine-planes", 0},  // one pass: coarse-to-fine training came later
      {"fine-span", 4.0},
      {"fine-resolution", 4},
      {"first-pass-downscale", 1},
      {"first-pass-loss-weight", 0.5},
      {"network", "mvsnet"},  // the 2-D network came later
  };
  for (const auto& entry : later.items()) {
    if (!options.contains(entry.key())) options[entry.key()] = entry.value();
  }
  return options;
}

}  // namespace

RunOptions upgrade_train_record(const RunRecord& record) {
  if (record.version == kRunRecordVersion) return with_later_options(record.options);
  if (record.version != 1) {
    throw std::runtime_error("run configuration '" + record.path + "' has version " + std::to_string(record.version) +
                             ", which this umvs does not know");
  }
  // Version 1 (run_config.txt): every option as text, typed here as today's option is.
  const RunOptions today = train_run_options(TrainOptions{}, DistributedConfig{});
  RunOptions options = RunOptions::object();
  for (const auto& entry : record.options.items()) {
    if (entry.key() == "rank") continue;  // which process this was, never the run's
    const std::string text = entry.value().is_string() ? entry.value().get<std::string>() : entry.value().dump();
    const auto like = today.find(entry.key());
    options[entry.key()] = like == today.end() ? nlohmann::json(text) : typed_like(*like, text);
  }
  // Version 1 left these options out when a run did what runs of the versions before them did
  // (or had not got them yet): those runs had these values.
  const RunOptions omitted = {
      {"anchor-unconfirmed", false},  // recorded as "1" (anchored) or "" since the option existed
      {"anchor-min-confidence", 0.0}, // recorded only for an anchored run with a floor above 0
      {"anchor-unseen", false},        // recorded only when on
      {"source-combination", "variance"},
      {"entropy-weight", 0.0},
      {"plane-loss-weight", 0.0},
      {"batchnorm", "train"},
      {"min-zoom", 1.0},               // the zoom range only when not the default 1-1.25
      {"max-zoom", 1.25},
      {"world-size", 1},               // one process before data-parallel runs
  };
  for (const auto& entry : omitted.items()) {
    if (!options.contains(entry.key())) options[entry.key()] = entry.value();
  }
  return with_later_options(options);
}

std::optional<RunOptions> recorded_train_options(const std::string& out) {
  const auto record = read_run_record(out);
  if (!record) return std::nullopt;
  return upgrade_train_record(*record);
}

}  // namespace umvs
