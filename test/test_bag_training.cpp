// Training tuples from rosbags (io/bag_training_data.h) and `umvs train --bag`, on a synthetic
// room logged with BagWriter.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <rosbag/bag.h>
#include <rosbag/view.h>
#include <sensor_msgs/CompressedImage.h>
#include <sensor_msgs/Image.h>
#include <torch/torch.h>

#include <cstdlib>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>

#include "test_util.h"
#include "unsup_mvs/core/synth.h"
#include "unsup_mvs/io/ros/bag_io.h"
#include "unsup_mvs/io/ros/bag_training_data.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/jobs/fine_tune_job.h"  // keyframe_stream_train_args

namespace {

struct LoggedScene {
  umvs::SynthScene scene;
  std::string bag;
};

// 14 views of a room written as a log (one frame per second).
const LoggedScene& logged_room() {
  static const LoggedScene logged = [] {
    LoggedScene l;
    umvs::SynthConfig c;
    c.scene = umvs::SynthSceneType::kRoom;
    c.seed = 5;
    c.num_views = 14;
    c.width = 128;
    c.height = 96;
    c.supersample = 1;
    c.gt_cloud_samples = 0;
    l.scene = umvs::render_synthetic_scene(c);
    l.bag = umvs::test::temp_dir("bag_training") + "/room.bag";
    umvs::BagTopics topics;
    topics.depth = "/camera/depth";  // ground truth, read only when asked for
    umvs::BagWriter writer(l.bag, topics);
    for (size_t i = 0; i < l.scene.views.size(); ++i) {
      const auto& v = l.scene.views[i];
      writer.write({100.0 + static_cast<double>(i), v.image, v.camera, v.depth});
    }
    writer.close();
    return l;
  }();
  return logged;
}

umvs::TupleConfig small_tuples() {
  umvs::TupleConfig t;
  t.width = 64;
  t.height = 64;
  t.views_in = 3;
  t.views_loss = 4;
  return t;
}

umvs::BagDataConfig room_config() {
  umvs::BagDataConfig c;
  c.keyframes.min_translation = 0.05;
  c.keyframes.min_score = 0.1;
  c.depth_min = 0.4;
  c.depth_max = 9.0;
  c.holdout_every = 4;
  return c;
}

bool same_pose(const umvs::Camera& a, const umvs::Camera& b) {
  return (a.T_cam_world.matrix() - b.T_cam_world.matrix()).norm() < 1e-6;
}

TEST(BagTraining, KeyframesFollowTheSelectorPolicyAndHoldOutEveryKth) {
  const auto& room = logged_room();
  const auto config = room_config();
  const auto keyframes = umvs::read_bag_keyframes({room.bag}, config);
  std::vector<umvs::Camera> cameras;
  for (const auto& v : room.scene.views) cameras.push_back(v.camera);
  const auto expected = umvs::select_keyframes(cameras, config.keyframes);
  ASSERT_EQ(keyframes.size(), expected.size());
  ASSERT_GE(keyframes.size(), 8u);
  for (size_t k = 0; k < keyframes.size(); ++k) {
    EXPECT_EQ(keyframes[k].frame, expected[k]);
    EXPECT_TRUE(same_pose(keyframes[k].image.camera, cameras[expected[k]]));
    EXPECT_EQ(keyframes[k].held_out, k % 4 == 3) << "keyframe " << k;
    EXPECT_FALSE(keyframes[k].image.depth.defined()) << "no depth topic was asked for";
  }
}

// The logged room again, its images as sensor_msgs/CompressedImage (`format`: "png" or "jpeg", as
// a camera driver or image_transport's compressed transport records them). `corrupt_frame` >= 0
// replaces that frame's bytes with garbage.
std::string compressed_copy(const std::string& raw_bag, const std::string& format, int corrupt_frame = -1) {
  const std::string out = umvs::test::temp_dir("bag_compressed_" + format + std::to_string(corrupt_frame)) + "/room.bag";
  const umvs::BagTopics topics;
  rosbag::Bag in(raw_bag, rosbag::bagmode::Read), copy(out, rosbag::bagmode::Write);
  int frame = 0;
  for (const rosbag::MessageInstance& m : rosbag::View(in)) {
    const auto image = m.instantiate<sensor_msgs::Image>();
    if (!image || m.getTopic() != topics.image) {
      copy.write(m.getTopic(), m.getTime(), m);
      continue;
    }
    const torch::Tensor rgb = umvs::image_msg_to_rgb8(*image);
    cv::Mat bgr;
    cv::cvtColor(cv::Mat(rgb.size(0), rgb.size(1), CV_8UC3, rgb.data_ptr()), bgr, cv::COLOR_RGB2BGR);
    sensor_msgs::CompressedImage c;
    c.header = image->header;
    c.format = format;
    cv::imencode(format == "png" ? ".png" : ".jpg", bgr, c.data);
    if (frame++ == corrupt_frame) std::fill(c.data.begin() + 2, c.data.end(), 0x5a);
    copy.write(topics.image, m.getTime(), c);
  }
  copy.close();
  return out;
}

TEST(BagTraining, CompressedImagesGiveTheSameKeyframesAsRawOnes) {
  const auto& room = logged_room();
  const auto config = room_config();
  const auto raw = umvs::read_bag_keyframes({room.bag}, config);
  const auto png = umvs::read_bag_keyframes({compressed_copy(room.bag, "png")}, config);
  const auto jpeg = umvs::read_bag_keyframes({compressed_copy(room.bag, "jpeg")}, config);
  ASSERT_GE(raw.size(), 8u);
  ASSERT_EQ(png.size(), raw.size());
  ASSERT_EQ(jpeg.size(), raw.size());
  for (size_t k = 0; k < raw.size(); ++k) {
    EXPECT_EQ(png[k].frame, raw[k].frame);
    EXPECT_EQ(jpeg[k].frame, raw[k].frame);
    EXPECT_TRUE(same_pose(png[k].image.camera, raw[k].image.camera));
    // png is lossless: the same pixels; jpeg: close (a few grey levels on average).
    EXPECT_TRUE(torch::equal(png[k].image.image, raw[k].image.image)) << "keyframe " << k;
    const double jpeg_error =
        (jpeg[k].image.image.to(torch::kFloat) - raw[k].image.image.to(torch::kFloat)).abs().mean().item<double>();
    EXPECT_GT(jpeg_error, 0.0) << "jpeg is lossy: the copy was really re-encoded";
    EXPECT_LT(jpeg_error, 6.0) << "keyframe " << k;
  }
}

TEST(BagTraining, ACompressedFrameThatDoesNotDecodeIsSkippedWithTheReason) {
  const auto& room = logged_room();
  const std::string bag = compressed_copy(room.bag, "png", 3);
  const umvs::BagReadStats stats =
      umvs::for_each_posed_image(bag, umvs::BagTopics{}, true, [](const umvs::PosedImage&) { return true; });
  EXPECT_EQ(stats.images, room.scene.views.size());
  EXPECT_EQ(stats.invalid, 1u);
  EXPECT_EQ(stats.used, room.scene.views.size() - 1);
  EXPECT_THAT(stats.first_error, testing::HasSubstr("cannot be decoded"));
  // A depth image in compressedDepth format is named as such, not decoded as colours.
  sensor_msgs::CompressedImage depth;
  depth.format = "32FC1; compressedDepth";
  depth.data = {1, 2, 3};
  EXPECT_THAT([&] { umvs::compressed_to_image_msg(depth, 1 << 20); },
              testing::ThrowsMessage<std::invalid_argument>(testing::HasSubstr("is a depth image")));
}

TEST(BagTraining, GroundTruthDepthFromADepthTopicReachesTheTuples) {
  const auto& room = logged_room();
  auto config = room_config();
  config.topics.depth = "/camera/depth";
  auto keyframes =
      std::make_shared<const std::vector<umvs::BagKeyframe>>(umvs::read_bag_keyframes({room.bag}, config));
  for (const auto& k : *keyframes) {
    ASSERT_TRUE(k.image.depth.defined());
    EXPECT_TRUE(torch::equal(k.image.depth, room.scene.views[k.frame].depth)) << "frame " << k.frame;
  }
  auto tuples = small_tuples();
  tuples.width = 128;  // the bag's size: no resampling, the ground truth must come through unchanged
  tuples.height = 96;
  const umvs::BagSource held_out(keyframes, umvs::BagSplit::kHeldOut, config, tuples);
  ASSERT_GT(held_out.size(), 0u);
  for (size_t i = 0; i < held_out.size(); ++i) {
    const auto t = held_out.tuple(i, nullptr);
    ASSERT_TRUE(t.depth_gt.defined());
    bool matched = false;
    for (const auto& v : room.scene.views) matched |= torch::equal(t.depth_gt, v.depth) && same_pose(v.camera, t.network_views[0].camera);
    EXPECT_TRUE(matched) << t.name;
  }
  EXPECT_NE(held_out.description().find("with ground-truth depth"), std::string::npos) << held_out.description();
}

TEST(BagTraining, TrainingTuplesNeverTouchHeldOutKeyframes) {
  const auto& room = logged_room();
  const auto config = room_config();
  auto keyframes =
      std::make_shared<const std::vector<umvs::BagKeyframe>>(umvs::read_bag_keyframes({room.bag}, config));
  const umvs::BagSource train(keyframes, umvs::BagSplit::kTraining, config, small_tuples());
  const umvs::BagSource held_out(keyframes, umvs::BagSplit::kHeldOut, config, small_tuples());
  std::vector<umvs::Camera> held_cameras;
  for (const auto& k : *keyframes)
    if (k.held_out) held_cameras.push_back(k.image.camera);
  ASSERT_GT(train.size(), 0u);
  ASSERT_GT(held_out.size(), 0u);
  EXPECT_LE(held_out.size(), held_cameras.size());
  EXPECT_LE(train.size() + held_cameras.size(), keyframes->size());
  EXPECT_GE(2 * train.size(), keyframes->size() - held_cameras.size()) << "most keyframes should have neighbours";
  for (size_t i = 0; i < train.size(); ++i) {
    const auto t = train.tuple(i, nullptr);
    EXPECT_EQ(t.network_views.size(), 3u);
    EXPECT_EQ(t.loss_views.size(), 4u);
    EXPECT_DOUBLE_EQ(t.depth_min, 0.4);
    EXPECT_DOUBLE_EQ(t.depth_max, 9.0);
    EXPECT_FALSE(t.depth_gt.defined());
    EXPECT_EQ(t.network_views[0].image.size(0), 64);
    std::vector<umvs::ViewInput> views = t.network_views;
    views.insert(views.end(), t.loss_views.begin(), t.loss_views.end());
    for (const auto& v : views)
      for (const auto& h : held_cameras) EXPECT_FALSE(same_pose(v.camera, h)) << t.name;
  }
  // Held-out references are exactly the held-out keyframes.
  for (size_t i = 0; i < held_out.size(); ++i) {
    const auto t = held_out.tuple(i, nullptr);
    bool found = false;
    for (const auto& h : held_cameras) found |= same_pose(t.network_views[0].camera, h);
    EXPECT_TRUE(found) << t.name;
  }
}

TEST(BagTraining, TheBestSourceSeesTheReferenceCentre) {
  // The ranking must pick overlapping views: the point 3 m along the reference's optical axis
  // (inside every room) projects into the best source's image.
  const auto& room = logged_room();
  auto config = room_config();
  config.holdout_every = 0;
  auto keyframes =
      std::make_shared<const std::vector<umvs::BagKeyframe>>(umvs::read_bag_keyframes({room.bag}, config));
  const umvs::BagSource all(keyframes, umvs::BagSplit::kAll, config, small_tuples());
  ASSERT_EQ(all.size(), keyframes->size());
  for (size_t i = 0; i < all.size(); ++i) {
    const auto t = all.tuple(i, nullptr);
    const auto& ref = t.network_views[0].camera;
    const auto& src = t.network_views[1].camera;
    // The best source's centre ray at mid-range lands inside its image.
    const Eigen::Vector4d p_world = ref.T_cam_world.inverse() * Eigen::Vector4d(0, 0, 3.0, 1.0);
    const Eigen::Vector3d p_src = src.K * (src.T_cam_world * p_world).head<3>();
    ASSERT_GT(p_src.z(), 0) << t.name;
    EXPECT_GE(p_src.x() / p_src.z(), 0) << t.name;
    EXPECT_LT(p_src.x() / p_src.z(), src.width) << t.name;
  }
}

TEST(BagTraining, SkippedKeyframesAreCountedWithTheNeighboursTheyLack) {
  // The room's last two keyframes as a second bag: each has one keyframe of its own bag, fewer than
  // the two neighbours needed, so exactly those two are skipped; the rest keep enough.
  const auto& room = logged_room();
  auto config = room_config();
  config.holdout_every = 0;
  auto keyframes = umvs::read_bag_keyframes({room.bag}, config);
  ASSERT_GE(keyframes.size(), 8u);
  keyframes[keyframes.size() - 1].bag = 1;
  keyframes[keyframes.size() - 2].bag = 1;
  auto tuples = small_tuples();
  tuples.views_loss = 2;
  const umvs::BagSource all(std::make_shared<const std::vector<umvs::BagKeyframe>>(keyframes), umvs::BagSplit::kAll,
                            config, tuples);
  EXPECT_EQ(all.size(), keyframes.size() - 2);
  EXPECT_NE(all.description().find(" keyframe tuples from " + std::to_string(keyframes.size()) +
                                   " keyframes (2 skipped: fewer than the 2 neighbours that --views-in 3 and "
                                   "--views-loss 2 need)"),
            std::string::npos)
      << all.description();
  tuples.views_in = 2;  // one neighbour is enough for the last two
  tuples.views_loss = 1;
  const umvs::BagSource none_skipped(std::make_shared<const std::vector<umvs::BagKeyframe>>(keyframes),
                                     umvs::BagSplit::kAll, config, tuples);
  EXPECT_EQ(none_skipped.description().find("skipped"), std::string::npos) << none_skipped.description();
}

TEST(BagTraining, UnusableInputIsRefusedWithTheReason) {
  const auto& room = logged_room();
  auto config = room_config();
  config.topics.image = "/wrong/image";
  EXPECT_THAT([&] { umvs::read_bag_keyframes({room.bag}, config); },
              testing::ThrowsMessage<std::runtime_error>(testing::HasSubstr("/wrong/image")));
  config = room_config();
  config.depth_max = config.depth_min;
  EXPECT_THROW(umvs::read_bag_keyframes({room.bag}, config), std::invalid_argument);
  config = room_config();
  config.keyframes.min_translation = 100.0;  // one keyframe only: no neighbours
  config.keyframes.min_rotation_deg = 0;
  auto keyframes =
      std::make_shared<const std::vector<umvs::BagKeyframe>>(umvs::read_bag_keyframes({room.bag}, config));
  EXPECT_EQ(keyframes->size(), 1u);
  EXPECT_THROW(umvs::BagSource(keyframes, umvs::BagSplit::kTraining, config, small_tuples()), std::runtime_error);
  EXPECT_THROW(umvs::read_bag_keyframes({room.bag + ".missing"}, room_config()), std::runtime_error);
}

TEST(BagTraining, UmvsTrainOnABagWritesModelsAndEvaluatesHeldOutKeyframes) {
  const auto& room = logged_room();
  const std::string out = umvs::test::temp_dir("bag_train_cli");
  const std::string common = " --bag " + room.bag +
                             " --min-translation 0.05 --depth-min 0.4 --depth-max 9 --holdout-every 4"
                             " --depth-topic /camera/depth"
                             " --width 64 --height 64 --num-depth 8 --views-loss 4 --threads 2";
  const std::string train = umvs::test::umvs_binary() + " train" + common + " --steps 3 --save-every 3 --out " + out +
                            "/run > " + out + "/train.txt 2>&1";
  ASSERT_EQ(std::system(train.c_str()), 0) << train;
  ASSERT_TRUE(std::filesystem::exists(out + "/run/best.pt"));
  std::ifstream log(out + "/run/train_log.csv");
  std::string header, line, last;
  std::getline(log, header);
  int rows = 0;
  while (std::getline(log, line)) last = line, ++rows;
  EXPECT_EQ(rows, 3);
  // The last row carries a held-out validation (val_photometric is column 9).
  std::vector<std::string> f;
  std::stringstream ss(last);
  for (std::string c; std::getline(ss, c, ',');) f.push_back(c);
  ASSERT_GE(f.size(), 10u);
  const double val_photometric = std::stod(f[8]);
  ASSERT_GE(f.size(), 11u) << last;
  EXPECT_GT(std::stod(f[10]), 0.0) << "validation against the bag's ground truth (val_abs_err): " << last;
  EXPECT_GT(val_photometric, 0.0) << last;

  const std::string eval = umvs::test::umvs_binary() + " train" + common + " --eval-only " + out +
                           "/run/best.pt --out " + out + "/eval > " + out + "/eval.txt 2>&1";
  ASSERT_EQ(std::system(eval.c_str()), 0) << eval;
  std::ifstream csv(out + "/eval/eval.csv");
  std::getline(csv, header);
  std::getline(csv, line);
  EXPECT_EQ(header.rfind("checkpoint,tuples,photometric", 0), 0u);
  f.clear();
  std::stringstream es(line);
  for (std::string c; std::getline(es, c, ',');) f.push_back(c);
  ASSERT_GE(f.size(), 3u);
  EXPECT_GT(std::stoi(f[1]), 0);
  ASSERT_GE(f.size(), 7u);
  EXPECT_GT(std::stod(f[6]), 0.0) << "the held-out keyframes have ground truth: abs_err expected";
  // Same held-out keyframes, same model (best.pt is the only checkpoint): the validation of the
  // last step and --eval-only agree.
  EXPECT_NEAR(std::stod(f[2]), val_photometric, 1e-4 * val_photometric);
}

// The trainer node hands `umvs train` the keyframe_selector's settings as
// keyframe_stream_train_args(): the tool must then keep exactly the keyframes that the library
// reader (the selector's policy, KeyframeBuffer) keeps with those settings, and other settings
// must give other keyframes (the arguments are not ignored).
TEST(BagTraining, UmvsTrainReadsTheBagWithTheSelectorSettingsItIsGiven) {
  const auto& room = logged_room();
  const std::string out = umvs::test::temp_dir("bag_stream_args");
  auto keyframes_reported = [&](const std::vector<std::string>& stream_args, const std::string& name) {
    std::string cmd = umvs::test::umvs_binary() + " train --bag " + room.bag + " --holdout-every 0";
    for (const auto& a : stream_args) cmd += " " + a;
    cmd += " --width 64 --height 64 --num-depth 8 --steps 0 --threads 1 --out " + out + "/" + name + " > " + out +
           "/" + name + ".txt 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
    std::ifstream f(out + "/" + name + ".txt");
    const std::string text((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    const auto at = text.find(" keyframes (0 held out)");
    EXPECT_NE(at, std::string::npos) << text;
    if (at == std::string::npos) return -1;
    const auto start = text.rfind(' ', at - 1) + 1;
    return std::stoi(text.substr(start, at - start));
  };
  umvs::BagDataConfig coarse = room_config();
  coarse.holdout_every = 0;
  coarse.keyframes.min_translation = 0.6;  // 7 of the 14 frames
  coarse.keyframes.min_rotation_deg = 40.0;
  umvs::BagDataConfig fine = coarse;
  fine.keyframes.min_translation = 0.05;
  fine.keyframes.min_rotation_deg = 5.0;
  const size_t coarse_expected = umvs::read_bag_keyframes({room.bag}, coarse).size();
  const size_t fine_expected = umvs::read_bag_keyframes({room.bag}, fine).size();
  ASSERT_LT(coarse_expected, fine_expected) << "the two settings must keep different keyframes";
  EXPECT_EQ(keyframes_reported(umvs::keyframe_stream_train_args(coarse), "coarse"), static_cast<int>(coarse_expected));
  EXPECT_EQ(keyframes_reported(umvs::keyframe_stream_train_args(fine), "fine"), static_cast<int>(fine_expected));
}

}  // namespace
