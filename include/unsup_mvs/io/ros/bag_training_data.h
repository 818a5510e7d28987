// Training tuples from robot logs (rosbags, read with the C++ API: no master). The keyframes are
// the frames the keyframe_selector node would keep (the same KeyframeBuffer policy, per bag);
// each keyframe is a reference whose sources are the other keyframes of its bag ranked by the
// MVSNet view-selection score on points in its frustum, exactly as the node ranks neighbours
// (offline, later keyframes are candidates too).
//
// Held-out keyframes (every holdout_every-th of each bag) give a validation set without ground
// truth: they are never used by training tuples, not even as sources, and `umvs train
// --eval-only` on the same bags with the same flags scores a model on exactly them.
#pragma once

#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include "unsup_mvs/core/keyframes.h"
#include "unsup_mvs/io/ros/bag_io.h"
#include "unsup_mvs/io/training_data.h"

namespace umvs {

// A bag's training data: the camera stream read exactly as the live keyframe_selector reads it
// (KeyframeStreamConfig: intrinsics, keyframe policy, neighbours' min_score / score_grid, depth
// range of every tuple), plus where the messages are and which keyframes are held out.
struct BagDataConfig : KeyframeStreamConfig {
  BagTopics topics;
  int holdout_every = 5;       // keyframes 4, 9, 14, ... of each bag are held out; 0 = none
  void validate() const;       // throws std::invalid_argument naming the field
};

struct BagKeyframe {
  size_t bag = 0;        // index into the bag list
  size_t frame = 0;      // index of the image in its bag (after skipping unusable ones)
  bool held_out = false;
  PosedImage image;
};

// Reads the keyframes of every bag. Throws std::runtime_error naming the bag when it cannot be
// read or yields no posed image (with the first reason, e.g. a missing tf or camera_info).
// Progress and per-bag counts go to `log` when given.
std::vector<BagKeyframe> read_bag_keyframes(const std::vector<std::string>& bags, const BagDataConfig& config,
                                            std::ostream* log = nullptr);

enum class BagSplit { kTraining, kHeldOut, kAll };

class BagSource : public TupleSource {
 public:
  // Tuples with the keyframes of `split` as references. Throws std::runtime_error when none has
  // enough neighbours (max(views_in - 1, views_loss) scoring >= keyframes.min_score).
  BagSource(std::shared_ptr<const std::vector<BagKeyframe>> keyframes, BagSplit split, BagDataConfig config,
            TupleConfig tuple_config);
  size_t size() const override { return entries_.size(); }
  TrainingTuple tuple(size_t index, std::mt19937_64* rng) const override;
  std::string description() const override;

 private:
  struct Entry {
    size_t ref;
    std::vector<size_t> sources;  // best first
  };
  std::shared_ptr<const std::vector<BagKeyframe>> keyframes_;
  BagSplit split_;
  BagDataConfig config_;
  TupleConfig tuple_config_;
  std::vector<Entry> entries_;
  size_t skipped_ = 0;  // references of the split with too few neighbours
};

}  // namespace umvs
