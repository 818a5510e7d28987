// rostest: fault injection against the running nodes (docs/reliability.md, "ROS nodes and file
// writes"). fusion's save_cloud stays inside ~save_dir whatever the path and links say;
// inference's reload_model refuses FIFOs, devices, oversized files and too many planes without
// blocking, and keeps serving meanwhile; truncated and oversized images are refused where they
// enter; images without CameraInfo are reported; the trainer never overwrites a file, publishes a
// model only when inference accepts it, its training process dies with it, and a restarted trainer
// removes the temporary files an interrupted write left. The trainer runs a stand-in for
// `umvs train` (a shell script) so that every job is fast and deterministic.
#include <fcntl.h>
#include <geometry_msgs/PoseArray.h>
#include <sensor_msgs/PointCloud2.h>
#include <sys/stat.h>
#include <tf2_msgs/TFMessage.h>
#include <torch/torch.h>
#include <unistd.h>

#include <atomic>
#include <filesystem>
#include <fstream>
#include <thread>

#include "rostest_util.h"
#include "test_messages.h"
#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/FineTune.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/ReloadModel.h"
#include "unsup_mvs/SaveCloud.h"
#include "unsup_mvs/TrainingProgress.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/child_process.h"
#include "unsup_mvs/io/ply.h"

namespace fs = std::filesystem;
using umvs_test::wait_for;

namespace {

std::string read_text(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}
void write_text(const std::string& path, const std::string& text) { std::ofstream(path) << text; }

// True once `pid` is gone (or a zombie nobody here can reap).
bool process_gone(pid_t pid) {
  std::ifstream stat("/proc/" + std::to_string(pid) + "/stat");
  std::string line;
  if (!std::getline(stat, line)) return true;
  const auto close = line.rfind(')');
  return close != std::string::npos && close + 2 < line.size() && line[close + 2] == 'Z';
}

// Stand-in for `umvs train`: a training job writes an unloadable best.pt at once (or, with
// --steps 99999, records its pid and sleeps); --eval-only rates the job's best.pt better than any
// other checkpoint (lower photometric loss, higher multi-view consistency), so the trainer always
// tries to publish the new model.
constexpr char kFakeUmvs[] = R"(#!/bin/sh
out=""; eval_only=""; steps=""
while [ $# -gt 0 ]; do
  case "$1" in --out) out="$2"; shift;; --eval-only) eval_only="$2"; shift;; --steps) steps="$2"; shift;; esac
  shift
done
mkdir -p "$out"
if [ -n "$eval_only" ]; then
  case "$eval_only" in */best.pt) scores=0.1,0.9;; *) scores=0.2,0.5;; esac
  printf 'photometric,consistent\n%s\n' "$scores" > "$out/eval.csv"
  exit 0
fi
echo $$ > "$out/child.pid"
if [ "$steps" = "99999" ]; then exec sleep 300; fi
printf 'not a checkpoint' > "$out/best.pt"
printf 'step,total\n1,0.5\n' > "$out/train_log.csv"
)";

class FaultsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ros::NodeHandle pnh("~");
    ASSERT_TRUE(pnh.getParam("work_dir", work_));
    fs::create_directories(work_ + "/clouds");
    for (const auto& e : fs::directory_iterator(work_)) {
      if (e.path().filename() != "clouds") fs::remove_all(e.path());  // fusion created clouds/ at start
    }
    for (const auto& e : fs::directory_iterator(work_ + "/clouds")) fs::remove_all(e.path());
    torch::manual_seed(0);
    umvs::MvsNetConfig config;
    config.num_depth = 32;
    umvs::MvsNet net(config);
    umvs::save_checkpoint(work_ + "/model.pt", net);
    write_text(work_ + "/fake_umvs.sh", kFakeUmvs);
    fs::permissions(work_ + "/fake_umvs.sh", fs::perms::owner_all);
    write_text(work_ + "/fake.bag", "a bag the stand-in never reads");
  }

  void SetUp() override {
    reload_ = nh_.serviceClient<unsup_mvs::ReloadModel>("/inference/reload_model");
    save_ = nh_.serviceClient<unsup_mvs::SaveCloud>("/fusion/save_cloud");
    ASSERT_TRUE(reload_.waitForExistence(ros::Duration(30.0))) << "inference did not come up";
    ASSERT_TRUE(save_.waitForExistence(ros::Duration(30.0))) << "fusion did not come up";
  }

  bool reload(const std::string& path, std::string* message) {
    unsup_mvs::ReloadModel srv;
    srv.request.checkpoint = path;
    EXPECT_TRUE(reload_.call(srv));
    *message = srv.response.message;
    return srv.response.success;
  }

  unsup_mvs::SaveCloud::Response save(const std::string& path) {
    unsup_mvs::SaveCloud srv;
    srv.request.path = path;
    EXPECT_TRUE(save_.call(srv));
    return srv.response;
  }

  // A trainer node of our own (so that it can be killed and restarted), running the stand-in.
  void start_trainer(umvs::ChildProcess& process, const std::string& name) {
    const std::string cmd = "exec '" + umvs_test::bin_dir() + "/trainer_node' __name:=" + name + " _output_dir:=" + work_ +
                            "/models _served_checkpoint:=" + work_ + "/models/served.pt _umvs_path:=" + work_ +
                            "/fake_umvs.sh _reload_service:=/inference/reload_model _poll_period:=0.1 >> " + work_ +
                            "/" + name + ".log 2>&1";
    process.start({"/bin/sh", "-c", cmd});
    ASSERT_TRUE(ros::service::waitForService("/" + name + "/fine_tune", ros::Duration(30.0)))
        << read_text(work_ + "/" + name + ".log");
  }

  unsup_mvs::FineTune::Response fine_tune(const std::string& trainer, int steps, const std::string& output) {
    unsup_mvs::FineTune srv;
    srv.request.bags = {work_ + "/fake.bag"};
    srv.request.steps = steps;
    srv.request.output = output;
    EXPECT_TRUE(ros::service::call("/" + trainer + "/fine_tune", srv));
    return srv.response;
  }

  static std::string work_;
  ros::NodeHandle nh_;
  ros::ServiceClient reload_, save_;
};
std::string FaultsTest::work_;

// ---------------------------------------------------------------------------------------------
// fusion: save_cloud

unsup_mvs::DepthEstimate plane_estimate(uint32_t id, double x) {
  return umvs_test::plane_estimate(id, x, "plane_cam");
}

TEST_F(FaultsTest, SaveCloudWritesOnlyInsideSaveDir) {
  auto estimate_pub = nh_.advertise<unsup_mvs::DepthEstimate>("/depth_estimate", 10);
  sensor_msgs::PointCloud2ConstPtr cloud;
  auto cloud_sub = nh_.subscribe<sensor_msgs::PointCloud2>("/cloud", 5, [&](const sensor_msgs::PointCloud2ConstPtr& m) {
    cloud = m;
  });
  ASSERT_TRUE(wait_for([&] { return estimate_pub.getNumSubscribers() > 0 && cloud_sub.getNumPublishers() > 0; }, 20.0));
  uint32_t id = 0;
  ASSERT_TRUE(wait_for([&] {  // one estimate per try until the map has points (two must agree)
    if (cloud && cloud->width > 0) return true;
    estimate_pub.publish(plane_estimate(id, 0.1 * (id % 3)));
    ++id;
    ros::WallDuration(0.1).sleep();
    return false;
  }, 30.0)) << "fusion made no cloud";

  const std::string clouds = work_ + "/clouds", outside = work_ + "/outside";
  fs::create_directories(outside);
  write_text(outside + "/victim.ply", "precious");
  fs::create_symlink(outside, clouds + "/escape");
  fs::create_symlink(outside + "/victim.ply", clouds + "/link.ply");
  const std::string tmp_outside = "/tmp/umvs_faults_test_outside.ply";
  fs::remove(tmp_outside);
  for (const std::string& bad : {std::string("out/../../outside/x.ply"), std::string("escape/x.ply"),
                                 std::string("link.ply"), outside + "/x.ply", tmp_outside}) {
    const auto res = save(bad);
    EXPECT_FALSE(res.success) << bad;
    EXPECT_NE(res.message.find("outside the allowed folder"), std::string::npos) << res.message;
  }
  EXPECT_FALSE(fs::exists(outside + "/x.ply"));
  EXPECT_FALSE(fs::exists(clouds + "/out")) << "a folder was created for a refused path";
  EXPECT_FALSE(fs::exists(tmp_outside));
  EXPECT_EQ(read_text(outside + "/victim.ply"), "precious");
  EXPECT_TRUE(fs::is_symlink(clouds + "/link.ply"));

  auto res = save("maps/room.ply");  // relative: inside ~save_dir, folders created there
  ASSERT_TRUE(res.success) << res.message;
  EXPECT_GT(res.num_points, 0u);
  EXPECT_EQ(umvs::read_ply(clouds + "/maps/room.ply").size(), res.num_points);
  res = save(clouds + "/abs.ply");  // absolute inside ~save_dir
  EXPECT_TRUE(res.success) << res.message;
  res = save("");  // ~default_save_path, relative to ~save_dir
  EXPECT_TRUE(res.success) << res.message;
  EXPECT_TRUE(fs::exists(clouds + "/unsup_mvs_cloud.ply"));
}

