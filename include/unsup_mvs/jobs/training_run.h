// One training run in its output folder: the data, the model, the optimiser, the checkpoints
// (last.pt, best.pt, written atomically), validation on held-out tuples, self-training rounds and
// the log (train_log.csv, loss_curve.png). `umvs train` only turns its options into a
// TrainingRunConfig and opens the data; everything a run does with them lives here.
#pragma once

#include <functional>
#include <iosfwd>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "unsup_mvs/core/distributed.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/core/mvsnet.h"
#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/run_folder.h"
#include "unsup_mvs/io/training_data.h"

namespace umvs {

// The tuples of a run. `train` is required; `held_out` (validation) and `supervised` (rendered
// folders trained on their ground truth, mixed in at TrainingRunConfig::supervised_share) may be null.
struct TrainingData {
  std::unique_ptr<TupleSource> train, held_out, supervised;
};

struct TrainingRunConfig {
  std::string out;                       // the run folder
  RunStart start = RunStart::kFresh;     // new run, --resume or --overwrite
  RunOptions options = RunOptions::object();  // recorded as run_config.json; a resume must match them
  std::vector<std::string> may_change_on_resume;  // options a resume may change (not compared)
  RunRecordUpgrade upgrade_record;       // an older version's record in today's terms (none: as recorded)
  std::string init;                      // checkpoint to start from; "" = new model (new_model)
  MvsNetConfig new_model;                // the network of a new model (num_views, sampling, ...)
  std::optional<FeatureWarp> feature_warp;  // set on a new or --init model (none: theirs)
  uint64_t seed = 1;                     // initial weights and data order
  TrainerConfig trainer;
  TupleConfig data;                      // the tuples' size and views (memory check)
  int64_t steps = 10000;                 // total optimisation steps of the run
  int batch = 1;
  int save_every = 500;                  // validate and checkpoint every this many steps
  double max_minutes = 0;                // stop after this wall time, checkpointed (0 = no limit)
  bool augment = true;
  int val_tuples = 0;                    // held-out tuples validated on (0 = all)
  double supervised_share = 0.5;         // share of steps' tuples from the supervised source
  // Self-training (0 = off): every N steps the training tuples are labelled by the current model
  // where views agree under label_rule, and trained on at supervised_share.
  int self_training_every = 0;
  int pseudo_label_tuples = 0;           // tuples labelled per round (0 = all)
  FusionConfig label_rule;
  // Anchored self-training: the pixels no view confirms are labelled with the depth of the model
  // the run started from (kept as OUT/anchor.pt), so that a round trains what other views can
  // check and keeps the rest where it was. Only read with self_training_every > 0. On by default:
  // judged on a second pass through rendered scenes, the reload rule served no anchored model
  // worse on two of three depth scores (24 runs), and 4 of the 21 plain ones it served were worse
  // on all three (docs/results.md).
  bool anchor_unconfirmed = true;
  // Anchor only the pixels the start model gave at least this confidence (0 = all): an unconfident
  // guess is no depth worth keeping, and where views rarely overlap nearly every pixel is one.
  double anchor_min_confidence = 0.0;
  // With a floor: anchor also the pixels no loss view sees at the start model's depth, whatever
  // their confidence (core/training.h, seen_by_loss_views): the photometric loss cannot judge them.
  bool anchor_unseen = false;
  // < 1 (needs init): at the end of the run also write OUT/blended.pt, this share of best.pt's
  // weights plus the rest of init's (core/weight_blend.h); 1 = off.
  double fine_tuned_share = 1.0;
  torch::Device device = torch::kCPU;
  // Data-parallel (world_size > 1): this process is one rank. Each step has world_size * batch
  // tuples, in the order one process would draw them; rank r trains on the r-th `batch` of them,
  // the gradients are averaged and every rank applies the same update. BatchNorm statistics are
  // per rank (as TrainerConfig::micro_batch = batch in one process); their running averages are
  // averaged over the ranks at each checkpoint. Validation tuples are shared out and the results
  // summed. Only rank 0 writes the run folder; a resume reads OUT/last.pt on every rank.
  DistributedConfig distributed;
  void validate() const;  // throws std::invalid_argument naming the field
};

class TrainingRun {
 public:
  // Checks the configuration and the run folder (check_run_folder) first, then opens the data
  // (open_data) and the model: resumed from OUT/last.pt, from config.init, or new. Writes nothing:
  // a refused run leaves OUT as it was. Messages (resume, validation) go to `messages`.
  TrainingRun(TrainingRunConfig config, const std::function<TrainingData()>& open_data, std::ostream& messages);
  ~TrainingRun();

