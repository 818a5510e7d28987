// TrainingRun's self-training (jobs/training_run.h): the labelled tuples, the rounds that label
// them with the model of the round's start (round_start.pt) and the anchors of anchored
// self-training (anchor.pt, the model of step 0).
#include <algorithm>
#include <filesystem>
#include <ostream>
#include <stdexcept>
#include <string>

#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/jobs/training_run.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

constexpr const char* kRoundStartFile = "round_start.pt";
constexpr const char* kAnchorFile = "anchor.pt";

// The labelled share of a self-training run: the model's own labels on --data, then the rendered
// scenes of --supervised-data (exact depth), one index range after the other.
class LabelledTuples : public TupleSource {
 public:
  LabelledTuples(const TupleSource& pseudo, std::unique_ptr<TupleSource> rendered)
      : pseudo_(pseudo), rendered_(std::move(rendered)) {}
  size_t size() const override { return pseudo_.size() + rendered_->size(); }
  TrainingTuple tuple(size_t index, std::mt19937_64* rng) const override {
    return index < pseudo_.size() ? pseudo_.tuple(index, rng) : rendered_->tuple(index - pseudo_.size(), rng);
  }
  std::string description() const override { return pseudo_.description() + " and " + rendered_->description(); }

 private:
  const TupleSource& pseudo_;
  std::unique_ptr<TupleSource> rendered_;
};

}  // namespace

void TrainingRun::prepare_self_training() {
  // The training tuples labelled by the model (refreshed every round), mixed with the photometric
  // tuples like supervised data.
  to_label_ = fixed_tuples(*data_.train, config_.pseudo_label_tuples);
  pseudo_ = std::make_unique<TupleList>(to_label_, "pseudo-labelled training tuples");
  if (data_.supervised) {
    data_.supervised = std::make_unique<LabelledTuples>(*pseudo_, std::move(data_.supervised));
    messages_ << "self-training labels drawn with: " << data_.supervised->description() << "\n";
  }
}

std::string TrainingRun::round_path() const { return config_.out + "/" + kRoundStartFile; }

void TrainingRun::start_self_training() {
  if (config_.anchor_unconfirmed) prepare_anchor();
  const int every = config_.self_training_every;
  if (step_ % every == 0) return;
  // Resumed within a round: its labels come from the model at the round's start, as round_start.pt
  // kept it, so that the resumed run labels exactly alike.
  const std::string path = round_path();
  if (!fs::exists(path)) throw std::runtime_error("--resume: " + path + " is missing");
  auto round_model = load_model(path, config_.device);
  if (round_model.meta.step != step_ / every * every) {
    throw std::runtime_error("--resume: " + path + " is from step " + std::to_string(round_model.meta.step) +
                             ", not from the start of the round of step " + std::to_string(step_));
  }
  label_round(round_model.model);
}

void TrainingRun::start_round() {
  label_round(trainer_->model());  // (every rank labels all tuples alike: same model, same labels)
  CheckpointMeta m;
  m.step = step_;
  if (writes_files()) save_checkpoint(round_path(), trainer_->model(), m);
}

void TrainingRun::label_round(MvsNet& labeller) {
  ConsistencyScore score;
  auto labelled = pseudo_labelled_tuples(labeller, to_label_, config_.trainer.num_depth, config_.label_rule,
                                         config_.device, &score, anchor_depth_.empty() ? nullptr : &anchor_depth_,
                                         config_.trainer.sources);
  int64_t labels = 0;
  for (const auto& t : labelled) labels += t.depth_gt.gt(0).sum().item<int64_t>();
  pseudo_->replace(std::move(labelled));
  messages_ << "\nself-training round at step " << step_ << ": " << 100.0 * score.confirmed_fraction
            << "% of the reference pixels of " << score.tuples << " tuples confirmed by other views";
  // Where few pixels are confirmed (far-apart keyframes), an anchored run barely moves the model:
  // say so, so that a user knows why and what the other choice is.
  if (!anchor_depth_.empty() && score.pixels > 0) {
    const double anchored = static_cast<double>(labels) / static_cast<double>(score.pixels) - score.confirmed_fraction;
    messages_ << "; " << 100.0 * anchored
              << "% keep the start model's depth (anchored; --anchor-unconfirmed 0 leaves them to the photometric loss)";
  }
  messages_ << "\n";
}

void TrainingRun::prepare_anchor() {
  const std::string path = config_.out + "/" + kAnchorFile;
  MvsNet anchor{nullptr};
  if (step_ == 0) {
    anchor = trainer_->model();
    CheckpointMeta m;
    if (writes_files()) save_checkpoint(path, anchor, m);
  } else {  // resumed: the model of step 0, as the run kept it
    if (!fs::exists(path)) throw std::runtime_error("--resume: " + path + " (anchored self-training) is missing");
    anchor = load_model(path, config_.device).model;
  }
  anchor_depth_ = reference_depths(anchor, to_label_, config_.trainer.num_depth, config_.device,
                                   config_.anchor_min_confidence, config_.anchor_unseen, config_.trainer.sources);
  messages_ << "anchored self-training: the pixels no view confirms keep the depth of step 0";
  if (config_.anchor_min_confidence > 0.0) {
    int64_t kept = 0, all = 0;
    for (const auto& d : anchor_depth_) kept += d.gt(0).sum().item<int64_t>(), all += d.numel();
    messages_ << " where its confidence is at least " << config_.anchor_min_confidence
              << (config_.anchor_unseen ? " or no loss view sees them" : "") << " ("
              << 100.0 * static_cast<double>(kept) / static_cast<double>(std::max<int64_t>(all, 1)) << "% of the reference pixels)";
  }
  messages_ << "\n";
}

}  // namespace umvs
