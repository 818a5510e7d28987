// Depth-map fusion: many per-view depth maps become one consistent, coloured point cloud.
//
// A reference pixel with depth d is kept when enough other views agree with it (geometric
// consistency, as in MVSNet's and Fusibile's filters):
//   1. lift the pixel with d into 3D and project it into a source view: pixel (u_s, v_s);
//   2. read the source depth there (bilinear; every contributing source pixel must be a valid
//      estimate), lift that source pixel into 3D and project it back into the reference:
//      pixel (u', v') with depth d';
//   3. the source agrees when |(u', v') - (u, v)| < max_reprojection_px and
//      |d' - d| / d < max_relative_depth.
// A pixel is a valid estimate when its depth is finite and > 0 and its confidence is
// >= min_confidence (in both the reference and the sources). A pixel with at least
// min_agreeing_views agreeing sources becomes a point at the mean of d and the agreeing d',
// coloured by the reference, carrying the reference confidence and the number of agreeing
// sources (PointCloud::num_views).
//
// On the CPU the consistency test is one multi-threaded loop over the reference pixels; on
// other devices (CUDA) it is batched tensor code (check_consistency_tensor_ops). The resulting
// cloud is on the CPU.
//
// FusionSourceRule::kMvsnetEval replaces step 2's rule by MVSNet's eval.py
// (check_geometric_consistency): the source depth is read from the raw source depth map,
// confident or not, as cv2.remap does (bilinear, coordinates rounded to 1/32 pixel, 0 outside
// the image), and reference pixels need confidence > min_confidence (strictly). With it, the
// fused cloud of MVSNet depth maps is eval.py's point for point.
#pragma once

#include <torch/types.h>

#include <cstdint>
#include <deque>
#include <memory>
#include <string>
#include <unordered_set>
#include <vector>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/point_cloud.h"

namespace umvs {

// Which source pixels may confirm a reference pixel (see the top of this file).
enum class FusionSourceRule {
  kConfidentNeighbours,  // the four source pixels around the projection are all estimates
  kMvsnetEval,           // MVSNet's eval.py: the raw source depth, zero outside the image
};
const char* to_string(FusionSourceRule rule);
FusionSourceRule fusion_source_rule_from_string(const std::string& s);  // "neighbours" | "mvsnet"

struct FusionConfig {
  double min_confidence = 0.8;      // pixels below this confidence are no estimate (0 = keep all)
  double max_reprojection_px = 1.0; // reference-pixel distance after the round trip, pixels
  double max_relative_depth = 0.01; // |d' - d| / d
  int min_agreeing_views = 3;       // sources (other than the reference) that must agree
  int max_source_views = 10;        // batch: sources tested per reference, best first
  double voxel_size = 0.0;          // > 0: at most one point per voxel of this edge (metres),
                                    // the first one fused wins; 0 = off (one point per pixel)
  FusionSourceRule source_rule = FusionSourceRule::kConfidentNeighbours;
  // Free-space clearing (StreamingFusion only; see there): a point leaves the cloud once this
  // many estimates in a row have seen through it; 0 = points stay forever.
  // The defaults keep every real set's cloud as good as without clearing (docs/results.md).
  int clear_after_views = 5;
  double clear_margin = 0.2;  // "seen through": farther than (1 + clear_margin) x the point's depth

  // Throws std::invalid_argument naming the offending field.
  void validate() const;
};

// One depth estimate (a network output or a ground-truth depth map).
struct FusionView {
  int64_t id = 0;
  torch::Tensor depth;       // [H,W] float32, metres (z in the camera); <= 0 or non-finite = no estimate
  torch::Tensor confidence;  // [H,W] float32 in [0,1]; undefined = 1 everywhere (ground truth)
  torch::Tensor color;       // [H,W,3] uint8 RGB at the depth pixels; undefined = grey
  Camera camera;             // camera of the depth map (width/height = W,H)
};

// Per reference view figures of a batch fusion (for progress output and benchmarks).
struct FusionViewStats {
  int64_t id = 0;
  int num_sources = 0;       // sources tested
  int64_t valid_pixels = 0;  // pixels that are an estimate (depth and confidence)
  int64_t points = 0;        // points this view added to the cloud
  double seconds = 0.0;      // all of this view's work, the stages below included
  double ranking_seconds = 0.0;      // ranking the sources (only without a source list)
  double consistency_seconds = 0.0;  // the consistency tests against all sources
  double points_seconds = 0.0;       // making the points (and the voxel filter)
};

// Batch fusion: every view is a reference once, tested against its sources.
class DepthFusion {
 public:
  DepthFusion(FusionConfig config, torch::Device device);

  // sources[i]: indices into `views` of the sources of view i, best first (e.g. from pair.txt);
  // at most config.max_source_views are used. Empty (or an empty entry) = ranked by MVSNet's
  // view-selection score on points of view i's own depth map. `stats` (optional) receives one
  // entry per view. Throws std::invalid_argument naming the view for inconsistent shapes,
  // cameras or source indices.
  PointCloud fuse(const std::vector<FusionView>& views, const std::vector<std::vector<int>>& sources = {},
                  std::vector<FusionViewStats>* stats = nullptr);

  // The same test without making points: per view, the pixels fuse() would keep (valid and
  // confirmed by min_agreeing_views sources) and their fused depth (the mean of the view's and
  // the agreeing depths). Self-training learns from these pixels; adaptation is judged by their
  // share. Same arguments and errors as fuse(); results on the CPU, in the order of `views`.
  struct Agreement {
    torch::Tensor confirmed;  // [H,W] bool
    torch::Tensor depth;      // [H,W] float32, 0 where not confirmed
  };
  std::vector<Agreement> agreement(const std::vector<FusionView>& views,
                                   const std::vector<std::vector<int>>& sources = {});

