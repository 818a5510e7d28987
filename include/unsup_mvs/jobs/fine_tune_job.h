// A fine-tuning job of the trainer node, without ROS: checks a request, runs `umvs train --bag ...`
// as a child process (ChildProcess: an argument list, never a shell), reports progress from the
// job's train_log.csv, evaluates the new and the served model on the same held-out keyframes
// (`umvs train --eval-only`, eval.csv) and decides whether the new model should be served. The
// node (ros/trainer.h) only maps parameters, services and topics onto it and calls inference's
// ReloadModel when the job is ready to reload.
//
// Phases: idle -> training -> evaluating new -> evaluating served -> idle (kept, failed) or
// ready to reload -> idle (reload_result / reload_unreachable). cancel() ends any phase.
#pragma once

#include <chrono>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/io/child_process.h"
#include "unsup_mvs/io/run_folder.h"

namespace umvs {

// The `umvs train --bag` options that make it read a bag with `stream` (written by the trainer
// node, parsed by umvs train; a test runs them through `umvs train`).
std::vector<std::string> keyframe_stream_train_args(const KeyframeStreamConfig& stream);

// How jobs run (the trainer node's parameters of the same names; default_steps is ~steps).
struct FineTuneConfig {
  std::string umvs_path;   // absolute path of the umvs tool
  std::string output_dir;  // new models and job folders go here only
  std::string image_topic = "/camera/image_rect_color";  // topics and frame inside the bags
  std::string camera_info_topic = "/camera/camera_info";
  std::string world_frame = "world";
  std::string device = "cpu";           // where jobs train and evaluate: cpu | cuda | cuda:N (umvs train --device)
  int default_steps = 500;              // steps of a request that gives 0
  std::vector<std::string> train_args;  // extra `umvs train` arguments (size, planes, held-out share)
  int local_ranks = 1;  // each training job as this many data-parallel ranks on this machine (--nproc)
  // The model a job judges and may serve: this share of the fine-tuned weights plus the rest of
  // the model it started from (`umvs train --fine-tuned-share`, core/weight_blend.h); 1 = the
  // fine-tuned weights as trained (default). Measured in docs/results.md: 0.5 undid most of what adaptation broke on rendered scenes, not all of it.
  double fine_tuned_share = 1.0;
  KeyframeStreamConfig keyframes;       // how `umvs train` reads the bags (as the keyframe_selector)

  // Throws std::invalid_argument naming the bad field.
  void validate() const;
  // The keyframe options (e.g. "--depth-min") that train_args sets too, overriding `keyframes`.
  std::vector<std::string> keyframe_args_overridden() const;
};

// What the job compares between a fine-tuned and the served model (label-free).
struct EvalScores {
  double photometric = 0.0;  // held-out photometric loss (lower is better)
  double consistent = 0.0;   // share of held-out depth confirmed by other views (higher is better)
};

// The two scores of an evaluation; nullopt when it lacks one of them.
std::optional<EvalScores> eval_scores(const EvalRow& row);
// Reads the held-out photometric loss and multi-view consistency from an eval.csv written by
// `umvs train --eval-only ... --out DIR` (its last row). Returns false when the file is missing or
// lacks them.
bool read_eval_scores(const std::string& eval_csv, EvalScores* scores);

// A photometric loss lower by less than this fraction of the served model's is no evidence either:
// self-training on loose labels raised the consistency of a rendered scene's depth while it got
// worse, at a photometric loss only 0.07 % lower (docs/results.md).
constexpr double kMinPhotometricGain = 0.01;
// Nor is a share of confirmed depth higher by less than this share of the held-out pixels (one
// percentage point; so a model with under 1 % confirmed is never served): fine-tuning an
// earlier default model on the trainer test's rendered bag raised it from 11.8 % to 12.5 % while
// the depth error rose 5 % (docs/results.md).
constexpr double kMinConsistentGain = 0.01;

struct ReloadVerdict {
  bool reload = false;
  std::string comparison;  // "held-out photometric loss: new A, served B; multi-view consistent depth: ..."
};
// Serve the candidate only if its photometric loss is lower by at least kMinPhotometricGain AND
// the share of its depth confirmed by other views is higher by at least kMinConsistentGain: a
// lower photometric loss alone does not mean better depth (it can fall while depth gets worse).
ReloadVerdict decide_reload(const EvalScores& candidate, const EvalScores& served);

struct FineTuneRequest {
  std::vector<std::string> bags;  // each must exist and be a readable file
  std::string init_checkpoint;    // "" = the served model
  int steps = 0;                  // 0 = default_steps
  std::string output;             // inside output_dir, a new name; "" = output_dir/<job_id>.pt
};

// The answer to start() and cancel(): accepted or not, and why.
struct FineTuneAnswer {
  bool ok = false;
  std::string job_id;
  std::string message;
};

// A job's progress (the fields of unsup_mvs/TrainingProgress).
struct FineTuneProgress {
  std::string job_id;
  // "" (no job yet) | training | evaluating | ready to reload | reloaded | kept | failed | cancelled
  std::string state;
  int step = 0;
  int total_steps = 0;
  float loss = 0.f, photometric = 0.f, ssim = 0.f, smoothness = 0.f;  // of the latest logged step
  float eta_seconds = -1.f;                                           // -1 when unknown
  std::string message;
};

class FineTuneJob {
 public:
  enum class Phase { kIdle, kTraining, kEvaluatingNew, kEvaluatingServed, kReadyToReload };

