// Converting real data sets into MVSNet-format folders (images/, cams/, pair.txt, depth_gt/) that
// `umvs infer`, `umvs fuse` and `umvs eval` read.
//  * Middlebury multi-view (templeRing, dinoRing, ...): <name>_par.txt lines
//    "imgname.png k11..k33 r11..r33 t1 t2 t3" (K and world-to-camera R, t) and a bounding box
//    (README.txt of the data set or given). Depth ranges come from the box corners seen by each
//    camera, pair.txt from MVSNet's view-selection score on points sampled in the box.
//  * RGB-D sequences in the TUM/ICL-NUIM layout used by slambook2: color/N.png, depth/N.png
//    (or .pgm/.tif with the colour image's stem; 16-bit, value / depth_scale metres, z-depth,
//    0 = no depth), pose.txt line N = "tx ty tz qx qy qz qw" camera-to-world. Depth becomes
//    depth_gt/XXXXXXXX.pfm.
// View ids are the numbers in the file names (templeR0013.png -> 13, color/4.png -> 4).
#pragma once

#include <Eigen/Core>
#include <string>

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

struct RgbdImportConfig {
  std::string data_dir;       // color/, depth/, pose.txt
  std::string out_dir;
  double fx = 481.2, fy = -480.0, cx = 319.5, cy = 239.5;  // ICL-NUIM (fy < 0: image y flipped)
  double depth_scale = 5000.0;  // raw 16-bit value / depth_scale = metres
  double depth_margin = 0.1;    // per-view range [min, max] of the GT depth, widened by this fraction
  int depth_num = 192;
  int num_sources = 10;
};

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