// ---------------------------------------------------------------------------------------------
// inference: reload_model and keyframe sets

// Frame "cam64" tells inference's answers to these from the other tests' estimates.
unsup_mvs::KeyframeSet small_set(uint32_t id) { return umvs_test::keyframe_set(id, {64, 64, 50.0, "cam64"}); }

class InferenceFaultsTest : public FaultsTest {
 protected:
  void SetUp() override {
    FaultsTest::SetUp();
    keyframes_pub_ = nh_.advertise<unsup_mvs::KeyframeSet>("/keyframes", 10);
    estimate_sub_ = nh_.subscribe<unsup_mvs::DepthEstimate>("/depth_estimate", 10,
                                                            [this](const unsup_mvs::DepthEstimateConstPtr& m) {
                                                              if (m->header.frame_id == "cam64") estimates_.push_back(m);
                                                            });
    ASSERT_TRUE(wait_for([&] { return keyframes_pub_.getNumSubscribers() > 0; }, 20.0));
    std::string message;
    ASSERT_TRUE(reload(work_ + "/model.pt", &message)) << message;
  }
  // Sends set `id` (again every 2 s: a set may be dropped as stale) until its estimate arrives.
  bool estimate_arrives(uint32_t id, double timeout) {
    ros::WallTime next;
    return wait_for([&] {
      if (ros::WallTime::now() >= next) {
        keyframes_pub_.publish(small_set(id));
        next = ros::WallTime::now() + ros::WallDuration(2.0);
      }
      for (const auto& e : estimates_) {
        if (e->keyframe_id == id) return true;
      }
      return false;
    }, timeout);
  }
  ros::Publisher keyframes_pub_;
  ros::Subscriber estimate_sub_;
  std::vector<unsup_mvs::DepthEstimateConstPtr> estimates_;
};

TEST_F(InferenceFaultsTest, ReloadOfAFifoNeitherBlocksTheServiceNorTheDepthMaps) {
  const std::string fifo = work_ + "/fifo.pt";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::atomic<bool> answered{false};
  std::string message;
  std::thread caller([&] {
    unsup_mvs::ReloadModel srv;
    srv.request.checkpoint = fifo;
    ros::service::call("/inference/reload_model", srv);
    message = srv.response.message;
    answered = true;
  });
  // Depth maps keep coming while the reload is handled.
  const bool served = estimate_arrives(1, 30.0);
  const bool answered_in_time = wait_for([&] { return answered.load(); }, 30.0);
  if (!answered_in_time) {  // unblock a node stuck opening the FIFO, so that the test can end
    const int fd = ::open(fifo.c_str(), O_WRONLY | O_NONBLOCK);
    if (fd >= 0) ::close(fd);
  }
  caller.join();
  EXPECT_TRUE(served) << "no depth map while reload_model was busy with a FIFO";
  ASSERT_TRUE(answered_in_time) << "reload_model did not answer for a FIFO";
  EXPECT_NE(message.find("is a FIFO, not a regular file"), std::string::npos) << message;
}