  // Validates `config`, creates output_dir and removes the temporary files that interrupted writes
  // left there (no job runs yet, so no writer is active). Problems that only make requests fail
  // later (output_dir cannot be created, umvs_path is not executable) are in setup_errors().
  explicit FineTuneJob(FineTuneConfig config);

  // Checks the request (refusing with the reason) and starts training. `served_checkpoint` is the
  // model inference serves: the default init and what the new model is compared with.
  FineTuneAnswer start(const FineTuneRequest& request, const std::string& served_checkpoint);

  // Reads the child's output (each line to `on_line`) and its train_log.csv, and moves on to the
  // next phase when the child ended. Returns the progress when there is something to report:
  // every poll while training; "evaluating" when training ended; the verdict ("kept", "failed",
  // "ready to reload"). nullopt otherwise (idle, or an evaluation still running).
  std::optional<FineTuneProgress> poll(const std::function<void(const std::string&)>& on_line = nullptr);

  // Stops the child (SIGTERM, then SIGKILL), removes its temporary files and, when ready to
  // reload, the copy under the output name. Refused when no job runs.
  FineTuneAnswer cancel();

  // When ready to reload: the new model, under its new name, for inference's ReloadModel.
  const std::string& reload_checkpoint() const { return output_path_; }
  // The outcome of ReloadModel: served ("reloaded"), or refused (the copy is removed, "failed").
  const FineTuneProgress& reload_result(bool ok, const std::string& message);
  // ReloadModel could not be called: the copy stays under its name ("failed").
  const FineTuneProgress& reload_unreachable(const std::string& service);

  Phase phase() const { return phase_; }
  bool busy() const { return phase_ != Phase::kIdle; }
  const FineTuneProgress& progress() const { return progress_; }
  const FineTuneConfig& config() const { return config_; }
  const std::vector<std::string>& setup_errors() const { return setup_errors_; }
  int removed_temp_files() const { return removed_temp_files_; }
  // "job ID: STATE, step S/T; MESSAGE" ("no job yet: idle, ..." before the first job).
  std::string describe() const;

 private:
  std::vector<std::string> data_args() const;  // --bag ... and the topic/keyframe/extra options
  std::string candidate_path() const;          // the job's model: blended.pt, or best.pt without a blend
  void start_evaluation(const std::string& checkpoint, const std::string& out_dir, Phase phase);
  void read_training_log();
  FineTuneProgress finish();
  const FineTuneProgress& report(const std::string& state, const std::string& message);

  FineTuneConfig config_;
  std::vector<std::string> setup_errors_;
  int removed_temp_files_ = 0;

  Phase phase_ = Phase::kIdle;
  ChildProcess child_;
  std::string job_dir_, output_path_, served_checkpoint_, comparison_;
  std::vector<std::string> bags_;
  FineTuneProgress progress_;
  EvalScores new_scores_;
  std::chrono::steady_clock::time_point started_;
};

}  // namespace umvs
