#include "unsup_mvs/io/inference_folder.h"

#include <filesystem>

#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace fs = std::filesystem;

namespace umvs {

bool InferenceFolder::holds(const std::string& dir) { return fs::is_directory(InferenceFolder(dir).depth_dir()); }

void InferenceFolder::create() const {
  for (const auto& d : {depth_dir(), confidence_dir(), cams_dir(), images_dir()}) make_directories(d);
}

std::string InferenceFolder::depth_path(int id) const { return depth_dir() + "/" + view_file_stem(id) + ".pfm"; }
std::string InferenceFolder::depth_preview_path(int id) const { return depth_dir() + "/" + view_file_stem(id) + ".png"; }
std::string InferenceFolder::confidence_path(int id) const {
  return confidence_dir() + "/" + view_file_stem(id) + ".pfm";
}
std::string InferenceFolder::confidence_preview_path(int id) const {
  return confidence_dir() + "/" + view_file_stem(id) + ".png";
}
std::string InferenceFolder::cam_path(int id) const { return cams_dir() + "/" + view_file_stem(id) + "_cam.txt"; }
std::string InferenceFolder::image_path(int id) const { return images_dir() + "/" + view_file_stem(id) + ".png"; }

}  // namespace umvs
