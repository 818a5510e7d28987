#include "import_common.h"

#include <torch/torch.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>
#include <stdexcept>

#include "unsup_mvs/core/camera.h"
#include "unsup_mvs/core/view_selection.h"
#include "unsup_mvs/io/atomic_file.h"

namespace umvs::import_detail {

namespace fs = std::filesystem;

int id_from_name(const std::string& name) {
  const std::string stem = fs::path(name).stem().string();
  int end = static_cast<int>(stem.size());
  while (end > 0 && !std::isdigit(static_cast<unsigned char>(stem[end - 1]))) --end;
  int begin = end;
  while (begin > 0 && std::isdigit(static_cast<unsigned char>(stem[begin - 1]))) --begin;
  if (begin == end) return -1;
  return std::stoi(stem.substr(begin, end - begin));
}

void copy_atomically(const std::string& from, const std::string& to) {
  const std::string bytes = read_file_bytes(from);
  write_file_atomically(to, [&](std::ostream& out) { out.write(bytes.data(), static_cast<std::streamsize>(bytes.size())); });
}

void write_pairs(const std::string& path, const std::vector<ImportedView>& views,
                 const std::vector<std::vector<Eigen::Vector3d>>& points_per_view, int num_sources,
                 double min_baseline, double max_baseline) {
  std::vector<Camera> cams;
  for (const auto& v : views) cams.push_back(v.cam.camera);
  std::vector<ViewPair> pairs;
  for (size_t i = 0; i < views.size(); ++i) {
    std::vector<Camera> others;
    std::vector<int> ids;
    for (size_t j = 0; j < views.size(); ++j) {
      if (j == i) continue;
      others.push_back(cams[j]);
      ids.push_back(views[j].id);
    }
    ViewPair p;
    p.ref = views[i].id;
    auto ranked = rank_source_views(points_per_view[i], cams[i], others);
    if (min_baseline > 0.0 || max_baseline > 0.0) {
      const auto in_range = [&](const ScoredView& s) {
        const double b = (others[s.index].center() - cams[i].center()).norm();
        return b >= min_baseline && (max_baseline <= 0.0 || b <= max_baseline);
      };
      std::stable_partition(ranked.begin(), ranked.end(), in_range);
    }
    for (const auto& s : ranked) {
      if (static_cast<int>(p.sources.size()) >= num_sources) break;
      p.sources.push_back(ids[s.index]);
      p.scores.push_back(s.score);
    }
    pairs.push_back(p);
  }
  write_pair_file(path, pairs);
}

void set_depth_range(MvsCam& cam, double zmin, double zmax, double margin, int depth_num, const std::string& what) {
  if (!(zmin > 0.0) || !std::isfinite(zmin) || !std::isfinite(zmax) || zmax < zmin) {
    throw std::runtime_error(what + ": impossible depth range [" + std::to_string(zmin) + ", " + std::to_string(zmax) + "]");
  }
  // A flat scene (a wall) still needs a range to sweep: at least 5% of the depth.
  const double extra = margin * std::max(zmax - zmin, 0.05 * zmax);
  cam.depth_min = std::max(zmin - extra, 1e-3 * zmax);
  cam.depth_max = zmax + extra;
  cam.depth_num = depth_num;
  cam.depth_interval = (cam.depth_max - cam.depth_min) / (depth_num - 1);
}

void check_import_folders(const std::string& data_dir, const std::string& out_dir, int depth_num, int num_sources) {
  if (!fs::is_directory(data_dir)) throw std::runtime_error("data folder '" + data_dir + "' does not exist");
  if (fs::exists(out_dir) && fs::equivalent(data_dir, out_dir)) {
    throw std::runtime_error("the output folder must differ from the data folder");
  }
  if (depth_num < 2 || num_sources < 1) throw std::runtime_error("depth_num must be >= 2 and num_sources >= 1");
}

std::vector<double> numbers_in(const std::string& text, const std::string& where) {
  std::vector<double> v;
  std::istringstream ss(text);
  for (std::string tok; ss >> tok;) {
    char* end = nullptr;
    const double x = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0') throw std::runtime_error(where + ": '" + tok + "' is not a number");
    v.push_back(x);
  }
  return v;
}

std::string depth_image_for(const std::string& depth_dir, const std::string& color_path) {
  const std::string stem = fs::path(color_path).stem().string();
  for (const char* ext : {".png", ".pgm", ".tif", ".tiff"}) {
    const fs::path candidate = fs::path(depth_dir) / (stem + ext);
    if (fs::is_regular_file(candidate)) return candidate.string();
  }
  throw std::runtime_error("no depth image " + depth_dir + "/" + stem + ".{png,pgm,tif,tiff} for " + color_path);
}

}  // namespace umvs::import_detail
