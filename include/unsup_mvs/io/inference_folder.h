// The folder `umvs infer` writes and `umvs fuse` / `umvs eval` read, in one place:
//   depth_est/XXXXXXXX.pfm (+ .png preview)   depth in scene units, 1/4 of the network input
//   confidence/XXXXXXXX.pfm (+ .png)          photometric confidence in [0,1]
//   cams/XXXXXXXX_cam.txt                      camera of the depth map's image (MVSNet cam file)
//   images/XXXXXXXX.png                        colours of the depth map
//   pair.txt                                   the views that made each depth map
#pragma once

#include <string>

namespace umvs {

class InferenceFolder {
 public:
  explicit InferenceFolder(std::string root) : root_(std::move(root)) {}

  // Whether `dir` holds depth maps written by `umvs infer` (it has depth_est/).
  static bool holds(const std::string& dir);
  // Creates the four subfolders (and the root).
  void create() const;

  const std::string& root() const { return root_; }
  std::string depth_dir() const { return root_ + "/depth_est"; }
  std::string confidence_dir() const { return root_ + "/confidence"; }
  std::string cams_dir() const { return root_ + "/cams"; }
  std::string images_dir() const { return root_ + "/images"; }
  std::string pair_file() const { return root_ + "/pair.txt"; }

  std::string depth_path(int id) const;               // depth_est/XXXXXXXX.pfm
  std::string depth_preview_path(int id) const;       // depth_est/XXXXXXXX.png
  std::string confidence_path(int id) const;          // confidence/XXXXXXXX.pfm
  std::string confidence_preview_path(int id) const;  // confidence/XXXXXXXX.png
  std::string cam_path(int id) const;                 // cams/XXXXXXXX_cam.txt
  std::string image_path(int id) const;               // images/XXXXXXXX.png

 private:
  std::string root_;
};

}  // namespace umvs