  struct Result {
    int64_t step = 0;         // the step of last.pt
    double best_score = 0;    // of best.pt (lower is better; see best_metric)
    std::string best_metric;  // val_abs_err | val_total | train_total
    int skipped_steps = 0;    // non-finite losses, updates skipped
    bool out_of_time = false; // max_minutes ended it before `steps`
  };
  // Trains from the current step to config.steps; on_step after every step with the row just
  // logged, the steps done in this call and the steps this call has to do.
  Result run(const std::function<void(const TrainLogRow& row, int64_t done, int64_t to_do)>& on_step = nullptr);

  int64_t step() const { return step_; }
  MvsNet& model() { return trainer_->model(); }
  // Whether this process writes the run folder (rank 0, or the only process).
  bool writes_files() const { return config_.distributed.rank == 0; }
  std::string last_path() const { return config_.out + "/last.pt"; }
  std::string best_path() const { return config_.out + "/best.pt"; }
  std::string log_path() const { return config_.out + "/train_log.csv"; }
  std::string blended_path() const { return config_.out + "/blended.pt"; }

 private:
  // Scores the model (validation fills `row`), appends `row` to `log` (when given), then saves
  // last.pt and, when it improved, best.pt.
  void checkpoint(TrainLogRow& row, std::ostream* log = nullptr);
  Evaluation validate();                        // on val_tuples_, shared out over the ranks
  std::vector<TrainingTuple> next_tuples();     // this rank's share of the next step
  // Self-training (training_run_self_training.cpp).
  void prepare_self_training();                 // to_label_, pseudo_ (and the rendered labels)
  void start_self_training();                   // anchors; labels of a round resumed within
  void start_round();                           // labels by the current model, kept as round_start.pt
  void label_round(MvsNet& labeller);
  void prepare_anchor();                        // anchor_depth_, from anchor.pt (written at step 0)
  std::string round_path() const;
  void write_curve() const;
  void write_blended();

  TrainingRunConfig config_;
  TrainingData data_;
  std::ostream& messages_;
  std::unique_ptr<ProcessGroup> group_;         // distributed jobs only
  std::unique_ptr<Trainer> trainer_;
  std::unique_ptr<MixedSampler> sampler_;
  std::unique_ptr<TupleList> pseudo_;           // self-training labels
  std::vector<TrainingTuple> to_label_, val_tuples_;
  std::vector<torch::Tensor> anchor_depth_;     // anchored self-training: to_label_'s start depth
  std::vector<TrainLogRow> history_;            // the log up to step_
  int64_t step_ = 0;
  double best_ = 0;
  std::string best_metric_;
  double interval_loss_ = 0;                    // training loss since the last checkpoint
  int interval_count_ = 0;
};

// --eval-only: the held-out loss, GT depth errors (where the tuples have them) and multi-view
// consistency of a checkpoint on (at most max_tuples, 0 = all) tuples of `source`.
EvalRow evaluate_checkpoint(const std::string& checkpoint, const TupleSource& source, int max_tuples,
                            const TrainerConfig& config, const torch::Device& device);
std::string describe(const EvalRow& row);  // one line for people

// `limit` tuples (0 = all) spread evenly over the source, unaugmented.
std::vector<TrainingTuple> fixed_tuples(const TupleSource& source, int limit);

}  // namespace umvs
