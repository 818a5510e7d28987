// Photographic textures for synthetic scenes (core/synth.h). The images come from io
// (io/texture_bank.h decodes them); here they are mip-mapped and looked up by the surface point in
// primitive-local coordinates, so a texture is glued to its surface: every view sees the same
// colour there (multi-view consistent) and only the level of detail depends on the distance.
//
// Lookup: planar projection onto the local coordinate plane the surface faces (exact for
// rectangles and box faces), blended over the three planes by the normal on curved surfaces
// (triplanar mapping). Images repeat mirrored, so a photograph that does not tile shows no seam.
// LibTorch + Eigen only.
#pragma once

#include <torch/types.h>

#include <Eigen/Core>
#include <vector>

namespace umvs {

// How one surface wears a photograph.
struct PhotoMapping {
  int texture = -1;     // index into the bank; -1 = the surface keeps its procedural texture
  double size = 1.0;    // scene units covered by the image's width
  double angle = 0.0;   // rotation in the surface plane (radians)
  Eigen::Vector2d offset = Eigen::Vector2d::Zero();  // shift, in image widths
  Eigen::Vector3d tint = Eigen::Vector3d::Ones();    // per-channel gain applied to the image
};

class PhotoTextureBank {
 public:
  PhotoTextureBank() = default;
  // images: uint8 [H,W,3] RGB, each side >= 2 pixels. Throws std::invalid_argument naming the
  // index of a bad image.
  explicit PhotoTextureBank(const std::vector<torch::Tensor>& images);

  bool empty() const { return pyramids_.empty(); }
  int size() const { return static_cast<int>(pyramids_.size()); }
  int levels(int texture) const { return static_cast<int>(pyramids_.at(texture).size()); }
  int width(int texture) const { return pyramids_.at(texture).front().width; }

  // Tinted colour in [0,1] at primitive-local point `q` with unit local normal `n`. `footprint`:
  // the width of one ray's pixel on the surface there (scene units); it picks the mip level
  // (trilinear), 0 = full resolution.
  Eigen::Vector3d sample(const PhotoMapping& m, const Eigen::Vector3d& q, const Eigen::Vector3d& n,
                         double footprint) const;
  // Bilinear lookup (mirrored repeat) at mip level `level`, in level-0 texel units: texel (i, j)
  // has its centre at (x, y) = (i, j). Untinted, in [0,1].
  Eigen::Vector3d texel(int texture, int level, double x, double y) const;
  // The image's mean colour (untinted, in [0,1]).
  const Eigen::Vector3d& mean_colour(int texture) const { return means_.at(texture); }

 private:
  struct Level {
    int width = 0, height = 0;
    std::vector<float> rgb;  // row-major, 3 floats per texel, in [0,1]
  };
  Eigen::Vector3d planar(const PhotoMapping& m, double a, double b, double footprint) const;
  std::vector<std::vector<Level>> pyramids_;  // per texture: level 0 = the image, then halved
  std::vector<Eigen::Vector3d> means_;
};

}  // namespace umvs
