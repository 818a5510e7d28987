#include "unsup_mvs/io/ros/bag_training_data.h"

#include <algorithm>
#include <cmath>
#include <ostream>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/view_selection.h"

namespace umvs {

void BagDataConfig::validate() const {
  KeyframeStreamConfig::validate();
  if (holdout_every < 0 || holdout_every == 1) {
    throw std::invalid_argument("holdout_every must be 0 (none) or >= 2, got " + std::to_string(holdout_every));
  }
  if (topics.image.empty() || topics.camera_info.empty() || topics.world_frame.empty()) {
    throw std::invalid_argument("the image topic, camera_info topic and world frame must not be empty");
  }
}

std::vector<BagKeyframe> read_bag_keyframes(const std::vector<std::string>& bags, const BagDataConfig& config,
                                            std::ostream* log) {
  config.validate();
  if (bags.empty()) throw std::invalid_argument("no bag given");
  std::vector<BagKeyframe> keyframes;
  for (size_t b = 0; b < bags.size(); ++b) {
    KeyframeBuffer policy(config.keyframes);  // per bag: a new log starts a new trajectory
    size_t frame = 0, kept = 0, held_out = 0;
    const BagReadStats stats =
        for_each_posed_image(bags[b], config.topics, config.rectified, [&](const PosedImage& image) {
          if (policy.is_keyframe(image.camera)) {
            policy.add(image.camera, image.stamp);
            const bool hold = config.holdout_every > 0 && kept % config.holdout_every ==
                                                              static_cast<size_t>(config.holdout_every - 1);
            keyframes.push_back({b, frame, hold, image});
            ++kept;
            held_out += hold;
          }
          ++frame;
          return true;
        });
    if (stats.used == 0) {
      std::ostringstream s;
      s << bags[b] << ": no usable posed image on '" << config.topics.image << "' (" << stats.images
        << " images; " << stats.without_info << " without camera_info on '" << config.topics.camera_info << "', "
        << stats.without_pose << " without a transform from '" << config.topics.world_frame << "', "
        << stats.invalid << " invalid" << (stats.first_error.empty() ? "" : ": " + stats.first_error) << ")";
      throw std::runtime_error(s.str());
    }
    if (log) {
      *log << bags[b] << ": " << stats.used << " posed images of " << stats.images << ", " << kept << " keyframes ("
           << held_out << " held out)";
      if (!config.topics.depth.empty()) *log << ", " << stats.with_depth << " images with depth";
      if (stats.used < stats.images) *log << "; skipped: " << stats.first_error;
      *log << "\n";
    }
  }
  return keyframes;
}

BagSource::BagSource(std::shared_ptr<const std::vector<BagKeyframe>> keyframes, BagSplit split, BagDataConfig config,
                     TupleConfig tuple_config)
    : keyframes_(std::move(keyframes)), split_(split), config_(std::move(config)), tuple_config_(tuple_config) {
  config_.validate();
  tuple_config_.validate();
  const auto& all = *keyframes_;
  const size_t needed = static_cast<size_t>(tuple_config_.neighbours_needed());
  const double score_depth = view_selection_depth(config_.depth_min, config_.depth_max);
  for (size_t r = 0; r < all.size(); ++r) {
    const bool wanted = split_ == BagSplit::kAll || (split_ == BagSplit::kHeldOut) == all[r].held_out;
    if (!wanted) continue;
    // Candidates: other keyframes of the same bag; training tuples never touch held-out keyframes.
    std::vector<size_t> ids;
    std::vector<Camera> cameras;
    for (size_t c = 0; c < all.size(); ++c) {
      if (c == r || all[c].bag != all[r].bag) continue;
      if (split_ == BagSplit::kTraining && all[c].held_out) continue;
      ids.push_back(c);
      cameras.push_back(all[c].image.camera);
    }
    const Camera& ref = all[r].image.camera;
    const auto points = sample_frustum_points(ref, score_depth, config_.keyframes.score_grid);
    Entry e{r, {}};
    for (const auto& s : rank_source_views(points, ref, cameras, config_.keyframes.score)) {
      if (s.score < config_.keyframes.min_score || e.sources.size() == needed) break;
      e.sources.push_back(ids[s.index]);
    }
    if (e.sources.size() < needed) {
      ++skipped_;
      continue;
    }
    entries_.push_back(std::move(e));
  }
  if (entries_.empty()) {
    throw std::runtime_error("no " + std::string(split_ == BagSplit::kHeldOut ? "held-out " : "") +
                             "keyframe has " +
                             tuple_config_.neighbours_needed_phrase(" (view-selection score >= " +
                                                                    std::to_string(config_.keyframes.min_score) + ")") +
                             ": record a longer sequence or lower the keyframe thresholds");
  }
}

TrainingTuple BagSource::tuple(size_t index, std::mt19937_64* rng) const {
  if (index >= entries_.size()) throw std::out_of_range("tuple index " + std::to_string(index) + " out of range");
  const Entry& e = entries_[index];
  const auto& all = *keyframes_;
  std::vector<ViewInput> sources;
  for (size_t s : e.sources) sources.push_back({all[s].image.image, all[s].image.camera});
  const BagKeyframe& ref = all[e.ref];
  return make_training_tuple("bag " + std::to_string(ref.bag) + " frame " + std::to_string(ref.frame),
                             {ref.image.image, ref.image.camera}, sources, config_.depth_min, config_.depth_max,
                             ref.image.depth, tuple_config_, rng);
}

std::string BagSource::description() const {
  std::ostringstream s;
  s << entries_.size() << (split_ == BagSplit::kHeldOut ? " held-out" : split_ == BagSplit::kTraining ? " training" : "")
    << " keyframe tuples from " << keyframes_->size() << " keyframes";
  if (skipped_ > 0) {
    s << " (" << skipped_ << " skipped: fewer than " << tuple_config_.neighbours_needed_phrase("") << ")";
  }
  size_t with_gt = 0;
  for (const auto& e : entries_) with_gt += (*keyframes_)[e.ref].image.depth.defined();
  s << ", depth " << config_.depth_min << "-" << config_.depth_max << " m, ";
  if (with_gt == 0) s << "no ground truth";
  else s << with_gt << " with ground-truth depth (" << config_.topics.depth << ")";
  return s.str();
}

}  // namespace umvs