TEST_F(InferenceFaultsTest, ReloadRefusesDevicesFoldersAndOversizedFiles) {
  // Each must be refused at once, naming the reason, and the served model stays.
  {
    std::ofstream(work_ + "/huge.pt");
  }
  fs::resize_file(work_ + "/huge.pt", 9u << 20);  // sparse: claims 9 MiB, ~max_checkpoint_mb is 8
  // /dev/zero last, and ASSERT: a node without the checks would read it until it runs out of memory.
  const std::vector<std::pair<std::string, std::string>> cases = {
      {work_, "is a folder, not a regular file"},
      {work_ + "/huge.pt", "is 9437184 bytes, more than the limit of 8388608"},
      {work_ + "/missing.pt", "cannot open"},
      {"/dev/zero", "is a device, not a regular file"},
  };
  for (const auto& [path, why] : cases) {
    std::string message;
    EXPECT_FALSE(reload(path, &message)) << path;
    ASSERT_NE(message.find(why), std::string::npos) << message;
  }
  EXPECT_TRUE(estimate_arrives(2, 60.0)) << "inference stopped serving";
}

TEST_F(InferenceFaultsTest, TruncatedAndOversizedImagesInASetAreRefused) {
  umvs_test::RosoutCapture log(nh_);
  auto truncated = small_set(10);
  truncated.source_images[1].data.resize(truncated.source_images[1].data.size() - 100);
  EXPECT_TRUE(umvs_test::publish_until_logged(keyframes_pub_, truncated, log, "truncated image", 20.0)) << log.all();
  auto oversized = small_set(11);
  oversized.reference_image = umvs_test::make_image(256, 256, oversized.reference_image.header);  // > 40000 px
  EXPECT_TRUE(umvs_test::publish_until_logged(keyframes_pub_, oversized, log, "more than the limit of 40000", 20.0)) << log.all();
  for (const auto& e : estimates_) EXPECT_TRUE(e->keyframe_id != 10 && e->keyframe_id != 11) << e->keyframe_id;
  EXPECT_TRUE(estimate_arrives(12, 60.0)) << log.all();
}

TEST_F(InferenceFaultsTest, ASetAskingForMorePlanesThanMaxPlanesIsRefused) {
  // ~num_depth 0: the planes follow the network input, 16 for the 64-wide sets, 24 for a 128-wide
  // one, more than ~max_planes 16.
  umvs_test::RosoutCapture log(nh_);
  const auto wide = umvs_test::keyframe_set(20, {128, 128, 100.0, "cam64"});
  EXPECT_TRUE(umvs_test::publish_until_logged(keyframes_pub_, wide, log, "24 depth planes, more than ~max_planes 16",
                                              20.0)) << log.all();
  for (const auto& e : estimates_) EXPECT_NE(e->keyframe_id, 20u);
  EXPECT_TRUE(estimate_arrives(21, 60.0)) << log.all();
}

// ---------------------------------------------------------------------------------------------
// keyframe_selector: images where they enter

class SelectorFaultsTest : public FaultsTest {
 protected:
  void SetUp() override {
    FaultsTest::SetUp();
    image_pub_ = nh_.advertise<sensor_msgs::Image>("/cam/image", 10);
    info_pub_ = nh_.advertise<sensor_msgs::CameraInfo>("/cam/camera_info", 10);
    tf_pub_ = nh_.advertise<tf2_msgs::TFMessage>("/tf", 100);
    sets_sub_ = nh_.subscribe<unsup_mvs::KeyframeSet>("/selected_keyframes", 20,
                                                      [this](const unsup_mvs::KeyframeSetConstPtr& m) { sets_.push_back(m); });
    poses_sub_ = nh_.subscribe<geometry_msgs::PoseArray>("/keyframe_poses", 5, [this](const geometry_msgs::PoseArrayConstPtr& m) {
      keyframe_poses_ = m;
    });
    ASSERT_TRUE(wait_for([&] { return image_pub_.getNumSubscribers() > 0 && info_pub_.getNumSubscribers() > 0 &&
                                      tf_pub_.getNumSubscribers() > 0 && sets_sub_.getNumPublishers() > 0; }, 30.0));
  }

