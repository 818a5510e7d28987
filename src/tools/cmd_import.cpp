// umvs import: real data sets -> MVSNet-format folders.
#include <iostream>
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

}  // namespace

UMVS_COMMAND(import, "convert a Middlebury or RGB-D data set to an MVSNet-format folder") {
  const std::string usage =
      "umvs import middlebury --data DIR --out OUT   Middlebury multi-view (e.g. templeRing): *_par.txt\n"
      "                                              calibration, bounding box from README.txt or --bbox\n"
      "umvs import rgbd --data DIR --out OUT         color/N.png, depth/N.png or .pgm (16-bit), pose.txt\n"
      "                                              ('tx ty tz qx qy qz qw' camera-to-world); writes depth_gt/\n"
      "View ids are the numbers in the image names. Depth ranges: the bounding box (middlebury) or the\n"
      "ground-truth depth (rgbd), widened by --margin. pair.txt ranks neighbours by MVSNet's\n"
      "view-selection score.";
  if (argc < 1 || std::string(argv[0]) == "--help" || std::string(argv[0]) == "-h") {
    const std::string help = umvs::subcommands_help(
        "umvs import", usage, {{"middlebury", "Middlebury multi-view (*_par.txt calibration)"}, {"rgbd", "color/, depth/ and pose.txt"}});
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
      std::vector<double> b;
      std::stringstream ss(args.str("bbox"));
      for (std::string item; std::getline(ss, item, ',');) b.push_back(std::stod(item));
      if (b.size() != 6) throw std::invalid_argument("--bbox needs 6 comma-separated numbers");
      cfg.bbox_given = true;
      cfg.bbox_min = Eigen::Vector3d(b[0], b[1], b[2]);
      cfg.bbox_max = Eigen::Vector3d(b[3], b[4], b[5]);
    }
    print_summary(umvs::import_middlebury(cfg), cfg.out_dir);
    return 0;
  }
  if (kind == "rgbd") {
    umvs::Args args("import rgbd", usage);
    umvs::RgbdImportConfig d;
    args.required("data", "folder with color/, depth/ and pose.txt")
        .required("out", "output MVSNet-format folder (with depth_gt/)")
        .option("fx", std::to_string(d.fx), "focal length x (pixels)")
        .option("fy", std::to_string(d.fy), "focal length y (pixels; negative flips the image y axis, as ICL-NUIM)")
        .option("cx", std::to_string(d.cx), "principal point x")
        .option("cy", std::to_string(d.cy), "principal point y")
        .option("depth-scale", std::to_string(d.depth_scale), "raw depth value per metre")
        .option("margin", "0.1", "depth range widened by this fraction of its length each side")
        .option("num-depth", "192", "DEPTH_NUM written to the cam files")
        .option("sources", "10", "neighbours per view in pair.txt");
    if (!args.parse(argc - 1, argv + 1)) return 0;
    umvs::RgbdImportConfig cfg;
    cfg.data_dir = args.str("data");
    cfg.out_dir = args.str("out");
    cfg.fx = args.real("fx");
    cfg.fy = args.real("fy");
    cfg.cx = args.real("cx");
    cfg.cy = args.real("cy");
    cfg.depth_scale = args.real("depth-scale");
    cfg.depth_margin = args.real("margin");
    cfg.depth_num = args.integer("num-depth");
    cfg.num_sources = args.integer("sources");
    print_summary(umvs::import_rgbd(cfg), cfg.out_dir);
    return 0;
  }
  throw std::invalid_argument("unknown data set kind '" + kind + "' (expected middlebury | rgbd; see umvs import --help)");
}
