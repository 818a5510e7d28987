#include "unsup_mvs/io/training_data.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/io/array_io.h"

namespace umvs {

void TupleConfig::validate() const {
  auto bad = [](const std::string& what) { throw std::invalid_argument(what); };
  if (views_in < 2) bad("--views-in must be at least 2 (reference + 1), got " + std::to_string(views_in));
  if (views_loss < 1) bad("--views-loss must be at least 1, got " + std::to_string(views_loss));
  if (width < 0 || height < 0 || width % 32 != 0 || height % 32 != 0) {
    bad("--width/--height must be multiples of 32 (0 = from the images), got " + std::to_string(width) + "x" +
        std::to_string(height));
  }
  if (!(min_zoom >= 1.0) || !(max_zoom >= min_zoom) || !std::isfinite(max_zoom)) {
    bad("the crop's zoom must satisfy 1 <= --min-zoom <= --max-zoom, got [" + std::to_string(min_zoom) + ", " +
        std::to_string(max_zoom) + "]");
  }
  if (!(jitter >= 0.0 && jitter < 1.0)) bad("jitter must be in [0, 1)");
  if (supervised && !read_ground_truth) bad("supervised training reads ground truth: read_ground_truth must be on");
  if (!(min_gain > 0.0) || !(max_gain >= min_gain) || !std::isfinite(max_gain)) {
    bad("exposure gains must satisfy 0 < min_gain <= max_gain, got [" + std::to_string(min_gain) + ", " +
        std::to_string(max_gain) + "]");
  }
}

std::string TupleConfig::neighbours_needed_phrase(const std::string& where) const {
  return "the " + std::to_string(neighbours_needed()) + " neighbours" + where + " that --views-in " +
         std::to_string(views_in) + " and --views-loss " + std::to_string(views_loss) + " need";
}

namespace {

double uniform(std::mt19937_64& rng, double lo, double hi) {
  // Explicit mapping (not std::uniform_real_distribution) so the sequence is the same everywhere.
  return lo + (hi - lo) * static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0);
}

// Scale so the image covers width x height (times zoom), then crop at (fx, fy) in [0,1] of the slack.
NetworkResize cover_and_crop(int W0, int H0, int width, int height, double zoom, double fx, double fy) {
  NetworkResize p;
  const double s = std::max(static_cast<double>(width) / W0, static_cast<double>(height) / H0) * zoom;
  p.scaled_width = std::max(width, static_cast<int>(std::lround(W0 * s)));
  p.scaled_height = std::max(height, static_cast<int>(std::lround(H0 * s)));
  p.width = width;
  p.height = height;
  p.crop_x = static_cast<int>(std::floor(fx * (p.scaled_width - width) + 0.5));
  p.crop_y = static_cast<int>(std::floor(fy * (p.scaled_height - height) + 0.5));
  return p;
}

}  // namespace

torch::Tensor apply_network_resize_nearest(const torch::Tensor& depth, const NetworkResize& plan) {
  const int64_t H0 = depth.size(0), W0 = depth.size(1);
  auto index = [](int64_t n, int scaled, int n0, int crop) {
    auto i = torch::arange(n, torch::kFloat64) + crop;
    return ((i + 0.5) * (static_cast<double>(n0) / scaled) - 0.5).round().clamp(0, n0 - 1).to(torch::kLong);
  };
  auto rows = index(plan.height, plan.scaled_height, H0, plan.crop_y);
  auto cols = index(plan.width, plan.scaled_width, W0, plan.crop_x);
  return depth.index_select(0, rows).index_select(1, cols).contiguous();
}

MvsFolderSource::MvsFolderSource(const std::vector<std::string>& roots, TupleConfig config)
    : config_(std::move(config)) {
  config_.validate();
  if (roots.empty()) throw std::invalid_argument("no training data folder given");
  const int needed = config_.neighbours_needed();
  for (const auto& root : roots) {
    folders_.emplace_back(root);
    size_t usable = 0;
    for (const auto& p : folders_.back().pairs()) {
      if (static_cast<int>(p.sources.size()) < needed) {
        ++skipped_;
        continue;
      }
      const bool ref_has_gt = config_.read_ground_truth && !folders_.back().depth_gt_path(p.ref).empty();
      if (config_.supervised && !ref_has_gt) {
        throw std::runtime_error(root + ": view " + std::to_string(p.ref) +
                                 " has no depth_gt/ map, and supervised training needs one for every reference");
      }
      entries_.push_back({folders_.size() - 1, p.ref, std::vector<int>(p.sources.begin(), p.sources.begin() + needed)});
      if (ref_has_gt) has_gt_ = true;
      ++usable;
    }
    if (usable == 0) {
      throw std::runtime_error(root + ": no view has " + config_.neighbours_needed_phrase(" in pair.txt"));
    }
  }
}

