// The data of a `umvs train` run and its --eval-only scoring (jobs/train_options.h).
#include <ostream>
#include <stdexcept>
#include <vector>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/jobs/fine_tune_job.h"
#include "unsup_mvs/jobs/train_options.h"
#ifdef UMVS_HAVE_ROS
#include "unsup_mvs/io/ros/bag_training_data.h"
#endif

namespace umvs {

namespace {

TrainingData open_folders(const TrainOptions& o, const TupleConfig& config) {
  TrainingData d;
  TupleConfig train_config = config;
  train_config.supervised = o.loss == "supervised";
  d.train = std::make_unique<MvsFolderSource>(o.data, train_config);
  if (o.was_given("val")) d.held_out = std::make_unique<MvsFolderSource>(o.val, config);
  return d;
}

TrainingData open_bags(const TrainOptions& o, const TupleConfig& config, std::ostream& messages) {
#ifdef UMVS_HAVE_ROS
  BagDataConfig bag;
  static_cast<KeyframeStreamConfig&>(bag) = o.stream;  // read as the keyframe_selector reads its stream
  bag.topics.image = o.image_topic;
  bag.topics.camera_info = o.camera_info_topic;
  bag.topics.world_frame = o.world_frame;
  bag.topics.depth = o.depth_topic;
  bag.holdout_every = o.holdout_every;
  auto keyframes = std::make_shared<const std::vector<BagKeyframe>>(read_bag_keyframes(o.bag, bag, &messages));
  TrainingData d;
  if (bag.holdout_every > 0) d.held_out = std::make_unique<BagSource>(keyframes, BagSplit::kHeldOut, bag, config);
  if (!o.was_given("eval-only")) {
    d.train = std::make_unique<BagSource>(keyframes, bag.holdout_every > 0 ? BagSplit::kTraining : BagSplit::kAll,
                                          bag, config);
  } else if (!d.held_out) {
    d.held_out = std::make_unique<BagSource>(keyframes, BagSplit::kAll, bag, config);
  }
  return d;
#else
  (void)o;
  (void)config;
  (void)messages;
  throw std::invalid_argument("--bag: this umvs was built without ROS (UMVS_WITH_ROS=OFF) and cannot read bags; "
                              "convert the log to an MVSNet folder elsewhere or rebuild with ROS");
#endif
}

// What the trainer node would do with `candidate` while serving `served` (decide_reload), for
// adaptations run by hand.
void print_reload_verdict(const EvalRow& candidate, const EvalRow& served, std::ostream& out) {
  const auto new_scores = eval_scores(candidate), served_scores = eval_scores(served);
  if (!new_scores || !served_scores) {
    throw std::runtime_error("no photometric loss or multi-view consistency to compare (no tuple evaluated?)");
  }
  const ReloadVerdict verdict = decide_reload(*new_scores, *served_scores);
  out << "trainer rule: " << (verdict.reload ? "reload " + candidate.checkpoint : "keep " + served.checkpoint) << " ("
      << verdict.comparison << ")\n";
}

}  // namespace

TrainingData open_training_data(const TrainOptions& o, const TrainSetup& setup, std::ostream& messages) {
  const bool eval_only = o.was_given("eval-only"), from_bags = o.was_given("bag");
  TrainingData data = from_bags ? open_bags(o, setup.data, messages) : open_folders(o, setup.data);
  if (o.was_given("supervised-data") && !eval_only) {
    TupleConfig supervised = setup.data;
    supervised.supervised = true;
    supervised.read_ground_truth = true;  // also when self-training leaves --data's depth_gt/ unread
    data.supervised = std::make_unique<MvsFolderSource>(o.supervised_data, supervised);
    messages << "supervised data: " << data.supervised->description() << ", share " << o.supervised_share
             << ", weight " << setup.trainer.supervised_weight << "\n";
  }
  // --eval-only scores held-out bag keyframes, or the --data folders themselves.
  messages << "data: " << (eval_only && from_bags ? *data.held_out : *data.train).description()
           << "\nloss: " << setup.trainer.loss.to_string() << "\ndepth planes: " << setup.planes.planes << " ("
           << setup.planes.why << ")\n";
  return data;
}

void evaluate_only(const TrainOptions& o, const TrainSetup& setup, const TrainingData& data,
                   const torch::Device& device, std::ostream& out) {
  const TupleSource& source = o.was_given("bag") ? *data.held_out : *data.train;
  auto evaluate = [&](const std::string& checkpoint) {
    EvalRow row = evaluate_checkpoint(checkpoint, source, o.val_tuples, setup.trainer, device);
    out << row.checkpoint << ": " << describe(row) << "\n";
    return row;
  };
  // Both checkpoints are checked before either is evaluated: a bad second path would otherwise
  // be found only after the first evaluation (47 s at 640x480).
  const bool against = o.was_given("against");
  if (against) {
    for (const std::string& checkpoint : {o.against, o.eval_only}) load_model(checkpoint, torch::kCPU);
  }
  // The served model first, so that eval.csv's last row stays the --eval-only checkpoint's.
  std::vector<EvalRow> rows;
  if (against) rows.push_back(evaluate(o.against));
  rows.push_back(evaluate(o.eval_only));
  if (against) print_reload_verdict(rows.back(), rows.front(), out);
  if (o.out.empty()) return;
  make_directories(o.out);
  write_file_atomically(o.out + "/eval.csv", [&](std::ostream& os) {
    os << csv_header(eval_columns()) << "\n";
    for (const auto& row : rows) os << format_csv_row(row) << "\n";
  });
}

}  // namespace umvs
