#include "unsup_mvs/io/refine_poses.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <Eigen/Geometry>
#include <map>
#include <optional>
#include <stdexcept>

#include "unsup_mvs/core/keyframe_pose_refiner.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/mvs_folder.h"

namespace umvs {

namespace fs = std::filesystem;

namespace {

void check_output_folder(const std::string& data_dir, const std::string& out_dir) {
  if (out_dir.empty()) throw std::invalid_argument("no output folder given");
  std::error_code ec;
  if (fs::is_symlink(out_dir, ec)) throw std::invalid_argument("output folder '" + out_dir + "' is a symbolic link; refusing it");
  if (!fs::exists(out_dir, ec)) return;
  if (fs::equivalent(data_dir, out_dir, ec)) throw std::invalid_argument("the output folder must differ from the data folder");
  if (!fs::is_directory(out_dir, ec)) throw std::invalid_argument("output '" + out_dir + "' exists and is not a folder");
  if (!fs::is_empty(out_dir, ec)) {
    throw std::invalid_argument("output folder '" + out_dir + "' is not empty; give a new folder (nothing is overwritten)");
  }
}

std::string report_text(const PoseRefinementResult& result) {
  std::string text = "# umvs refine-poses: per view, the turn applied (degrees about the camera's own x, y, z)\n";
  char line[200];
  for (const auto& [id, turn] : result.view_degrees) {
    const Eigen::Vector3d d = turn.unaryExpr([](double v) { return std::abs(v) < 5e-4 ? 0.0 : v; });  // no "-0.000"
    std::snprintf(line, sizeof(line), "view %d turn %.3f %.3f %.3f\n", id, d.x(), d.y(), d.z());
    text += line;
  }
  text += "# per round and pair: the source's best turn against the reference, the warp's gains (search, full"
          " size), whether the turn was kept, how the pair was used (turn: measured; zero: agrees as posed; unused:"
          " the two gains disagree) and how far the consistent turns are from it (degrees)\n";
  for (const MeasuredPair& p : result.pairs) {
    const char* use = !p.used ? "unused" : p.turn.kept ? "turn" : "zero";
    std::snprintf(line, sizeof(line), "round %d pair %d %d turn %.3f %.3f %.3f gain %.4f %.4f %s %s residual %.3f\n",
                  p.round, p.reference, p.source, p.turn.degrees.x(), p.turn.degrees.y(), p.turn.degrees.z(),
                  p.turn.search_gain, p.turn.full_size_gain, p.turn.kept ? "kept" : "not_kept", use, p.residual_deg);
    text += line;
  }
  return text;
}

}  // namespace

PoseRefinementResult refine_folder_poses(const PoseRefinementConfig& config, DepthEstimator& estimator,
                                         const std::function<void(int, int, const MeasuredPair&)>& on_pair) {
  if (config.rounds < 1) throw std::invalid_argument("need at least 1 round, got " + std::to_string(config.rounds));
  if (config.sources < 1) throw std::invalid_argument("need at least 1 neighbour per reference, got " + std::to_string(config.sources));
  if (!std::isfinite(config.search_deg) || config.search_deg <= 0) {
    throw std::invalid_argument("the search limit must be an angle > 0 degrees, got " + std::to_string(config.search_deg));
  }
  check_output_folder(config.data_dir, config.out_dir);
  const MvsFolder folder(config.data_dir);

  std::vector<int> refs = config.refs;
  if (refs.empty()) {
    for (const auto& p : folder.pairs()) refs.push_back(p.ref);
  }
  std::vector<std::pair<int, int>> to_measure;  // (reference, source)
  for (const int ref : refs) {
    const ViewPair& pair = folder.pair_of(ref);
    for (size_t s = 0; s < pair.sources.size() && static_cast<int>(s) < config.sources; ++s) to_measure.emplace_back(ref, pair.sources[s]);
  }
  std::map<int, MvsView> views;
  for (const auto& p : folder.pairs()) views.emplace(p.ref, folder.load_view(p.ref));
  const auto view = [&](int id) -> const MvsView& {
    auto it = views.find(id);
    if (it == views.end()) it = views.emplace(id, folder.load_view(id)).first;
    return it->second;
  };

  std::map<int, Camera> cameras;  // as corrected so far
  for (const auto& [ref, source] : to_measure) {
    cameras.emplace(ref, view(ref).cam.camera);
    cameras.emplace(source, view(source).cam.camera);
  }
  PoseRefinementResult result;
  const int total = config.rounds * static_cast<int>(to_measure.size());
  for (int round = 0; round < config.rounds; ++round) {
    std::vector<PairTurn> measurements;
    for (const auto& [ref, source] : to_measure) {
      const MvsCam& cam = view(ref).cam;
      if (cam.depth_min <= 0) throw std::runtime_error("view " + std::to_string(ref) + ": no depth range in its cam file");
      MeasuredPair measured;
      measured.round = round + 1;
      measured.reference = ref;
      measured.source = source;
      measured.turn = estimator.best_source_turn({view(ref).image, cameras.at(ref)}, {view(source).image, cameras.at(source)},
                                                 cam.depth_min, cam.resolved_depth_max(estimator.num_depth()), config.search_deg);
      const std::optional<Eigen::Vector3d> relative_turn = measured_pair_turn(measured.turn);
      if (relative_turn) measurements.push_back({ref, source, *relative_turn});
      measured.used = relative_turn.has_value();
      result.pairs.push_back(measured);
      if (on_pair) on_pair(static_cast<int>(result.pairs.size()), total, measured);
    }
    const ConsistentTurns turns = consistent_view_turns(cameras, measurements);
    size_t k = 0;
    for (size_t p = result.pairs.size() - to_measure.size(); p < result.pairs.size(); ++p) {
      if (result.pairs[p].used) result.pairs[p].residual_deg = turns.residual_degrees[k++];
    }
    for (auto& [id, camera] : cameras) camera = camera.turned(turns.view_degrees.at(id) * kRadiansPerDegree);
  }
  for (const auto& [id, camera] : cameras) {
    const Eigen::AngleAxisd total_turn(camera.R() * view(id).cam.camera.R().transpose());  // R_cw' = turn R_cw
    result.view_degrees[id] = total_turn.axis() * total_turn.angle() / kRadiansPerDegree;
  }

  check_output_folder(config.data_dir, config.out_dir);  // again: the measurements took a while
  for (const char* sub : {"images", "cams"}) make_directories(config.out_dir + "/" + sub);
  for (const auto& [id, v] : views) {
    const std::string image = folder.image_path(id);
    copy_file_to_new_name(image, config.out_dir + "/images/" + fs::path(image).filename().string());
    MvsCam cam = v.cam;
    if (cameras.count(id)) cam.camera = cameras.at(id);
    write_cam_file(config.out_dir + "/cams/" + view_file_stem(id) + "_cam.txt", cam);
  }
  write_pair_file(config.out_dir + "/pair.txt", folder.pairs());
  const std::string report = report_text(result);
  write_file_atomically(config.out_dir + "/pose_refinement.txt", [&](std::ostream& out) { out << report; });
  return result;
}

}  // namespace umvs