std::string MvsFolderSource::description() const {
  std::ostringstream s;
  s << entries_.size() << " tuples from " << folders_.size() << " folder(s)";
  if (skipped_ > 0) {
    // Named with what they lack: a --views-loss one too high silently drops most of a small folder.
    s << " (" << skipped_ << " views skipped: fewer than " << config_.neighbours_needed_phrase(" in pair.txt") << ")";
  }
  s << (config_.supervised ? ", supervised on ground-truth depth"
                           : has_gt_ ? ", with ground-truth depth (for scoring only)" : ", no ground truth");
  return s.str();
}

TrainingTuple make_training_tuple(std::string name, const ViewInput& ref, const std::vector<ViewInput>& sources,
                                  double depth_min, double depth_max, const torch::Tensor& depth_gt,
                                  const TupleConfig& config, std::mt19937_64* rng) {
  const size_t needed = static_cast<size_t>(config.neighbours_needed());
  if (sources.size() < needed) {
    throw std::invalid_argument(name + ": " + std::to_string(sources.size()) + " source views, " +
                                std::to_string(needed) + " needed");
  }
  const int W0 = ref.camera.width, H0 = ref.camera.height;
  int width = config.width, height = config.height;
  if (width == 0 || height == 0) {
    const auto p = plan_network_resize(W0, H0, 0, 0);
    width = p.width;
    height = p.height;
  }
  const double zoom = rng ? uniform(*rng, config.min_zoom, config.max_zoom) : 1.0;
  const double fx = rng ? uniform(*rng, 0.0, 1.0) : 0.5, fy = rng ? uniform(*rng, 0.0, 1.0) : 0.5;
  const NetworkResize plan = cover_and_crop(W0, H0, width, height, zoom, fx, fy);
  // One photometric change for the whole tuple: contrast, brightness, per-channel gain.
  torch::Tensor gain;
  double contrast = 1.0, brightness = 0.0;
  if (rng && config.jitter > 0) {
    const double j = config.jitter;
    contrast = uniform(*rng, 1 - j, 1 + j);
    brightness = uniform(*rng, -j / 2, j / 2);
    gain = torch::tensor({uniform(*rng, 1 - j, 1 + j), uniform(*rng, 1 - j, 1 + j), uniform(*rng, 1 - j, 1 + j)},
                         torch::kFloat32).view({3, 1, 1});
  }
  double exposure = 1.0;
  if (rng && (config.min_gain != 1.0 || config.max_gain != 1.0)) {
    exposure = std::exp(uniform(*rng, std::log(config.min_gain), std::log(config.max_gain)));
  }
  auto make_view = [&](const ViewInput& v) {
    if (v.camera.width != W0 || v.camera.height != H0) {
      throw std::runtime_error(name + ": a source image's size differs from the reference's");
    }
    auto img = apply_network_resize(rgb8_to_float(v.image), plan);
    if (gain.defined()) img = (((img - 0.5) * contrast + 0.5 + brightness) * gain).clamp(0, 1);
    if (exposure != 1.0) img = (img * exposure).clamp(0, 1);
    return ViewInput{float_to_rgb8(img), apply_network_resize(v.camera, plan)};
  };

  TrainingTuple t;
  t.name = std::move(name);
  t.network_views.push_back(make_view(ref));
  std::vector<ViewInput> resized;
  for (size_t i = 0; i < needed; ++i) resized.push_back(make_view(sources[i]));
  t.network_views.insert(t.network_views.end(), resized.begin(), resized.begin() + (config.views_in - 1));
  t.loss_views.assign(resized.begin(), resized.begin() + config.views_loss);
  t.depth_min = depth_min;
  t.depth_max = depth_max;
  if (depth_gt.defined()) {
    if (depth_gt.dim() != 2 || depth_gt.size(0) != H0 || depth_gt.size(1) != W0) {
      throw std::runtime_error(t.name + ": ground-truth depth size differs from the image's");
    }
    t.depth_gt = apply_network_resize_nearest(depth_gt, plan);
  }
  t.supervised = config.supervised;
  t.validate();
  return t;
}

TrainingTuple MvsFolderSource::tuple(size_t index, std::mt19937_64* rng) const {
  if (index >= entries_.size()) throw std::out_of_range("tuple index " + std::to_string(index) + " out of range");
  const Entry& e = entries_[index];
  const MvsFolder& folder = folders_[e.folder];
  const MvsView ref = folder.load_view(e.ref);
  std::vector<ViewInput> sources;
  for (int id : e.sources) {
    const MvsView v = folder.load_view(id);
    sources.push_back({v.image, v.cam.camera});
  }
  torch::Tensor gt;
  const std::string gt_path = config_.read_ground_truth ? folder.depth_gt_path(e.ref) : std::string();
  if (!gt_path.empty()) gt = read_pfm(gt_path);
  return make_training_tuple(folder.root() + " view " + std::to_string(e.ref), {ref.image, ref.cam.camera}, sources,
                             ref.cam.depth_min, ref.cam.resolved_depth_max(config_.num_depth), gt, config_, rng);
}