  // The transform world -> cam at a new stamp, then the camera_info and `image` (stamped alike).
  void send(double x, sensor_msgs::Image image, bool with_info = true) {
    const ros::Time stamp = ros::Time::now();
    geometry_msgs::TransformStamped tf;
    tf.header.stamp = stamp;
    tf.header.frame_id = "world";
    tf.child_frame_id = "cam";
    const auto pose = umvs_test::make_pose({x, 0, 0});
    tf.transform.translation.x = pose.position.x;
    tf.transform.rotation = pose.orientation;
    tf2_msgs::TFMessage tfm;
    tfm.transforms.push_back(tf);
    tf_pub_.publish(tfm);
    image.header.stamp = stamp;
    image.header.frame_id = "cam";
    if (with_info) info_pub_.publish(umvs_test::make_info(image.width, image.height, 120.0, image.header));
    image_pub_.publish(image);
  }
  static sensor_msgs::Image image(int width = 160, int height = 128) {
    return umvs_test::make_image(width, height, std_msgs::Header());
  }

  ros::Publisher image_pub_, info_pub_, tf_pub_;
  ros::Subscriber sets_sub_, poses_sub_;
  std::vector<unsup_mvs::KeyframeSetConstPtr> sets_;
  geometry_msgs::PoseArrayConstPtr keyframe_poses_;  // the selector's keyframes (latched)
};

TEST_F(SelectorFaultsTest, TruncatedImagesNeverBecomeKeyframes) {
  umvs_test::RosoutCapture log(nh_);
  // Keyframes every 0.11 m; the third position first comes with a truncated image.
  auto truncated = image();
  truncated.data.resize(truncated.data.size() - 1);
  auto oversized = image(256, 256);  // 65536 px > ~max_image_pixels 40000
  const std::vector<double> xs = {0.0, 0.11, 0.22, 0.33, 0.44, 0.55};
  for (size_t i = 0; i < xs.size(); ++i) {
    if (i == 2) {
      ros::WallTime next;  // resent until refused: the selector may not have the transform yet
      ASSERT_TRUE(wait_for([&] {
        if (ros::WallTime::now() >= next) send(xs[i], truncated), next = ros::WallTime::now() + ros::WallDuration(0.5);
        return log.contains("truncated image");
      }, 20.0)) << log.all();
      next = ros::WallTime();
      ASSERT_TRUE(wait_for([&] {
        if (ros::WallTime::now() >= next) send(xs[i], oversized), next = ros::WallTime::now() + ros::WallDuration(2.1);
        return log.contains("more than the limit of 40000");
      }, 20.0)) << log.all();
    }
    const size_t sets_before = sets_.size();
    send(xs[i], image());
    // Each good frame is a keyframe; from the third on, each gives the previous one its set (the
    // third also gives the first one its set).
    ASSERT_TRUE(wait_for([&] { return keyframe_poses_ && keyframe_poses_->poses.size() == i + 1; }, 20.0))
        << "x = " << xs[i] << " did not become keyframe " << i << "\n" << log.all();
    if (i >= 2) {
      ASSERT_TRUE(wait_for([&] { return sets_.size() > sets_before; }, 20.0)) << "no set for x = " << xs[i] << "\n" << log.all();
    }
  }
  ASSERT_TRUE(wait_for([&] { return sets_.size() >= 5; }, 10.0)) << sets_.size() << " sets";
  ASSERT_EQ(sets_.size(), 5u);  // the last keyframe waits for a newer one
  for (const auto& s : sets_) {
    std::vector<const sensor_msgs::Image*> images = {&s->reference_image};
    for (const auto& i : s->source_images) images.push_back(&i);
    for (const auto* i : images) {
      EXPECT_GE(i->data.size(), static_cast<size_t>(i->step) * i->height) << "a truncated image went out in set " << s->reference_id;
      EXPECT_EQ(i->width, 160u);
    }
  }
}

TEST_F(SelectorFaultsTest, ImagesWithoutCameraInfoAreReported) {
  umvs_test::RosoutCapture log(nh_);
  ros::WallTime next;
  double x = 5.0;
  EXPECT_TRUE(wait_for([&] {
    if (ros::WallTime::now() >= next) send(x += 0.2, image(), /*with_info=*/false), next = ros::WallTime::now() + ros::WallDuration(0.1);
    return log.contains("no CameraInfo") && log.contains("on '/cam/camera_info'");
  }, 20.0)) << log.all();
  EXPECT_NE(log.all().find("images arrive on '/cam/image'"), std::string::npos) << log.all();
}

// ---------------------------------------------------------------------------------------------
// trainer: new names only, publish what inference accepts, die together, clean up after

