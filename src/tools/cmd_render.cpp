// umvs render: a picture of a point cloud (z-buffered splats) as PNG.
#include <sstream>

#include "unsup_mvs/core/render_points.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

UMVS_COMMAND(render, "render a point cloud (PLY or PCD) to a PNG picture") {
  umvs::Args args("render",
                  "Splats the points of a PLY into a picture, seen either from an MVSNet cam file (--cam, its\n"
                  "image being --width x --height) or from an orbit around the cloud's centre.");
  args.required("cloud", "input cloud (.ply or .pcd)")
      .required("out", "output PNG")
      .option("cam", "", "MVSNet cam file to look through (default: orbit view)")
      .option("width", "640", "picture width (with --cam: the width of the image the cam file describes)")
      .option("height", "480", "picture height")
      .option("scale", "1", "with --cam: picture size = image size * scale")
      .option("azimuth", "30", "orbit: degrees about --up")
      .option("elevation", "25", "orbit: degrees above the horizontal plane")
      .option("up", "0,0,1", "orbit: world up axis x,y,z")
      .option("fov", "40", "orbit: horizontal field of view, degrees")
      .option("splat", "1", "splat radius in pixels");
  if (!args.parse(argc, argv)) return 0;
  const auto cloud = umvs::read_cloud(args.str("cloud"));
  if (cloud.empty()) throw std::runtime_error(args.str("cloud") + " has no points");
  umvs::Camera cam;
  const int W = args.integer("width"), H = args.integer("height");
  if (W <= 0 || H <= 0) throw std::invalid_argument("--width and --height must be positive");
  if (args.given("cam")) {
    cam = umvs::read_cam_file(args.str("cam")).camera;
    cam.width = W;
    cam.height = H;
    const double s = args.real("scale");
    if (!(s > 0)) throw std::invalid_argument("--scale must be positive");
    if (s != 1.0) cam = cam.resized(static_cast<int>(std::lround(W * s)), static_cast<int>(std::lround(H * s)));
  } else {
    std::vector<double> up;
    std::stringstream ss(args.str("up"));
    for (std::string item; std::getline(ss, item, ',');) up.push_back(std::stod(item));
    if (up.size() != 3) throw std::invalid_argument("--up needs x,y,z");
    cam = umvs::orbit_camera(cloud, W, H, args.real("azimuth"), args.real("elevation"), Eigen::Vector3d(up[0], up[1], up[2]),
                             args.real("fov"));
  }
  umvs::RenderConfig rc;
  rc.splat_radius = args.integer("splat");
  umvs::write_png(args.str("out"), umvs::render_points(cloud, cam, rc));
  std::printf("rendered %zu points to %s (%dx%d)\n", cloud.size(), args.str("out").c_str(), cam.width, cam.height);
  return 0;
}