TupleSampler::TupleSampler(const TupleSource& source, uint64_t seed) : source_(source), rng_(seed) {
  if (source.size() == 0) throw std::invalid_argument("empty training source");
}

size_t TupleSampler::next_index() {
  if (position_ >= order_.size()) {
    order_.resize(source_.size());
    std::iota(order_.begin(), order_.end(), size_t{0});
    for (size_t i = order_.size(); i > 1; --i) std::swap(order_[i - 1], order_[rng_() % i]);  // Fisher-Yates
    position_ = 0;
  }
  return order_[position_++];
}

// Each tuple's augmentation draws from a generator seeded by one draw of rng_: a skipped tuple
// moves the sampler exactly as a read one, whatever the augmentation consumes.
TrainingTuple TupleSampler::next(bool augment) {
  const size_t index = next_index();
  std::mt19937_64 augmentation(rng_());
  return source_.tuple(index, augment ? &augmentation : nullptr);
}

void TupleSampler::skip() {
  next_index();
  rng_();
}

std::string TupleSampler::state() const {
  std::ostringstream s;
  s << rng_ << "\n" << position_ << " " << order_.size();
  for (size_t i : order_) s << " " << i;
  return s.str();
}

TupleList::TupleList(std::vector<TrainingTuple> tuples, std::string what)
    : tuples_(std::move(tuples)), what_(std::move(what)) {}

TrainingTuple TupleList::tuple(size_t index, std::mt19937_64*) const {
  if (index >= tuples_.size()) throw std::out_of_range("tuple index " + std::to_string(index) + " out of range");
  return tuples_[index];
}

std::string TupleList::description() const { return std::to_string(tuples_.size()) + " " + what_; }

void TupleList::replace(std::vector<TrainingTuple> tuples) {
  if (tuples.size() != tuples_.size()) {
    throw std::invalid_argument("TupleList::replace: " + std::to_string(tuples.size()) + " tuples for " +
                                std::to_string(tuples_.size()));
  }
  tuples_ = std::move(tuples);
}

MixedSampler::MixedSampler(const TupleSource& first, const TupleSource* second, double first_share, uint64_t seed)
    : first_(first, seed), first_share_(first_share), choice_rng_(seed ^ 0x9e3779b97f4a7c15ULL) {
  if (second != nullptr) {
    if (!(first_share >= 0.0 && first_share <= 1.0)) {
      throw std::invalid_argument("the share of tuples from the first source must be in [0, 1], got " +
                                  std::to_string(first_share));
    }
    second_ = std::make_unique<TupleSampler>(*second, seed + 1);
  }
}

TrainingTuple MixedSampler::next(bool augment) {
  if (!second_) return first_.next(augment);
  return uniform(choice_rng_, 0.0, 1.0) < first_share_ ? first_.next(augment) : second_->next(augment);
}

// Sections separated by a line "--": the choice RNG, the first sampler, the second (if any). The
// single-source state is the first sampler's alone, as before mixing existed.
void MixedSampler::skip() {
  if (!second_) return first_.skip();
  if (uniform(choice_rng_, 0.0, 1.0) < first_share_) first_.skip();
  else second_->skip();
}

std::string MixedSampler::state() const {
  if (!second_) return first_.state();
  std::ostringstream s;
  s << choice_rng_ << "\n--\n" << first_.state() << "\n--\n" << second_->state();
  return s.str();
}

void MixedSampler::set_state(const std::string& state) {
  if (!second_) return first_.set_state(state);
  const auto a = state.find("\n--\n");
  const auto b = a == std::string::npos ? a : state.find("\n--\n", a + 4);
  if (b == std::string::npos) throw std::runtime_error("mixed training sampler state is malformed or from another run");
  std::istringstream choice(state.substr(0, a));
  std::mt19937_64 rng;
  choice >> rng;
  if (!choice) throw std::runtime_error("mixed training sampler state is malformed");
  first_.set_state(state.substr(a + 4, b - a - 4));
  second_->set_state(state.substr(b + 4));
  choice_rng_ = rng;
}

void TupleSampler::set_state(const std::string& state) {
  std::istringstream s(state);
  std::mt19937_64 rng;
  size_t position = 0, n = 0;
  s >> rng >> position >> n;
  std::vector<size_t> order(n);
  for (auto& i : order) s >> i;
  if (!s || position > n || std::any_of(order.begin(), order.end(), [&](size_t i) { return i >= source_.size(); })) {
    throw std::runtime_error("training sampler state is malformed or belongs to other data");
  }
  rng_ = rng;
  position_ = position;
  order_ = std::move(order);
}

}  // namespace umvs
