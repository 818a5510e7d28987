// One depth map from a reference view and its source views: resizes/crops the images to the
// network size (intrinsics kept consistent), builds the projection matrices and the depth
// hypotheses, runs MVSNet's inference path (FastMvsNet) without gradients. Shared by
// `umvs infer` and the inference nodelet.
#pragma once

#include <torch/types.h>

#include <functional>
#include <string>
#include <vector>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/depth_completion.h"
#include "unsup_mvs/core/fast_mvsnet.h"
#include "unsup_mvs/core/mvsnet.h"

namespace umvs {

struct ViewInput {
  torch::Tensor image;  // uint8 [H,W,3] RGB
  Camera camera;        // width/height must match the image
};

// How the source views make one depth map.
//  kVariance: one pass over all views, MVSNet's variance cost volume.
//  kMostConfident: that pass, plus one pass per source with the reference alone; each pixel keeps
//    the estimate of highest confidence. A source that sees another part of the scene, or sees
//    it from too far off, then cannot spoil the variance for the other sources at the pixels
//    where it is wrong. One pass more per source (3 instead of 1 for 2 sources).
//  kAuto: the variance pass; when it is unsure of most of the map (fewer than
//    kAutoMinConfidentShare of its pixels at kAutoConfidentLevel or more), also the per-source
//    passes of kMostConfident. Far-apart keyframes, whose sources disagree, get the extra passes;
//    well-overlapping ones keep the one pass and its depth. Measured in docs/results.md:
//    on the living room the variance pass is confident on
//    5-13 % of each map, on templeRing on 36-51 %, on rendered scenes on 69-98 %.
enum class SourceCombination { kVariance, kMostConfident, kAuto };
const char* to_string(SourceCombination c);
SourceCombination source_combination_from_string(const std::string& s);  // "variance" | "most_confident" | "auto"
constexpr double kAutoConfidentLevel = 0.5;
constexpr double kAutoMinConfidentShare = 0.2;
// What `umvs infer` and the inference nodelet use (DepthEstimatorConfig keeps MVSNet's variance, so
// that training, the reload judge and parity see the one pass unless told otherwise).
constexpr SourceCombination kRecommendedSourceCombination = SourceCombination::kAuto;

struct DepthEstimatorConfig {
  int max_width = 0;   // 0 = no limit; images are scaled down to fit, then cropped to multiples of 32
  int max_height = 0;
  int num_depth = 0;   // 0 = the model's config
  SourceCombination source_combination = SourceCombination::kVariance;
  // Label-free correction of the sources' orientation, in degrees about each axis (0 = off).
  // Poses from odometry or SLAM are often a few tenths of a degree off between keyframes, several
  // pixels at 640 wide, and the cost volume then compares pixels that do not correspond. Before
  // the final pass each source camera is turned about its own centre by the small rotation with
  // which the pass of the reference and that source alone warps the source best onto the
  // reference (SSIM over the reference's textured windows; search_rotation), on images of half the
  // network's size with half the planes, when that is clearly better than the pose as given there
  // and again at full size. About 30 of those passes per source. Off by default: it costs 6-14
  // times the time of a map, and it corrects each source for one reference only, not the poses
  // fusion uses.
  double source_rotation_search_deg = 0.0;
  // Completion of the pixels below a confidence floor from the confident ones (core/depth_completion.h;
  // off by default). The confidence map is left as the network gave it.
  DepthCompletionConfig completion = {};
  // "Unknown" where the views cannot tell depth: a pixel whose projection moves by less than this
  // many pixels (of the network input) in every source when its depth changes by
  // kParallaxDepthChange gets confidence 0. A camera turning in place, or a baseline too short
  // for the depth, gives the cost volume nothing to match, and the network's guess there can be
  // confidently wrong. 0 = off (the default everywhere: at 1 px the confident pixels left on short
  // real clips were still mostly wrong; docs/results.md). Applied before completion, which then
  // fills such pixels.
  double min_parallax_px = 0.0;
  // A second pass around the first one's depth (FastMvsNet::forward_coarse_to_fine; off by
  // default): with it num_depth is the first pass's planes, and the map has the fine pass's
  // resolution (1/2 or 1/4 of the network input).
  FinePassConfig fine = {};

