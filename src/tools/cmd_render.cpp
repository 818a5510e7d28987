// umvs render: a picture of a point cloud (z-buffered splats) as PNG.
#include <filesystem>
#include <optional>
#include <sstream>
#include <utility>

#include "unsup_mvs/core/render_points.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/image_io.h"
#include "unsup_mvs/io/inference_folder.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"

namespace {

// The size of the image an MVSNet cam file describes: that of DIR/images/ID.* for DIR/cams/ID_cam.txt.
std::optional<std::pair<int, int>> image_size_of_cam(const std::string& cam_path) {
  namespace fs = std::filesystem;
  const fs::path cam(cam_path);
  const std::string stem = cam.filename().string();
  const auto suffix = stem.rfind("_cam.txt");
  if (suffix == std::string::npos || cam.parent_path().filename() != "cams") return std::nullopt;
  int id = 0;
  try {
    id = std::stoi(stem.substr(0, suffix));
  } catch (const std::exception&) {
    return std::nullopt;
  }
  try {
    const auto image = umvs::read_image_rgb8(umvs::find_view_image((cam.parent_path().parent_path() / "images").string(), id));
    return std::make_pair(static_cast<int>(image.size(1)), static_cast<int>(image.size(0)));
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

// A cam file drawn at another image size than its own puts the picture in a corner (or off it):
// its principal point lies near the centre of the image it describes.
void check_principal_point(const umvs::Camera& cam, int width, int height) {
  const double cx = cam.K(0, 2), cy = cam.K(1, 2);
  if (cx < 0.25 * width || cx > 0.75 * width || cy < 0.25 * height || cy > 0.75 * height) {
    std::ostringstream why;
    why << "--cam: the principal point (" << cx << ", " << cy << ") is far from the centre of a " << width << "x"
        << height << " picture: the cam file describes an image of another size (about " << std::lround(2 * cx) << "x"
        << std::lround(2 * cy) << "?); give that size with --width/--height, and --scale to draw it larger or smaller";
    throw std::invalid_argument(why.str());
  }
}

}  // namespace

UMVS_COMMAND(render, "render a point cloud (PLY or PCD) to a PNG picture") {
  umvs::Args args("render",
                  "Splats the points of a cloud into a picture, seen either from an MVSNet cam file (--cam; the\n"
                  "picture has the size of the view's image in the same folder, DIR/images/ID.*, unless\n"
                  "--width/--height say otherwise) or from an orbit around the cloud's centre.");
  args.required("cloud", "input cloud (.ply or .pcd)")
      .required("out", "output PNG")
      .option("cam", "", "MVSNet cam file to look through (default: orbit view)")
      .option("width", "640", "picture width (with --cam: the width of the image the cam file describes, "
                              "by default that of its image in DIR/images/)")
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
  int W = args.integer("width"), H = args.integer("height");
  if (W <= 0 || H <= 0) throw std::invalid_argument("--width and --height must be positive");
  if (args.given("cam")) {
    cam = umvs::read_cam_file(args.str("cam")).camera;
    if (!args.given("width") && !args.given("height")) {
      if (const auto size = image_size_of_cam(args.str("cam"))) {
        W = size->first;
        H = size->second;
      }
    }
    check_principal_point(cam, W, H);
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