  const FusionConfig& config() const { return config_; }

 private:
  FusionConfig config_;
  torch::Device device_;
};

// Online fusion for a stream of depth estimates. Keeps a ring of the last `window` estimates.
// When a view is added it is tested against every stored estimate AND every stored estimate is
// tested against it, so a pixel is emitted as soon as it has min_agreeing_views agreeing views
// among the estimates it has met, whether it belongs to the new view or to an older one still in
// the ring. Each pixel is emitted at most once. With a window holding all views, voxel_size = 0
// and max_source_views >= views - 1, the emitted pixels are exactly those DepthFusion::fuse keeps
// when every view's sources are all the others (positions may differ slightly: a point averages
// the agreeing depths known when it is emitted). max_source_views is not used here: the window
// bounds the work instead (each estimate meets at most 2 * window others).
// Memory is bounded: `window` estimates on the device and at most `max_points` points (the
// oldest are dropped first); with voxel_size > 0 a voxel hash keeps overlapping views from
// piling up duplicates.
// A map that forgets what moved: each new estimate is also free-space evidence. A cloud point is
// seen through when every pixel of the 3x3 around its projection is a valid estimate (confidence
// >= min_confidence) farther than (1 + clear_margin) x the point's depth, and seen again when the
// pixel it projects to holds its depth within that margin. A point seen through by
// clear_after_views estimates with none seeing it again in between is removed: an object that
// left is forgotten after a few looks, while a wall survives a confidently wrong estimate or
// noise, which rarely shows through it in a neighbourhood and several estimates in a row. Pixels
// that are no estimate, and points hidden behind something nearer, count neither way.
class StreamingFusion {
 public:
  StreamingFusion(FusionConfig config, int window, size_t max_points, torch::Device device);
  ~StreamingFusion();

  // The points this estimate creates: its own pixels now confirmed and the pixels of stored
  // estimates that it confirms (already appended to cloud()). Throws std::invalid_argument
  // naming the view for bad shapes or cameras; the state is unchanged then.
  PointCloud add(const FusionView& view);
  const PointCloud& cloud() const { return cloud_; }  // everything so far (bounded)
  void reset();                                       // forget the estimates and the cloud
  size_t num_views() const;                           // estimates currently in the ring
  int window() const { return window_; }
  int64_t points_cleared() const { return points_cleared_; }  // removed as free space since reset
  const FusionConfig& config() const { return config_; }
  // New thresholds for the estimates added from now on (live tuning). Throws
  // std::invalid_argument naming the field, keeping the old ones. Stored estimates keep the
  // confident pixels they were added with; a new voxel_size applies to the whole cloud from now on.
  void set_config(const FusionConfig& config);

 private:
  struct Entry;
  void append_points(PointCloud& points);
  void clear_free_space(const torch::Tensor& depth, const torch::Tensor& valid, const Camera& camera);
  void rebuild_voxel_index();  // voxels_ from cloud_ at config_.voxel_size
  FusionConfig config_;
  int window_;
  size_t max_points_;
  torch::Device device_;
  std::deque<std::unique_ptr<Entry>> ring_;
  PointCloud cloud_;
  std::vector<uint8_t> seen_through_;  // per point of cloud_: estimates in a row that saw through it
  int64_t points_cleared_ = 0;
  std::unordered_set<int64_t> voxels_;
};

// What one depth map says about a point (the rule in StreamingFusion's comment).
enum class FreeSpaceEvidence : uint8_t { kNone, kSeenThrough, kSeenAgain };
// depth [H,W] float32 and valid [H,W] bool on the CPU, of `camera`. -> one entry per cloud point.
std::vector<FreeSpaceEvidence> free_space_evidence(const PointCloud& cloud, const torch::Tensor& depth,
                                                   const torch::Tensor& valid, const Camera& camera, double margin);

// --- building blocks (exposed for tests and benchmarks) ------------------------------------

// Valid-estimate mask of a view: finite depth > 0 and confidence >= min_confidence.  -> [H,W] bool
torch::Tensor valid_estimate_mask(const torch::Tensor& depth, const torch::Tensor& confidence,
                                  double min_confidence);

// Geometric consistency of a reference depth map with one source.
//   ref_depth [H,W] (invalid pixels may hold anything), ref_valid [H,W] bool,
//   src_depth [Hs,Ws], src_valid [Hs,Ws] bool, all on one device. With kMvsnetEval, src_depth
//   is read as it is (0 or non-finite = no depth) and src_valid is not used.
//   -> agree [H,W] bool, depth [H,W] float32: the source's depth seen from the reference (d'),
//      meaningful where agree is true.
// On the CPU a per-pixel loop (float32 geometry; float64 with kMvsnetEval, as eval.py's NumPy),
// elsewhere check_consistency_tensor_ops; the two agree up to rounding on borderline pixels (tested).
struct ConsistencyCheck {
  torch::Tensor agree;
  torch::Tensor depth;
};
ConsistencyCheck check_consistency(const torch::Tensor& ref_depth, const torch::Tensor& ref_valid,
                                   const Camera& ref_camera, const torch::Tensor& src_depth,
                                   const torch::Tensor& src_valid, const Camera& src_camera,
                                   const FusionConfig& config);
ConsistencyCheck check_consistency_tensor_ops(const torch::Tensor& ref_depth, const torch::Tensor& ref_valid,
                                              const Camera& ref_camera, const torch::Tensor& src_depth,
                                              const torch::Tensor& src_valid, const Camera& src_camera,
                                              const FusionConfig& config);

}  // namespace umvs
