// umvs import: real data sets -> MVSNet-format folders.
#include <cmath>
#include <iostream>
#include <map>
#include <sstream>

#include "unsup_mvs/io/import.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

namespace {

void print_summary(const umvs::ImportSummary& s, const std::string& out) {
  std::cout << "wrote " << s.views << " views to " << out << " (images/, cams/, pair.txt";
  std::cout << "), depth range " << s.depth_min << " .. " << s.depth_max;
  if (s.skipped) std::cout << "; " << s.skipped << " calibrated views without an image skipped";
  std::cout << "\n";
}

// "1,2.5,-3" -> numbers; names the option on anything else.
std::vector<double> parse_numbers(const std::string& text, const std::string& option) {
  std::vector<double> out;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) {
    char* end = nullptr;
    const double v = std::strtod(item.c_str(), &end);
    if (item.empty() || *end != '\0' || !std::isfinite(v)) {
      throw std::invalid_argument("--" + option + " needs comma-separated numbers, got '" + text + "'");
    }
    out.push_back(v);
  }
  return out;
}

}  // namespace

UMVS_COMMAND(import, "convert a Middlebury or RGB-D data set to an MVSNet-format folder") {
  const std::string usage =
      "umvs import middlebury --data DIR --out OUT   Middlebury multi-view (e.g. templeRing): *_par.txt\n"
      "                                              calibration, bounding box from README.txt or --bbox\n"
      "umvs import rgbd --data DIR --out OUT --intrinsics K.txt   color/N.png, depth/N.png|.pgm (16-bit), pose.txt\n"
      "                                              ('tx ty tz qx qy qz qw' camera-to-world, line N = frame N)\n"
      "umvs import tum --data DIR --out OUT --fx .. --fy .. --cx .. --cy ..   TUM RGB-D: rgb.txt, depth.txt,\n"
      "                                              groundtruth.txt, associated by nearest timestamp\n"
      "umvs import sevenscenes --data DIR --out OUT  7-Scenes: frame-N.color.png|jpg, .depth.png, .pose.txt\n"
      "umvs import dvmvs --data DIR --out OUT        DeepVideoMVS: images/, depth/, poses.txt (4x4 rows), K.txt\n"
      "RGB-D layouts write depth_gt/ (sensor depth, for scoring only); 0 and 65535 are no depth.\n"
      "View ids are the numbers in the image names. Depth ranges: the bounding box (middlebury) or the\n"
      "ground-truth depth (rgbd), widened by --margin. pair.txt ranks neighbours by MVSNet's\n"
      "view-selection score.";
  if (argc < 1 || std::string(argv[0]) == "--help" || std::string(argv[0]) == "-h") {
    const std::string help = umvs::subcommands_help(
        "umvs import", usage, {{"middlebury", "Middlebury multi-view (*_par.txt calibration)"},
                                        {"rgbd", "color/, depth/ and pose.txt (slambook2, ICL-NUIM)"},
                                        {"tum", "TUM RGB-D: rgb.txt, depth.txt, groundtruth.txt"},
                                        {"sevenscenes", "Microsoft 7-Scenes frames"},
                                        {"dvmvs", "DeepVideoMVS: images/, depth/, poses.txt, K.txt"}});
    (argc < 1 ? std::cerr : std::cout) << help;
    return argc < 1 ? 2 : 0;
  }
  const std::string kind = argv[0];
  if (kind == "middlebury") {
    umvs::Args args("import middlebury", usage);
    args.required("data", "folder with the images and *_par.txt")
        .required("out", "output MVSNet-format folder")
        .option("par", "", "calibration file (default: the only *_par.txt in --data)")
        .option("bbox", "", "xmin,ymin,zmin,xmax,ymax,zmax (default: from --data/README.txt)")
        .option("margin", "0.1", "depth range widened by this fraction of its length each side")
        .option("num-depth", "192", "DEPTH_NUM written to the cam files")
        .option("sources", "10", "neighbours per view in pair.txt");
    if (!args.parse(argc - 1, argv + 1)) return 0;
    umvs::MiddleburyImportConfig cfg;
    cfg.data_dir = args.str("data");
    cfg.out_dir = args.str("out");
    cfg.par_file = args.str("par");
    cfg.depth_margin = args.real("margin");
    cfg.depth_num = args.integer("num-depth");
    cfg.num_sources = args.integer("sources");
    if (args.given("bbox")) {
      const std::vector<double> b = parse_numbers(args.str("bbox"), "bbox");
      if (b.size() != 6) throw std::invalid_argument("--bbox needs 6 comma-separated numbers");
      cfg.bbox_given = true;
      cfg.bbox_min = Eigen::Vector3d(b[0], b[1], b[2]);
      cfg.bbox_max = Eigen::Vector3d(b[3], b[4], b[5]);
    }
    print_summary(umvs::import_middlebury(cfg), cfg.out_dir);
    return 0;
  }
  const std::map<std::string, umvs::RgbdLayout> layouts = {{"rgbd", umvs::RgbdLayout::kSlambook},
                                                          {"tum", umvs::RgbdLayout::kTum},
                                                          {"sevenscenes", umvs::RgbdLayout::kSevenScenes},
                                                          {"dvmvs", umvs::RgbdLayout::kDvmvs}};
  const auto layout = layouts.find(kind);
  if (layout != layouts.end()) {
    umvs::Args args("import " + kind, usage);
    const umvs::RgbdImportConfig d;
    const bool own_intrinsics = layout->second == umvs::RgbdLayout::kSevenScenes || layout->second == umvs::RgbdLayout::kDvmvs;
    args.required("data", "the data set's folder")
        .required("out", "output MVSNet-format folder (with depth_gt/)")
        .option("intrinsics", "",
                own_intrinsics ? "intrinsics file (default: the data set's own camera-intrinsics.txt / K.txt)"
                               : "intrinsics file: a 3x3 matrix, 'fx fy cx cy [k1 k2 p1 p2 [k3]]' or Camera.fx... YAML "
                                 "(or give --fx --fy --cx --cy)")
        .option("fx", "", "focal length x (pixels)")
        .option("fy", "", "focal length y (pixels; negative flips the image y axis, as ICL-NUIM)")
        .option("cx", "", "principal point x")
        .option("cy", "", "principal point y")
        .option("distortion", "", "k1,k2,p1,p2[,k3]: removed from colour and depth on import")
        .option("depth-scale", d.depth_scale, "raw depth value per metre (0 = the layout's: 5000 rgbd/tum, 1000 the others)")
        .option("depth-range", "",
                "NEAR,FAR metres for every view, as a robot configures it (default: each view's sensor depth range, "
                "widened by --margin: for scoring runs only)")
        .option("first", d.first, "first frame (in the layout's order)")
        .option("every", d.every, "keep every N-th frame")
        .option("count", d.count, "at most this many frames (0 = all)")
        .option("min-baseline", d.min_baseline, "metres: sources at least this far from the reference rank first")
        .option("max-baseline", d.max_baseline, "metres: ... and at most this far (0 = no limit)")
        .option("margin", d.depth_margin, "depth range widened by this fraction of its length each side")
        .option("num-depth", d.depth_num, "DEPTH_NUM written to the cam files")
        .option("sources", d.num_sources, "neighbours per view in pair.txt");
    if (layout->second == umvs::RgbdLayout::kTum) {
      args.option("poses", d.tum_pose_file, "pose file in --data: 'timestamp tx ty tz qx qy qz qw' camera-to-world")
          .option("associate", d.tum_association, "timestamp (nearest within --max-dt) | index (row k of each list)")
          .option("max-dt", d.tum_max_dt, "seconds: largest timestamp difference of an image to its depth and pose");
    }
    if (!args.parse(argc - 1, argv + 1)) return 0;
    umvs::RgbdImportConfig cfg;
    cfg.layout = layout->second;
    cfg.data_dir = args.str("data");
    cfg.out_dir = args.str("out");
    const int pinhole_given = args.given("fx") + args.given("fy") + args.given("cx") + args.given("cy");
    if (pinhole_given != 0 && pinhole_given != 4) throw std::invalid_argument("give all four of --fx --fy --cx --cy, or none");
    if (pinhole_given && args.given("intrinsics")) throw std::invalid_argument("give --intrinsics or --fx --fy --cx --cy, not both");
    if (args.given("intrinsics")) cfg.intrinsics = umvs::read_intrinsics_file(args.str("intrinsics"));
    if (pinhole_given) cfg.intrinsics.K << args.real("fx"), 0, args.real("cx"), 0, args.real("fy"), args.real("cy"), 0, 0, 1;
    if (!cfg.intrinsics.given() && !own_intrinsics) {
      throw std::invalid_argument("umvs import " + kind + " needs the camera's intrinsics: --intrinsics FILE or --fx --fy --cx --cy");
    }
    if (args.given("distortion")) {
      if (!cfg.intrinsics.given()) throw std::invalid_argument("--distortion needs the intrinsics it belongs to (--intrinsics or --fx ...)");
      cfg.intrinsics.distortion = parse_numbers(args.str("distortion"), "distortion");
      if (cfg.intrinsics.distortion.size() != 4 && cfg.intrinsics.distortion.size() != 5) {
        throw std::invalid_argument("--distortion needs 4 or 5 numbers: k1,k2,p1,p2[,k3]");
      }
    }
    if (args.given("depth-range")) {
      const auto range = parse_numbers(args.str("depth-range"), "depth-range");
      if (range.size() != 2 || !(range[0] > 0 && range[1] > range[0])) throw std::invalid_argument("--depth-range needs NEAR,FAR with 0 < NEAR < FAR");
      cfg.depth_near = range[0];
      cfg.depth_far = range[1];
    }
    cfg.depth_scale = args.real("depth-scale");
    cfg.first = args.integer("first");
    cfg.every = args.integer("every");
    cfg.count = args.integer("count");
    cfg.min_baseline = args.real("min-baseline");
    cfg.max_baseline = args.real("max-baseline");
    cfg.depth_margin = args.real("margin");
    cfg.depth_num = args.integer("num-depth");
    cfg.num_sources = args.integer("sources");
    if (layout->second == umvs::RgbdLayout::kTum) {
      cfg.tum_pose_file = args.str("poses");
      cfg.tum_association = args.str("associate");
      cfg.tum_max_dt = args.real("max-dt");
    }
    print_summary(umvs::import_rgbd(cfg), cfg.out_dir);
    return 0;
  }
  throw std::invalid_argument("unknown data set kind '" + kind + "' (expected middlebury | rgbd | tum | sevenscenes | dvmvs; see umvs import --help)");
}