TEST_F(FaultsTest, FineTuneNeverOverwritesAFileAndKeepsNoRefusedModel) {
  const std::string models = work_ + "/models";
  fs::create_directories(models);
  if (!fs::exists(models + "/served.pt")) fs::copy_file(work_ + "/model.pt", models + "/served.pt");
  const std::string served_bytes = read_text(models + "/served.pt");
  write_text(models + "/taken.pt", "someone's model");
  fs::create_symlink(models + "/not_yet.pt", models + "/dangling.pt");
  umvs::ChildProcess trainer;
  ASSERT_NO_FATAL_FAILURE(start_trainer(trainer, "trainer_a"));

  for (const std::string& taken : {models + "/served.pt", models + "/taken.pt", models + "/dangling.pt"}) {
    const auto r = fine_tune("trainer_a", 10, taken);
    EXPECT_FALSE(r.accepted) << taken;
    EXPECT_NE(r.message.find("already exists"), std::string::npos) << r.message;
  }
  EXPECT_EQ(read_text(models + "/served.pt"), served_bytes);
  EXPECT_EQ(read_text(models + "/taken.pt"), "someone's model");
  EXPECT_FALSE(fs::exists(models + "/not_yet.pt"));

  // A job whose model wins the comparison but that inference refuses: it must not stay under the output name.
  unsup_mvs::TrainingProgressConstPtr last;
  auto progress = nh_.subscribe<unsup_mvs::TrainingProgress>("/trainer_a/progress", 20,
                                                             [&](const unsup_mvs::TrainingProgressConstPtr& m) { last = m; });
  const auto r = fine_tune("trainer_a", 10, models + "/new.pt");
  ASSERT_TRUE(r.accepted) << r.message;
  ASSERT_TRUE(wait_for([&] { return last && last->job_id == r.job_id && (last->state == "failed" || last->state == "reloaded"); },
                       60.0)) << read_text(work_ + "/trainer_a.log");
  EXPECT_EQ(last->state, "failed");
  EXPECT_NE(last->message.find("inference refused the new model"), std::string::npos) << last->message;
  EXPECT_FALSE(fs::exists(models + "/new.pt")) << "a model inference refused sits under the output name";
  EXPECT_TRUE(fs::exists(models + "/" + r.job_id + "/best.pt")) << "the job's model is kept in its folder";
  EXPECT_EQ(read_text(models + "/served.pt"), served_bytes);
}

TEST_F(FaultsTest, AKilledTrainerTakesItsTrainingAlongAndARestartCleansUp) {
  const std::string models = work_ + "/models";
  fs::create_directories(models);
  if (!fs::exists(models + "/served.pt")) fs::copy_file(work_ + "/model.pt", models + "/served.pt");
  umvs::ChildProcess trainer;
  ASSERT_NO_FATAL_FAILURE(start_trainer(trainer, "trainer_b"));
  const auto r = fine_tune("trainer_b", 99999, "");
  ASSERT_TRUE(r.accepted) << r.message;
  const std::string job_dir = models + "/" + r.job_id;
  ASSERT_TRUE(wait_for([&] { return !read_text(job_dir + "/child.pid").empty(); }, 30.0)) << "the job did not start";
  const pid_t training = std::stoi(read_text(job_dir + "/child.pid"));
  ASSERT_FALSE(process_gone(training));
  write_text(job_dir + "/best.pt" + std::string(".tmp-4242"), "half a model");  // an interrupted write

  ::kill(trainer.pid(), SIGKILL);
  ASSERT_TRUE(wait_for([&] { return !trainer.running(); }, 10.0));
  const bool died = wait_for([&] { return process_gone(training); }, 10.0);
  if (!died) ::kill(training, SIGKILL);
  EXPECT_TRUE(died) << "the training process outlived the killed trainer";

  ASSERT_NO_FATAL_FAILURE(start_trainer(trainer, "trainer_b"));
  EXPECT_TRUE(wait_for([&] { return !fs::exists(job_dir + "/best.pt.tmp-4242"); }, 10.0))
      << "the restarted trainer left the temporary file";
  EXPECT_NE(read_text(work_ + "/trainer_b.log").find("removed 1 temporary file"), std::string::npos)
      << read_text(work_ + "/trainer_b.log");
}

}  // namespace
