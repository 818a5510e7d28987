#include "unsup_mvs/io/texture_bank.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <stdexcept>

#include "unsup_mvs/core/image_ops.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/image_io.h"

namespace umvs {
namespace fs = std::filesystem;
namespace {

std::string lower_extension(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

bool is_image_file(const fs::path& p) {
  static const char* kExtensions[] = {".png", ".jpg", ".jpeg", ".webp", ".bmp", ".tif", ".tiff", ".pat"};
  const std::string e = lower_extension(p);
  return std::any_of(std::begin(kExtensions), std::end(kExtensions), [&](const char* k) { return e == k; });
}

uint32_t big_endian_u32(const std::string& bytes, size_t at) {
  return (static_cast<uint32_t>(static_cast<uint8_t>(bytes[at])) << 24) |
         (static_cast<uint32_t>(static_cast<uint8_t>(bytes[at + 1])) << 16) |
         (static_cast<uint32_t>(static_cast<uint8_t>(bytes[at + 2])) << 8) |
         static_cast<uint32_t>(static_cast<uint8_t>(bytes[at + 3]));
}

// uint8 [H,W,3] with the longest side at most max_side (area averaging).
torch::Tensor shrink(const torch::Tensor& rgb8, int max_side) {
  const int64_t h = rgb8.size(0), w = rgb8.size(1);
  if (std::max(h, w) <= max_side) return rgb8;
  const double s = static_cast<double>(max_side) / std::max(h, w);
  const int nw = std::max(2, static_cast<int>(std::lround(w * s))), nh = std::max(2, static_cast<int>(std::lround(h * s)));
  return float_to_rgb8(resize_image(rgb8_to_float(rgb8), nw, nh));
}

}  // namespace

torch::Tensor read_gimp_pattern(const std::string& path) {
  const std::string bytes = read_file_bytes(path);
  auto fail = [&](const std::string& why) -> torch::Tensor {
    throw std::runtime_error("GIMP pattern '" + path + "': " + why);
  };
  if (bytes.size() < 24) return fail("file too short for the header (" + std::to_string(bytes.size()) + " bytes)");
  if (bytes.compare(20, 4, "GPAT") != 0) return fail("no 'GPAT' magic: not a GIMP pattern");
  const uint32_t header = big_endian_u32(bytes, 0), version = big_endian_u32(bytes, 4);
  const uint32_t width = big_endian_u32(bytes, 8), height = big_endian_u32(bytes, 12), depth = big_endian_u32(bytes, 16);
  if (version != 1) return fail("unsupported version " + std::to_string(version));
  if (depth < 1 || depth > 4) return fail("unsupported " + std::to_string(depth) + " bytes per pixel");
  if (width < 1 || height < 1 || width > 16384 || height > 16384) {
    return fail("impossible size " + std::to_string(width) + "x" + std::to_string(height));
  }
  const size_t need = static_cast<size_t>(header) + static_cast<size_t>(width) * height * depth;
  if (header < 24 || need > bytes.size()) {
    return fail("truncated: " + std::to_string(bytes.size()) + " bytes, the header announces " + std::to_string(need));
  }
  auto rgb = torch::empty({static_cast<int64_t>(height), static_cast<int64_t>(width), 3}, torch::kUInt8);
  uint8_t* out = rgb.data_ptr<uint8_t>();
  const auto* in = reinterpret_cast<const uint8_t*>(bytes.data()) + header;
  for (size_t i = 0; i < static_cast<size_t>(width) * height; ++i) {
    const uint8_t* px = in + i * depth;
    const bool grey = depth <= 2;  // grey or grey + alpha; the alpha byte is dropped
    for (int c = 0; c < 3; ++c) out[i * 3 + c] = grey ? px[0] : px[c];
  }
  return rgb;
}

TextureBank load_texture_bank(const std::vector<std::string>& folders, int max_side) {
  if (folders.empty()) throw std::invalid_argument("texture bank: no folder given");
  if (max_side < 8) throw std::invalid_argument("texture bank: max_side must be at least 8, got " + std::to_string(max_side));
  TextureBank bank;
  for (const std::string& folder : folders) {
    std::error_code ec;
    if (!fs::exists(folder, ec)) throw std::runtime_error("texture folder '" + folder + "' does not exist");
    if (!fs::is_directory(folder, ec)) throw std::runtime_error("texture folder '" + folder + "' is not a folder");
    std::vector<fs::path> files;
    for (auto it = fs::recursive_directory_iterator(folder, fs::directory_options::skip_permission_denied, ec);
         !ec && it != fs::recursive_directory_iterator(); it.increment(ec)) {
      if (it->is_regular_file(ec) && is_image_file(it->path())) files.push_back(it->path());
    }
    if (ec) throw std::runtime_error("texture folder '" + folder + "': cannot list it (" + ec.message() + ")");
    std::sort(files.begin(), files.end());
    size_t decoded = 0;
    for (const fs::path& f : files) {
      try {
        const torch::Tensor img = lower_extension(f) == ".pat" ? read_gimp_pattern(f.string()) : read_image_rgb8(f.string());
        if (img.size(0) < 2 || img.size(1) < 2) throw std::runtime_error("smaller than 2x2 pixels");
        bank.images.push_back(shrink(img, max_side).contiguous());
        bank.paths.push_back(f.string());
        ++decoded;
      } catch (const std::exception& e) {
        bank.skipped.push_back(f.string() + ": " + e.what());
      }
    }
    if (decoded == 0) {
      throw std::runtime_error("texture folder '" + folder + "' holds no image that decodes (" + std::to_string(files.size()) +
                               " image files; png, jpg, webp, bmp, tif or GIMP .pat expected)");
    }
  }
  return bank;
}

std::vector<std::string> installed_texture_folders() {
  // Keep in step with scripts/install_textures.sh and docs/synthetic.md.
  static const char* kCollections[] = {
      "/usr/share/gimp/2.0/patterns",                   // gimp-data
      "/usr/share/backgrounds/mate/nature",             // mate-backgrounds
      "/usr/local/share/unsup_mvs/textures/scikit-image",  // python3-skimage's sample images
  };
  std::vector<std::string> present;
  for (const char* c : kCollections) {
    std::error_code ec;
    if (fs::is_directory(c, ec)) present.emplace_back(c);
  }
  return present;
}

}  // namespace umvs
