// inference: KeyframeSet -> MVSNet -> DepthEstimate (+ depth and confidence images). Thin around
// core::DepthEstimator. The network runs on a worker thread; when it is busy only the newest
// keyframe set waits (latest wins). The network resolution and plane count can be tuned live
// (dynamic_reconfigure, cfg/Inference.cfg). See docs/ros.md for topics and parameters.
#include <diagnostic_msgs/DiagnosticArray.h>
#include <image_transport/image_transport.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <ros/callback_queue.h>
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <torch/torch.h>

#include <atomic>
#include <boost/make_shared.hpp>
#include <chrono>
#include <condition_variable>
#include <future>
#include <mutex>
#include <optional>
#include <thread>

#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/InferenceConfig.h"
#include "unsup_mvs/KeyframeSet.h"
#include "unsup_mvs/ReloadModel.h"
#include "unsup_mvs/core/depth_estimator.h"
#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/latest_slot.h"
#include "unsup_mvs/core/timing_log.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/io/checkpoint.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/input_limits.h"
#include "unsup_mvs/io/model_check.h"
#include "unsup_mvs/io/plane_count.h"
#include "unsup_mvs/ros/depth_camera_outputs.h"
#include "unsup_mvs/ros/nodelets.h"
#include "unsup_mvs/ros/online_pose_refinement.h"
#include "unsup_mvs/ros/live_settings.h"
#include "unsup_mvs/ros/params.h"
#include "unsup_mvs/ros/reconfigure.h"

namespace umvs_ros {

namespace {

bool same_settings(const umvs::DepthEstimatorConfig& a, const umvs::DepthEstimatorConfig& b) {
  return a.max_width == b.max_width && a.max_height == b.max_height && a.num_depth == b.num_depth;
}

// An estimator serving `model` with `config`; refused (std::invalid_argument) when it would run
// more than max_planes depth planes. With num_depth 0 the count is set per keyframe set
// (fitPlanesToInput) and checked then.
std::unique_ptr<umvs::DepthEstimator> make_estimator(const umvs::MvsNet& model, const torch::Device& device,
                                                     const umvs::DepthEstimatorConfig& config, int max_planes) {
  if (config.num_depth > max_planes) {
    throw std::invalid_argument("it would run with " + std::to_string(config.num_depth) +
                                " depth planes, more than ~max_planes " + std::to_string(max_planes));
  }
  return std::make_unique<umvs::DepthEstimator>(model, device, config);
}

// What ~num_depth asks for, in words.
std::string planes_description(int num_depth) {
  return num_depth > 0 ? std::to_string(num_depth) + " depth planes"
                       : "depth planes following the network input (128 at 640 wide, scaled with the width)";
}

// The online pose refinement the node's settings ask for (nullptr when off).
std::unique_ptr<OnlinePoseRefinement> make_pose_refiner(const InferenceNodeConfig& c) {
  if (c.pose_refinement_deg <= 0) return nullptr;
  return std::make_unique<OnlinePoseRefinement>(
      umvs::KeyframePoseRefinerConfig{c.pose_refinement_deg, static_cast<size_t>(c.pose_refinement_keyframes)});
}

}  // namespace

class InferenceNodelet : public nodelet::Nodelet {
 public:
  ~InferenceNodelet() override {
    reload_spinner_.reset();  // no reload callback runs past this point
    if (pending_) pending_->close();
    if (worker_.joinable()) worker_.join();
  }

 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      node_ = inference_node_config_from_ros(pnh);
      const InferenceNodeConfig& c = node_;
      device_ = umvs::parse_device(c.device);
      threads_ = c.threads;
      config_ = c.estimator;
      rectified_ = c.rectified;
      checkpoint_ = c.checkpoint;
      max_image_pixels_ = c.max_image_pixels;
      depth_camera_min_confidence_ = c.depth_camera_min_confidence;
      max_views_ = c.max_views;
      max_planes_ = c.max_planes;
      max_checkpoint_bytes_ = static_cast<uint64_t>(c.max_checkpoint_mb) << 20;
      reload_timeout_ = c.reload_timeout;
      pose_refiner_ = make_pose_refiner(c);
      pending_ = std::make_unique<umvs::LatestSlot<unsup_mvs::KeyframeSetConstPtr>>(static_cast<size_t>(c.queue_size));
    } catch (const std::exception& e) {
      NODELET_FATAL("inference: invalid parameters: %s", e.what());
      throw;
    }
    umvs::configure_threads(threads_);

