// Converting real data sets into MVSNet-format folders (images/, cams/, pair.txt, depth_gt/) that
// `umvs infer`, `umvs fuse`, `umvs eval` and `umvs train` read.
//  * Middlebury multi-view (templeRing, dinoRing, ...): <name>_par.txt lines
//    "imgname.png k11..k33 r11..r33 t1 t2 t3" (K and world-to-camera R, t) and a bounding box
//    (README.txt of the data set or given). Depth ranges come from the box corners seen by each
//    camera, pair.txt from MVSNet's view-selection score on points sampled in the box.
//  * Posed RGB-D sequences (RgbdLayout), each frame a colour image, a 16-bit depth image (z-depth,
//    raw value / depth_scale metres; 0 and 65535 = no depth) and a camera-to-world pose:
//      slambook:    color/N.png, depth/N.png|.pgm|.tif (same stem), pose.txt line N =
//                   "tx ty tz qx qy qz qw" (slambook2, ICL-NUIM);
//      tum:         TUM RGB-D: rgb.txt and depth.txt ("timestamp path"), a pose file
//                   ("timestamp tx ty tz qx qy qz qw", groundtruth.txt by default), associated by
//                   nearest timestamp within a tolerance (or by row);
//      sevenscenes: frame-N.color.{png,jpg}, frame-N.depth.png, frame-N.pose.txt (4x4),
//                   camera-intrinsics.txt (7-Scenes as tsdf-fusion ships it);
//      dvmvs:       images/*.png, depth/ (same names), poses.txt (row k = flattened 4x4 of the
//                   k-th image in name order), K.txt (DeepVideoMVS).
//    Intrinsics are always explicit: given, or the data set's own intrinsics file. Distortion,
//    when given, is removed from colour (bilinear) and depth (nearest). Depth becomes
//    depth_gt/XXXXXXXX.pfm, which only evaluation reads.
// View ids are the numbers in the file names (templeR0013.png -> 13, color/4.png -> 4), or the
// row in rgb.txt (tum).
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

namespace umvs {

struct MiddleburyImportConfig {
  std::string data_dir;       // folder with the images and *_par.txt
  std::string out_dir;        // MVSNet-format folder to write
  std::string par_file;       // "" = the only *_par.txt in data_dir
  bool bbox_given = false;    // false: parse data_dir/README.txt ("(x y z)" twice)
  Eigen::Vector3d bbox_min = Eigen::Vector3d::Zero(), bbox_max = Eigen::Vector3d::Zero();
  double depth_margin = 0.1;  // depth range widened by this fraction of its length each side
  int depth_num = 192;        // DEPTH_NUM written to the cam files
  int num_sources = 10;       // neighbours per view in pair.txt
};

// Pinhole intrinsics with optional Brown-Conrady distortion (k1 k2 p1 p2 [k3], OpenCV's order).
struct CameraIntrinsics {
  Eigen::Matrix3d K = Eigen::Matrix3d::Zero();  // zero = not given
  std::vector<double> distortion;               // empty or all zero = none
  bool given() const { return K(2, 2) != 0.0; }
  bool distorted() const;
};
// Intrinsics from a text file: a 3x3 matrix (K.txt, camera-intrinsics.txt), one line
// "fx fy cx cy [k1 k2 p1 p2 [k3]]", or the YAML keys Camera.fx/fy/cx/cy[/k1/k2/p1/p2/k3] of
// ORB-SLAM's TUM1-3.yaml. Throws std::runtime_error naming the file and what is missing.
CameraIntrinsics read_intrinsics_file(const std::string& path);

enum class RgbdLayout { kSlambook, kTum, kSevenScenes, kDvmvs };
const char* to_string(RgbdLayout layout);

struct RgbdImportConfig {
  RgbdLayout layout = RgbdLayout::kSlambook;
  std::string data_dir;
  std::string out_dir;
  // Required for slambook and tum; sevenscenes and dvmvs read their own file when not given.
  CameraIntrinsics intrinsics;
  double depth_scale = 0.0;  // raw 16-bit value per metre; 0 = the layout's (5000 slambook/tum, 1000 the others)
  // tum: the pose file inside data_dir, how frames are associated ("timestamp": nearest within
  // tum_max_dt seconds, as TUM's associate.py; "index": row k of each list), the tolerance.
  std::string tum_pose_file = "groundtruth.txt";
  std::string tum_association = "timestamp";
  double tum_max_dt = 0.02;
  // Which frames (in the layout's order): from `first`, every `every`-th, at most `count` (0 = all).
  int first = 0, every = 1, count = 0;
  // A fixed depth range for every view (what a robot configures): then nothing but depth_gt/
  // comes from the sensor, and sources are ranked on the frustum at the range's middle, so the
  // folder can train a model without labels. 0 = each view's own range from its sensor depth
  // (min..max) and sources ranked on the sensor's surface, for scoring runs.
  double depth_near = 0.0, depth_far = 0.0;
  double depth_margin = 0.1;  // the range widened by this fraction of its length each side
  int depth_num = 192;
  int num_sources = 10;
  // Sources whose camera centre is this far from the reference's (metres) rank first; 0 = any.
  double min_baseline = 0.0, max_baseline = 0.0;
};

// One frame of a posed RGB-D sequence.
struct RgbdFrame {
  int id = 0;
  std::string color_path, depth_path;
  Eigen::Matrix4d T_world_cam = Eigen::Matrix4d::Identity();
};
// The frames that config.layout lists in config.data_dir, after first/every/count. Throws
// std::runtime_error naming the file and line for missing files, malformed lines, non-unit
// quaternions, frames without a depth image or a pose within the tolerance.
std::vector<RgbdFrame> list_rgbd_frames(const RgbdImportConfig& config);

struct ImportSummary {
  int views = 0;
  int skipped = 0;  // listed in the calibration but without an image
  double depth_min = 0.0, depth_max = 0.0;  // over all views
};

// Both throw std::runtime_error naming the file and the problem (missing file, malformed line,
// non-finite or invalid calibration, impossible depth range).
ImportSummary import_middlebury(const MiddleburyImportConfig& config);
ImportSummary import_rgbd(const RgbdImportConfig& config);

// "(-0.023121 -0.038009 -0.091940)" and "(0.078626 0.121636 -0.017395)" in a Middlebury README.
// Returns false when the text holds no two such triples.
bool parse_middlebury_bbox(const std::string& readme_text, Eigen::Vector3d* min, Eigen::Vector3d* max);

}  // namespace umvs