  void validate() const;  // throws std::invalid_argument naming the field
};

// A side (width or height) of the first pass's input for a network input side `network_side`
// (half of it with a fine pass whose first pass runs at half size): what a default plane count follows.
int first_pass_size(const DepthEstimatorConfig& config, int network_side);

// The relative depth change by which min_parallax_px is judged.
constexpr double kParallaxDepthChange = 0.1;

// Per pixel of a depth map, the largest shift over the sources (in pixels of each source camera)
// of the pixel's projection when its depth d becomes d * (1 + relative_change).
//   depth [h,w] metres (<= 0: shift 0), depth_camera of that size, sources: cameras of any size.
//   -> [h,w] float32
torch::Tensor parallax_shift_px(const torch::Tensor& depth, const Camera& depth_camera, const std::vector<Camera>& sources,
                                double relative_change = kParallaxDepthChange);

// Coordinate search for the rotation (degrees about x, y, z) that maximises `score`: from zero,
// steps of 0.4, 0.2 and 0.1 degrees along each axis while the score rises, each angle within
// +-limit_deg.
struct RotationSearch {
  Eigen::Vector3d degrees;   // the best rotation found
  double score = 0.0;        // its score
  double start_score = 0.0;  // the score of no rotation
  int evaluations = 0;       // calls of `score`
};
RotationSearch search_rotation(const std::function<double(const Eigen::Vector3d& degrees)>& score, double limit_deg);

// The relative drop of a source's warp loss a turn must bring, in the search and at full size.
constexpr double kMinSourceTurnGain = 0.05;

// A source view's turn by the rotation search (DepthEstimatorConfig::source_rotation_search_deg).
struct SourceTurn {
  Eigen::Vector3d degrees = Eigen::Vector3d::Zero();  // the best turn found, about the source's x, y, z
  double search_gain = 0.0;  // how much the best turn found lowered the warp's SSIM loss (fraction)
  double full_size_gain = 0.0;  // the same at the network's full size (0 when the search gain was too small)
  bool kept = false;  // whether the source was turned: both gains at least kMinSourceTurnGain
};

struct DepthMap {
  torch::Tensor depth;       // [h,w] float32 metres, CPU (h, w = network input / 4, or / 2 with a fine pass at 1/2)
  torch::Tensor confidence;  // [h,w] float32 in [0,1], CPU
  torch::Tensor color;       // [h,w,3] uint8: the reference image at the depth pixels
  Camera camera;             // camera of the depth map: pixel (i,j) <-> network input pixel (4i,4j) (or (2i,2j))
  Camera network_camera;     // camera of the network input image (after resize and crop)
  double depth_min = 0.0, depth_max = 0.0;
  double seconds = 0.0;      // network time, including transfers (all passes)
  double completion_seconds = 0.0;   // DepthEstimatorConfig::completion's time (0 when off)
  DepthCompletionStats completion;   // what it did (zeros when off)
  MvsStageTimes stages;      // where the first pass's network time went (CPU fast path only)
  // [h,w] bool: pixels set to confidence 0 by min_parallax_px (undefined when it is off).
  torch::Tensor unresolvable;
  bool per_source_passes = false;  // whether the passes of each source alone ran (most_confident, or auto on an unsure map)
  // Per source view, what DepthEstimatorConfig::source_rotation_search_deg did (empty when off).
  std::vector<SourceTurn> source_turns;
};

class DepthEstimator {
 public:
  DepthEstimator(MvsNet model, torch::Device device, DepthEstimatorConfig config = {});

  // views[0] is the reference. Throws std::invalid_argument naming the problem for an impossible
  // depth range, invalid cameras, mismatched image sizes or fewer than 2 views.
  DepthMap estimate(const std::vector<ViewInput>& views, double depth_min, double depth_max);

  // The model's weights are folded when the estimator is built: build a new estimator after
  // changing them.
  MvsNet& model() { return network_.model(); }
  const torch::Device& device() const { return device_; }
  const DepthEstimatorConfig& config() const { return config_; }
  int num_depth() const;

  // The rotation, within +-limit_deg about each axis, with which the pass of the reference and the
  // source alone warps the source best onto the reference (images as loaded); kept when clearly
  // better (SourceTurn::kept). What source_rotation_search_deg runs per source, and what
  // `umvs refine-poses` measures per pair (core/pose_refinement.h). Throws std::invalid_argument as
  // estimate() does for the views, and for a limit that is not > 0.
  SourceTurn best_source_turn(const ViewInput& reference, const ViewInput& source, double depth_min, double depth_max,
                              double limit_deg);

 private:
  // The SSIM loss, over the reference's textured windows, of the source warped by the pair pass's
  // depth after the source is turned by the given rotation (degrees), at the given size and planes.
  std::function<double(const Eigen::Vector3d&)> source_warp_loss(const ViewInput& reference, const ViewInput& source,
                                                                 const NetworkResize& plan, int planes,
                                                                 double depth_min, double depth_max);

  torch::Device device_;
  FastMvsNet network_;
  DepthEstimatorConfig config_;
};

// The depth-map camera for MVSNet's 1/4-resolution output (naive scaling, as the network's warp).
Camera depth_map_camera(const Camera& network_camera, double scale = 0.25);

}  // namespace umvs