    std::string message;
    if (checkpoint_.empty()) {
      NODELET_ERROR("inference: no ~checkpoint parameter; load one with the reload_model service");
    } else if (!installModel(checkpoint_, &message)) {
      NODELET_ERROR("inference: %s; load another one with the reload_model service", message.c_str());
    } else {
      NODELET_INFO("inference: %s", message.c_str());
    }

    it_ = std::make_unique<image_transport::ImageTransport>(nh);
    auto connect = [this](const ros::SingleSubscriberPublisher&) { updateSubscription(); };
    auto it_connect = [this](const image_transport::SingleSubscriberPublisher&) { updateSubscription(); };
    {
      std::lock_guard<std::mutex> lock(connect_mutex_);
      estimate_pub_ = nh.advertise<unsup_mvs::DepthEstimate>("depth_estimate", 2, connect, connect);
      depth_pub_ = it_->advertise("depth", 2, it_connect, it_connect);
      confidence_pub_ = it_->advertise("confidence", 2, it_connect, it_connect);
      // The depth map as a standard depth camera (REP 118) with the reference's colour beside it:
      // what depth_image_proc, rtabmap and other ROS consumers take.
      depth_camera_ = std::make_unique<DepthCameraOutputs>(*it_, it_connect, connect);
    }
    diagnostics_pub_ = nh.advertise<diagnostic_msgs::DiagnosticArray>("/diagnostics", 5);
    // reload_model has its own queue and thread: a slow or stuck load never holds up the keyframe
    // callbacks (the standalone node spins one thread), so depth maps keep coming meanwhile.
    ros::AdvertiseServiceOptions reload_options = ros::AdvertiseServiceOptions::create<unsup_mvs::ReloadModel>(
        "reload_model",
        [this](unsup_mvs::ReloadModel::Request& req, unsup_mvs::ReloadModel::Response& res) { return onReload(req, res); },
        ros::VoidConstPtr(), &reload_queue_);
    reload_srv_ = pnh.advertiseService(reload_options);
    // What a run did, in one line (scripts/demo.sh prints it at the end).
    stats_srv_ = pnh.advertiseService<std_srvs::Trigger::Request, std_srvs::Trigger::Response>(
        "stats", [this](std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
          res.success = true;
          res.message = statsLine();
          return true;
        });
    reload_spinner_ = std::make_unique<ros::AsyncSpinner>(1, &reload_queue_);
    reload_spinner_->start();
    worker_ = std::thread(&InferenceNodelet::work, this);
    reconfigure_ = std::make_unique<ReconfigureServer<unsup_mvs::InferenceConfig>>(
        pnh, "inference", to_reconfigure(node_), [this](const unsup_mvs::InferenceConfig& r) { onReconfigure(r); });
  }

  // A new resolution, plane count or pose refinement limit from dynamic_reconfigure: checked as at start-up, then the
  // served model is rebuilt with it for the next keyframe set (after the one running, if any).
  // Throws std::invalid_argument (naming the parameter) and changes nothing when invalid.
  void onReconfigure(const unsup_mvs::InferenceConfig& request) {
    InferenceNodeConfig next = with_reconfigure(node_, request);
    next.validate();
    std::lock_guard<std::mutex> lock(model_mutex_);
    if (estimator_) estimator_ = make_estimator(estimator_->model(), device_, next.estimator, max_planes_);
    // A new search limit starts afresh: pairs measured with the old one are measured again.
    if (next.pose_refinement_deg != node_.pose_refinement_deg) pose_refiner_ = make_pose_refiner(next);
    config_ = next.estimator;
    depth_camera_min_confidence_ = next.depth_camera_min_confidence;
    node_ = next;
  }

  // Lazy subscription: keyframe sets are only received while someone listens to an output.
  void updateSubscription() {
    std::lock_guard<std::mutex> lock(connect_mutex_);
    const bool wanted = estimate_pub_.getNumSubscribers() > 0 || depth_pub_.getNumSubscribers() > 0 ||
                        confidence_pub_.getNumSubscribers() > 0 || (depth_camera_ && depth_camera_->has_subscribers());
    if (wanted && !keyframes_sub_) {
      keyframes_sub_ = getNodeHandle().subscribe("keyframes", static_cast<uint32_t>(pending_->capacity()),
                                               &InferenceNodelet::onKeyframes, this);
    } else if (!wanted && keyframes_sub_) {
      keyframes_sub_.shutdown();
    }
  }

  // Beyond ~queue_size waiting sets the oldest is stale: dropped and counted.
  void onKeyframes(const unsup_mvs::KeyframeSetConstPtr& msg) { pending_->put(msg); }

  void work() {
    while (true) {
      const std::optional<unsup_mvs::KeyframeSetConstPtr> next = pending_->take();
      if (!next) return;  // closed: the nodelet is going away
      const unsup_mvs::KeyframeSetConstPtr& set = *next;
      try {
        process(*set);
      } catch (const std::exception& e) {
        ++failed_;
        NODELET_ERROR_THROTTLE(2.0, "inference: keyframe set %u skipped: %s", set->reference_id, e.what());
      }
    }
  }

  void process(const unsup_mvs::KeyframeSet& set) {
    const auto t0 = ros::WallTime::now();
    if (set.source_images.size() != set.source_infos.size() || set.source_images.size() != set.source_poses.size() ||
        set.source_images.empty()) {
      throw std::invalid_argument("needs as many source images, camera_infos and poses (>= 1), got " +
                                  std::to_string(set.source_images.size()) + ", " + std::to_string(set.source_infos.size()) +
                                  ", " + std::to_string(set.source_poses.size()));
    }
    if (set.source_images.size() + 1 > static_cast<size_t>(max_views_)) {
      throw std::invalid_argument(std::to_string(set.source_images.size() + 1) + " views, more than ~max_views " +
                                  std::to_string(max_views_));
    }
    if (!(set.depth_min > 0 && set.depth_max > set.depth_min)) {
      throw std::invalid_argument("impossible depth range " + std::to_string(set.depth_min) + " - " +
                                  std::to_string(set.depth_max));
    }
    std::vector<umvs::ViewInput> views;
    const auto max_pixels = static_cast<uint64_t>(max_image_pixels_);
    auto add_view = [&](const sensor_msgs::Image& image, const sensor_msgs::CameraInfo& info,
                        const geometry_msgs::Pose& pose, const std::string& name) {
      umvs::PosedImage posed = umvs::checked_posed_image_from_msgs(image, info, pose, rectified_, max_pixels, name);
      views.push_back({std::move(posed.image), posed.camera});
    };
    add_view(set.reference_image, set.reference_info, set.reference_pose, "reference");
    for (size_t i = 0; i < set.source_images.size(); ++i) {
      add_view(set.source_images[i], set.source_infos[i], set.source_poses[i],
               "source " + std::to_string(set.source_ids.size() > i ? set.source_ids[i] : i));
    }
    umvs::DepthMap map;
    int planes = 0;
    std::string served;
    std::string refinement = "off";
    // The reference's pose as the depth map was made and its optical frame: with refined poses the
    // turned camera, in its own frame that tf places there too, so that fusion, the occupancy map
    // and the depth camera's consumers all put the map where it agrees with the other keyframes.
    geometry_msgs::Pose pose = set.reference_pose;
    std_msgs::Header header = set.reference_image.header;
    {
      std::lock_guard<std::mutex> lock(model_mutex_);
      if (!estimator_) throw std::runtime_error("no model loaded (set ~checkpoint or call reload_model)");
      fitPlanesToInput(views.front());
      planes = estimator_->num_depth();
      const bool refined = pose_refiner_ && pose_refiner_->correct(*estimator_, set, &views);
      if (pose_refiner_) refinement = pose_refiner_->summary();
      map = estimator_->estimate(views, set.depth_min, set.depth_max);
      served = checkpoint_;
      if (refined) {
        pose = umvs::matrix_to_pose(map.camera.T_cam_world.inverse());
        pose_refiner_->place(set.header.frame_id, pose, &header);
      }
    }
    unsup_mvs::DepthEstimate out;
    out.header = header;
    out.keyframe_id = set.reference_id;
    out.depth = umvs::float_to_image_msg(map.depth, header);
    out.confidence = umvs::float_to_image_msg(map.confidence, header);
    out.image = umvs::rgb8_to_image_msg(map.color, header);
    out.camera_info = umvs::camera_info_from_camera(map.camera, header);
    out.world_frame = set.header.frame_id;
    out.pose = pose;
    out.depth_min = set.depth_min;
    out.depth_max = set.depth_max;
    out.inference_seconds = static_cast<float>(map.seconds);
    estimate_pub_.publish(out);
    if (depth_pub_.getNumSubscribers() > 0) depth_pub_.publish(out.depth);
    if (confidence_pub_.getNumSubscribers() > 0) confidence_pub_.publish(out.confidence);
    depth_camera_->publish(map.depth, map.confidence, depth_camera_min_confidence_, out.image, out.camera_info);

    const double total = (ros::WallTime::now() - t0).toSec();
    const double latency = (ros::Time::now() - header.stamp).toSec();
    timings_.add(total, latency);
    NODELET_INFO_THROTTLE(2.0, "inference: keyframe %u: %dx%d depth map in %.2f s (network %.2f s%s), %.2f s after the "
                          "image; %ld done, %ld stale sets dropped, %ld failed",
                          set.reference_id, map.camera.width, map.camera.height, total, map.seconds,
                          map.per_source_passes ? ", each source also alone" : "", latency, static_cast<long>(timings_.count()),
                          static_cast<long>(pending_->dropped()), failed_.load());
    for (size_t s = 0; s < map.source_turns.size(); ++s) {
      const umvs::SourceTurn& turn = map.source_turns[s];
      if (!turn.kept) continue;
      NODELET_DEBUG("inference: keyframe %u: source %zu turned by (%.1f, %.1f, %.1f) deg (warp %.0f %% better)",
                    set.reference_id, s + 1, turn.degrees.x(), turn.degrees.y(), turn.degrees.z(),
                    100.0 * turn.full_size_gain);
    }
    publishDiagnostics(total, map.seconds, latency, planes, served, refinement);
  }

  // With ~num_depth 0 the planes follow the network input's width as in `umvs infer` (MVSNet learnt a
  // plane spacing per pixel: 64 planes at 320 wide beat 128 there, 128 beat 64 at 640 wide; a sweep2d
  // network sweeps its own). The estimator is rebuilt when another count is due. Under model_mutex_.
  void fitPlanesToInput(const umvs::ViewInput& reference) {
    if (config_.num_depth > 0) return;
    const umvs::NetworkResize plan = umvs::plan_network_resize(reference.camera.width, reference.camera.height,
                                                               config_.max_width, config_.max_height);
    const int planes =
        umvs::default_plane_count(estimator_->model()->config(), umvs::first_pass_size(config_, plan.width));
    if (estimator_->config().num_depth == planes) return;
    umvs::DepthEstimatorConfig fitted = config_;
    fitted.num_depth = planes;
    estimator_ = make_estimator(estimator_->model(), device_, fitted, max_planes_);
    NODELET_INFO("inference: %d depth planes for a %dx%d network input%s", planes, plan.width, plan.height,
                 config_.fine.enabled() ? " (the first pass's, then a fine pass)" : "");
  }

  std::string statsLine() const {
    return std::to_string(timings_.count()) + " keyframe sets processed, " + std::to_string(pending_->dropped()) +
           " dropped (stale), " + std::to_string(failed_.load()) + " failed; " +
           timings_.summary("image to depth map", "after the image's stamp");
  }

  void publishDiagnostics(double total, double network, double latency, int planes, const std::string& served,
                          const std::string& refinement) {
    diagnostic_msgs::DiagnosticArray array;
    array.header.stamp = ros::Time::now();
    diagnostic_msgs::DiagnosticStatus status;
    status.level = diagnostic_msgs::DiagnosticStatus::OK;
    status.name = "unsup_mvs: " + getName();
    status.hardware_id = device_.str();
    status.message = "depth map in " + std::to_string(total) + " s";
    const std::pair<const char*, std::string> values[] = {
        {"processed", std::to_string(timings_.count())}, {"dropped_stale", std::to_string(pending_->dropped())},
        {"failed", std::to_string(failed_.load())}, {"last_total_s", std::to_string(total)},
        {"last_network_s", std::to_string(network)}, {"last_latency_s", std::to_string(latency)},
        {"total_p50_p90", timings_.summary("image to depth map", "after the image's stamp")},
        {"depth_planes", std::to_string(planes)}, {"checkpoint", served}, {"pose_refinement", refinement}};
    for (const auto& [key, value] : values) {
      diagnostic_msgs::KeyValue kv;
      kv.key = key;
      kv.value = value;
      status.values.push_back(kv);
    }
    array.status.push_back(status);
    diagnostics_pub_.publish(array);
  }

  // A checked model, ready to serve.
  struct Candidate {
    std::unique_ptr<umvs::DepthEstimator> estimator;
    std::string description;
  };

  // Loads `path` and checks it: a regular file of at most max_bytes, loads, at most max_planes
  // planes, a forward pass with finite output. Throws std::runtime_error saying why not. Touches
  // no member: it may outlive the nodelet on an abandoned reload.
  static Candidate loadCandidate(const std::string& path, const torch::Device& device,
                                 const umvs::DepthEstimatorConfig& config, uint64_t max_bytes, int max_planes) {
    umvs::checked_file_size(path, max_bytes, "checkpoint");  // before reading: no FIFO, device or huge file
    umvs::LoadedModel loaded = umvs::load_model(path, device);
    Candidate c;
    c.estimator = make_estimator(loaded.model, device, config, max_planes);
    umvs::check_model_forward(loaded.model, device);
    c.description = "loaded " + path + " (" + loaded.format + ", " + loaded.model->config().to_string() + "), " +
                    planes_description(config.num_depth) + " on " + device.str() + ", " +
                    std::to_string(torch::get_num_threads()) + " threads";
    return c;
  }

  void install(Candidate candidate, const std::string& path, std::string* message) {
    std::lock_guard<std::mutex> lock(model_mutex_);
    if (!same_settings(candidate.estimator->config(), config_)) {  // reconfigured while it loaded
      candidate.estimator = make_estimator(candidate.estimator->model(), device_, config_, max_planes_);
    }
    estimator_ = std::move(candidate.estimator);
    checkpoint_ = path;
    *message = candidate.description;
  }

  // Loads, checks and swaps in `path` on this thread (startup). On failure the current model
  // stays and *message says why.
  bool installModel(const std::string& path, std::string* message) {
    try {
      install(loadCandidate(path, device_, config_, max_checkpoint_bytes_, max_planes_), path, message);
      return true;
    } catch (const std::exception& e) {
      *message = "model " + path + " refused: " + e.what();
      return false;
    }
  }

  // The load runs on its own thread; this callback waits at most ~reload_timeout for it. A load
  // that takes longer is abandoned (its result is dropped; its thread finishes on its own) and
  // no further reload starts until it has.
  bool onReload(unsup_mvs::ReloadModel::Request& req, unsup_mvs::ReloadModel::Response& res) {
    res.success = false;
    const std::string path = req.checkpoint;
    if (loads_running_->load() > 0) {
      res.message = "model " + path + " refused: an earlier reload is still loading; try again later";
    } else {
      auto result = std::make_shared<std::promise<Candidate>>();
      std::future<Candidate> done = result->get_future();
      umvs::DepthEstimatorConfig config;
      {
        std::lock_guard<std::mutex> lock(model_mutex_);  // config_ may be reconfigured meanwhile
        config = config_;
      }
      ++*loads_running_;
      std::thread([result, path, device = device_, config, max_bytes = max_checkpoint_bytes_,
                   max_planes = max_planes_, running = loads_running_] {
        Candidate candidate;
        std::exception_ptr error;
        try {
          candidate = loadCandidate(path, device, config, max_bytes, max_planes);
        } catch (...) {
          error = std::current_exception();
        }
        // Done before the answer: a reload requested right after this one is answered must not
        // find it still running.
        --*running;
        if (error) result->set_exception(error);
        else result->set_value(std::move(candidate));
      }).detach();
      if (done.wait_for(std::chrono::duration<double>(reload_timeout_)) != std::future_status::ready) {
        res.message = "model " + path + " refused: loading it took longer than ~reload_timeout (" +
                      std::to_string(reload_timeout_) + " s)";
      } else {
        try {
          install(done.get(), path, &res.message);
          res.success = true;
        } catch (const std::exception& e) {
          res.message = "model " + path + " refused: " + e.what();
        }
      }
    }
    if (res.success) {
      NODELET_INFO("inference: %s", res.message.c_str());
    } else {
      std::unique_lock<std::mutex> lock(model_mutex_);
      const std::string kept = estimator_ ? "the model from " + checkpoint_ : "no model";
      lock.unlock();
      NODELET_ERROR("inference: %s; keeping %s", res.message.c_str(), kept.c_str());
    }
    return true;
  }

  torch::Device device_{torch::kCPU};
  int threads_ = 0;
  bool rectified_ = false;
  std::atomic<double> depth_camera_min_confidence_{0.5};  // set by reconfigure, read by the worker
  InferenceNodeConfig node_;        // as started, then as reconfigured (changed only by onReconfigure)
  umvs::DepthEstimatorConfig config_;  // node_.estimator, read by reloads (under model_mutex_)
  std::string checkpoint_;
  std::mutex model_mutex_;
  std::unique_ptr<umvs::DepthEstimator> estimator_;
  std::unique_ptr<OnlinePoseRefinement> pose_refiner_;  // ~pose_refinement_deg > 0 (else null); under model_mutex_

  // resource bounds (docs/reliability.md)
  int max_image_pixels_ = kDefaultMaxImagePixels, max_views_ = 16, max_planes_ = 256;
  uint64_t max_checkpoint_bytes_ = 256ull << 20;
  double reload_timeout_ = 60.0;
  ros::CallbackQueue reload_queue_;
  std::unique_ptr<ros::AsyncSpinner> reload_spinner_;
  std::shared_ptr<std::atomic<int>> loads_running_ = std::make_shared<std::atomic<int>>(0);

  // Sets waiting for the network (~queue_size; counts the stale ones dropped); made in onInit.
  std::unique_ptr<umvs::LatestSlot<unsup_mvs::KeyframeSetConstPtr>> pending_;
  std::thread worker_;
  std::atomic<long> failed_{0};
  umvs::TimingLog timings_;  // per processed set (the latest 1000): image to depth map, and since the image's stamp
  ros::ServiceServer stats_srv_;

  std::mutex connect_mutex_;
  std::unique_ptr<image_transport::ImageTransport> it_;
  ros::Publisher estimate_pub_, diagnostics_pub_;
  image_transport::Publisher depth_pub_, confidence_pub_;
  std::unique_ptr<DepthCameraOutputs> depth_camera_;
  ros::Subscriber keyframes_sub_;
  ros::ServiceServer reload_srv_;
  std::unique_ptr<ReconfigureServer<unsup_mvs::InferenceConfig>> reconfigure_;
};

boost::shared_ptr<nodelet::Nodelet> make_inference_nodelet() { return boost::make_shared<InferenceNodelet>(); }

}  // namespace umvs_ros

PLUGINLIB_EXPORT_CLASS(umvs_ros::InferenceNodelet, nodelet::Nodelet)
