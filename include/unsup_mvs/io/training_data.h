// Training tuples (core/training.h) from data on disk. A TupleSource is anything that can hand
// out tuples by index; `umvs train` mixes sources, so other kinds (e.g. keyframes from rosbags)
// only need to implement this interface.
#pragma once

#include <algorithm>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "unsup_mvs/core/training.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {

struct TupleConfig {
  int views_in = 3;     // views the network sees (reference + N-1 best neighbours)
  int views_loss = 6;   // neighbours the loss warps into the reference (M)
  int width = 640;      // network input size (multiples of 32); 0 = the reference's size rounded down
  int height = 512;
  int num_depth = 128;  // only to resolve cam files that give DEPTH_MIN and DEPTH_INTERVAL alone
  // Augmentation (training only): zoom in by a random factor in [min_zoom, max_zoom] and crop at a
  // random offset (intrinsics follow), then one photometric jitter for all views of the tuple:
  // contrast and per-channel gain in [1 - jitter, 1 + jitter], brightness in [-jitter/2, jitter/2].
  // Zoom 1 scales the image to just cover width x height; a zoom of (image width / width) crops at
  // the image's own pixel scale (e.g. 2 for 640x512 images trained at 320x256).
  double min_zoom = 1.0, max_zoom = 1.25;
  double jitter = 0.1;
  // Exposure augmentation (training only): after the jitter, all views of the tuple are
  // multiplied by one gain drawn log-uniformly from [min_gain, max_gain] and clipped at 1, as a
  // darker or saturating camera would record them. [1, 1] = off (no random draw).
  double min_gain = 1.0, max_gain = 1.0;
  // Tuples are trained on their ground truth (TrainingTuple::supervised): every reference must
  // have one (rendered data).
  bool supervised = false;
  // false: depth_gt/ is never opened (label-free runs such as self-training stay label-free even
  // where the folders have ground truth).
  bool read_ground_truth = true;
  void validate() const;  // throws std::invalid_argument naming the field
  // Neighbours a reference needs: the network's sources and the loss's views are the first of one
  // ranked list of neighbours.
  int neighbours_needed() const { return std::max(views_in - 1, views_loss); }
  // "the 4 neighbours<where> that --views-in 3 and --views-loss 4 need": what a skipped view lacks.
  std::string neighbours_needed_phrase(const std::string& where) const;
};

class TupleSource {
 public:
  virtual ~TupleSource() = default;
  virtual size_t size() const = 0;
  // The tuple at `index` (0 <= index < size()). With `rng` it is augmented (random crop and
  // jitter drawn from rng), without it resized and centre-cropped deterministically.
  virtual TrainingTuple tuple(size_t index, std::mt19937_64* rng) const = 0;
  virtual std::string description() const = 0;
};

// One tuple at the network size from full-size views (all of the reference's size): resized to
// cover config.width x height and centre-cropped, or, with `rng`, zoomed, cropped at a random
// offset and jittered (one draw for the whole tuple; intrinsics follow). `sources` are best first,
// at least max(views_in - 1, views_loss) of them; `depth_gt` [H,W] may be undefined.
TrainingTuple make_training_tuple(std::string name, const ViewInput& ref, const std::vector<ViewInput>& sources,
                                  double depth_min, double depth_max, const torch::Tensor& depth_gt,
                                  const TupleConfig& config, std::mt19937_64* rng);

// Tuples from MVSNet-format folders: every view with enough neighbours in pair.txt is a
// reference; its best views_in-1 neighbours feed the network, its best views_loss neighbours the
// loss. Ground truth comes from depth_gt/XXXXXXXX.pfm when present.
class MvsFolderSource : public TupleSource {
 public:
  // Throws std::runtime_error naming the folder when it is unreadable or has no usable reference.
  MvsFolderSource(const std::vector<std::string>& roots, TupleConfig config);
  size_t size() const override { return entries_.size(); }
  TrainingTuple tuple(size_t index, std::mt19937_64* rng) const override;
  std::string description() const override;
  bool has_ground_truth() const { return has_gt_; }

 private:
  struct Entry {
    size_t folder;
    int ref;
    std::vector<int> sources;  // best first, max(views_in - 1, views_loss) of them
  };
  std::vector<MvsFolder> folders_;
  std::vector<Entry> entries_;
  TupleConfig config_;
  int skipped_ = 0;
  bool has_gt_ = false;
};

// Tuples held in memory (e.g. pseudo-labelled ones), handed out as they are (no augmentation).
// replace() swaps the contents for as many new tuples, so samplers drawing from it stay valid.
class TupleList : public TupleSource {
 public:
  TupleList(std::vector<TrainingTuple> tuples, std::string what);
  size_t size() const override { return tuples_.size(); }
  TrainingTuple tuple(size_t index, std::mt19937_64* rng) const override;
  std::string description() const override;
  void replace(std::vector<TrainingTuple> tuples);  // throws std::invalid_argument on a size change

 private:
  std::vector<TrainingTuple> tuples_;
  std::string what_;
};

// Draws each tuple from `first` with probability first_share, else from `second` (each cycling
// through its own shuffled order): e.g. rendered scenes with ground truth mixed with real images
// in one optimisation. Its state is saved and restored like TupleSampler's.
class MixedSampler;

// Nearest-neighbour resampling of a depth map [H0,W0] with a NetworkResize plan  -> [h,w]
torch::Tensor apply_network_resize_nearest(const torch::Tensor& depth, const NetworkResize& plan);

// Cycles through a source in random order, reshuffling each epoch; its whole state (the source
// order, position and the augmentation RNG) is saved and restored for exact resume.
class TupleSampler {
 public:
  TupleSampler(const TupleSource& source, uint64_t seed);
  TrainingTuple next(bool augment = true);
  // Moves on as next() would, without reading the tuple (distributed ranks skip the others' share).
  void skip();
  std::string state() const;                 // text
  void set_state(const std::string& state);  // throws std::runtime_error when malformed

 private:
  size_t next_index();
  const TupleSource& source_;
  std::mt19937_64 rng_;
  std::vector<size_t> order_;
  size_t position_ = 0;
};

class MixedSampler {
 public:
  // second may be null: then every tuple comes from first.
  MixedSampler(const TupleSource& first, const TupleSource* second, double first_share, uint64_t seed);
  TrainingTuple next(bool augment = true);
  void skip();  // as next(), without reading the tuple
  std::string state() const;
  void set_state(const std::string& state);  // throws std::runtime_error when malformed

 private:
  TupleSampler first_;
  std::unique_ptr<TupleSampler> second_;
  double first_share_;
  std::mt19937_64 choice_rng_;
};

}  // namespace umvs
