// umvs bag: an MVSNet-format folder as a robot-like log (rosbag), or a summary of a log.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>

#include "unsup_mvs/io/array_io.h"
#include "unsup_mvs/io/ros/bag_io.h"
#include "unsup_mvs/io/mvs_folder.h"
#include "unsup_mvs/tools/args.h"
#include "unsup_mvs/tools/command.h"
#include "unsup_mvs/tools/progress.h"

UMVS_COMMAND(bag, "MVSNet-format folder -> rosbag (Image, CameraInfo, /tf); --inspect a bag") {
  umvs::Args args("bag",
                  "Writes the views of DIR (in id order) as a log a robot would record:\n"
                  "  IMAGE_TOPIC sensor_msgs/Image rgb8, INFO_TOPIC sensor_msgs/CameraInfo,\n"
                  "  /tf world_frame -> camera_frame (the optical frame), one frame every 1/rate s.\n"
                  "With --inspect FILE, reads a bag as training does and prints what it holds.");
  args.option("data", "", "MVSNet-format input folder (images/, cams/, pair.txt)")
      .option("out", "", "output .bag (written atomically)")
      .option("inspect", "", "print the posed images of this bag instead")
      .option("rate", "2", "frames per second in the log")
      .option("start", "0", "stamp of the first frame in seconds (0 = now)")
      .option("image-topic", "/camera/image_rect_color", "image topic")
      .option("info-topic", "/camera/camera_info", "CameraInfo topic")
      .option("world-frame", "world", "fixed frame of the poses")
      .option("camera-frame", "camera_optical_frame", "the camera's optical frame")
      .option("depth-topic", "", "also write DIR/depth_gt as 32FC1 depth (m) on this topic, e.g. /camera/depth "
                                 "(ground truth for validation); with --inspect: count the depth maps on it");
  if (!args.parse(argc, argv)) return 0;
  umvs::BagTopics topics;
  topics.image = args.str("image-topic");
  topics.camera_info = args.str("info-topic");
  topics.world_frame = args.str("world-frame");
  topics.camera_frame = args.str("camera-frame");
  topics.depth = args.str("depth-topic");

  if (args.given("inspect")) {
    size_t n = 0;
    double first = 0, last = 0;
    umvs::Camera first_cam;
    const auto stats = umvs::for_each_posed_image(args.str("inspect"), topics, true, [&](const umvs::PosedImage& f) {
      if (n == 0) {
        first = f.stamp;
        first_cam = f.camera;
      }
      last = f.stamp;
      ++n;
      return true;
    });
    std::cout << args.str("inspect") << ": " << stats.images << " images on " << topics.image << ", " << stats.used
              << " posed and calibrated";
    if (!topics.depth.empty()) std::cout << ", " << stats.with_depth << " with depth on " << topics.depth;
    if (n) std::printf(" (%dx%d, %.1f s, %.2f Hz)", first_cam.width, first_cam.height, last - first,
                       n > 1 ? (n - 1) / (last - first) : 0.0);
    std::cout << "\n";
    if (stats.without_info + stats.without_pose + stats.invalid > 0) {
      std::cout << "skipped: " << stats.without_info << " without CameraInfo, " << stats.without_pose
                << " without pose, " << stats.invalid << " invalid; first problem: " << stats.first_error << "\n";
    }
    return stats.used > 0 ? 0 : 1;
  }

  if (!args.given("data") || !args.given("out")) throw std::invalid_argument("give --data DIR and --out FILE.bag (or --inspect FILE)");
  const double rate = args.real("rate");
  if (!(rate > 0)) throw std::invalid_argument("--rate must be > 0");
  double start = args.real("start");
  if (start < 0) throw std::invalid_argument("--start must be >= 0");
  if (start == 0) {
    start = std::floor(std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count());
  }
  umvs::MvsFolder folder(args.str("data"));
  std::vector<int> ids;
  for (const auto& p : folder.pairs()) ids.push_back(p.ref);
  std::sort(ids.begin(), ids.end());
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  if (ids.empty()) throw std::runtime_error(folder.root() + "/pair.txt lists no views");

  umvs::BagWriter writer(args.str("out"), topics);
  umvs::Progress progress("bag", static_cast<int64_t>(ids.size()));
  for (size_t i = 0; i < ids.size(); ++i) {
    const umvs::MvsView v = folder.load_view(ids[i]);
    umvs::PosedImage frame;
    frame.stamp = start + i / rate;
    frame.image = v.image;
    frame.camera = v.cam.camera;
    if (!topics.depth.empty()) {
      const std::string gt = folder.depth_gt_path(ids[i]);
      if (gt.empty()) throw std::runtime_error("--depth-topic: view " + std::to_string(ids[i]) + " has no depth_gt");
      frame.depth = umvs::read_pfm(gt);
    }
    writer.write(frame);
    progress.update(static_cast<int64_t>(i + 1));
  }
  writer.close();
  progress.finish();
  std::cout << "wrote " << writer.frames() << " frames (" << ids.size() / rate << " s at " << rate << " Hz) to "
            << args.str("out") << ": " << topics.image << ", " << topics.camera_info << ", /tf " << topics.world_frame
            << " -> " << topics.camera_frame << (topics.depth.empty() ? "" : ", " + topics.depth) << "\n";
  return 0;
}
