// MVSNet-format scene folders:
//   images/XXXXXXXX.{jpg,png}   cams/XXXXXXXX_cam.txt   pair.txt   [depth_gt/XXXXXXXX.pfm]
// A cam file holds "extrinsic" (4x4 world-to-camera), "intrinsic" (3x3) and one line
// "DEPTH_MIN DEPTH_INTERVAL [DEPTH_NUM [DEPTH_MAX]]".
#pragma once

#include <torch/types.h>

#include <string>
#include <vector>

#include "unsup_mvs/core/camera.h"

namespace umvs {

struct MvsCam {
  Camera camera;  // width/height are 0 in the file; MvsFolder::load_view fills them in
  double depth_min = 0.0;
  double depth_interval = 0.0;
  int depth_num = 0;       // 0 = not given
  double depth_max = 0.0;  // 0 = not given

  // The far end of the range: DEPTH_MAX if given, else DEPTH_MIN + DEPTH_INTERVAL * (n - 1) with
  // n = DEPTH_NUM if given, else `default_num` (MVSNet's convention).
  double resolved_depth_max(int default_num) const;
};

// Throws std::runtime_error naming the file and what is wrong with it (missing section,
// non-numeric entry, NaN, invalid rotation, impossible depth range).
MvsCam read_cam_file(const std::string& path);
void write_cam_file(const std::string& path, const MvsCam& cam);

struct ViewPair {
  int ref = 0;
  std::vector<int> sources;     // best first
  std::vector<double> scores;   // one per source
};
std::vector<ViewPair> read_pair_file(const std::string& path);
void write_pair_file(const std::string& path, const std::vector<ViewPair>& pairs);

struct MvsView {
  int id = 0;
  torch::Tensor image;  // uint8 [H,W,3] RGB
  MvsCam cam;           // camera.width/height set from the image
};

class MvsFolder {
 public:
  // Checks that images/, cams/ and pair.txt exist; throws std::runtime_error naming what is missing.
  explicit MvsFolder(const std::string& root);

  const std::string& root() const { return root_; }
  const std::vector<ViewPair>& pairs() const { return pairs_; }
  const ViewPair& pair_of(int ref) const;  // throws if the view has no line in pair.txt
  std::string image_path(int id) const;     // throws if no image file for the view
  std::string cam_path(int id) const;
  std::string depth_gt_path(int id) const;  // "" when the folder has no ground truth for it
  MvsView load_view(int id) const;

 private:
  std::string root_;
  std::vector<ViewPair> pairs_;
};

std::string view_file_stem(int id);  // 8-digit zero-padded id

// The image file of view `id` in an images/ folder: XXXXXXXX with the first of .jpg, .png, .jpeg,
// .JPG, .PNG that exists. Throws std::runtime_error naming the folder when there is none.
std::string find_view_image(const std::string& images_dir, int id);

}  // namespace umvs
