// Photographic texture collections for synthetic scenes (core/synth_textures.h maps them onto
// surfaces). The images come from Debian packages that scripts/install_textures.sh installs
// (sources and licences: docs/synthetic.md); nothing of them is in the repository.
#pragma once

#include <torch/types.h>

#include <string>
#include <vector>

namespace umvs {

struct TextureBank {
  std::vector<torch::Tensor> images;  // uint8 [H,W,3], longest side <= max_side
  std::vector<std::string> paths;     // the file of each image
  std::vector<std::string> skipped;   // "file: reason" for image files that did not decode
};

// Every image file (.png .jpg .jpeg .webp .bmp .tif .tiff, and GIMP patterns .pat) under each
// folder, recursively, in sorted path order (the same folders give the same bank, so a scene is
// reproducible), shrunk by area averaging to at most `max_side` pixels on the longest side.
// Throws std::runtime_error naming the folder when it does not exist, is not a folder or holds
// no image that decodes; std::invalid_argument for an empty list or max_side < 8.
TextureBank load_texture_bank(const std::vector<std::string>& folders, int max_side = 512);

// The collections scripts/install_textures.sh installs (GIMP patterns, MATE nature photographs,
// scikit-image sample images), those present on this machine, in a fixed order; empty when none is.
std::vector<std::string> installed_texture_folders();

// A GIMP pattern file (.pat: a big-endian header, then 8-bit grey/grey+alpha/RGB/RGBA pixels)
// -> uint8 [H,W,3] RGB. Throws std::runtime_error naming the file and the problem.
torch::Tensor read_gimp_pattern(const std::string& path);

}  // namespace umvs
