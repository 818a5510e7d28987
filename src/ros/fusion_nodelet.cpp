// fusion: DepthEstimate stream -> core::StreamingFusion -> PointCloud2 (x y z rgb confidence views
// in the world frame, built with PCL). `cloud` carries the whole (bounded) map at ~publish_rate Hz
// (points that later estimates see through are removed from it, core/fusion.h),
// after the optional ~filter/ stages, `cloud_increment` the points each depth estimate adds, as
// soon as they exist. save_cloud writes .ply or .pcd (by extension) only inside ~save_dir.
// The thresholds can be tuned live (dynamic_reconfigure, cfg/Fusion.cfg). See docs/ros.md.
#include <map_msgs/OccupancyGridUpdate.h>
#include <nodelet/nodelet.h>
#include <pluginlib/class_list_macros.hpp>
#include <nav_msgs/OccupancyGrid.h>
#include <ros/ros.h>
#include <pcl_conversions/pcl_conversions.h>
#include <sensor_msgs/PointCloud2.h>
#include <torch/torch.h>

#include <boost/make_shared.hpp>
#include <filesystem>
#include <mutex>

#include "unsup_mvs/DepthEstimate.h"
#include "unsup_mvs/FusionConfig.h"
#include "unsup_mvs/ResetFusion.h"
#include "unsup_mvs/SaveCloud.h"
#include "unsup_mvs/core/device.h"
#include "unsup_mvs/core/fusion.h"
#include "unsup_mvs/io/atomic_file.h"
#include "unsup_mvs/io/cloud_file.h"
#include "unsup_mvs/io/cloud_filter.h"
#include "unsup_mvs/io/file_safety.h"
#include "unsup_mvs/io/occupancy_map.h"
#include "unsup_mvs/io/pcl_cloud.h"
#include "unsup_mvs/io/ros/ros_conversions.h"
#include "unsup_mvs/ros/nodelets.h"
#include "unsup_mvs/ros/live_settings.h"
#include "unsup_mvs/ros/params.h"
#include "unsup_mvs/ros/reconfigure.h"

namespace umvs_ros {

namespace {

// The cloud as PCL's FusedPoint (x y z rgb confidence views, io/pcl_cloud.h) through pcl_conversions,
// so that pcl_ros and pcl::fromROSMsg users read it directly.
sensor_msgs::PointCloud2 to_cloud_msg(const umvs::PointCloud& cloud, const std::string& frame, const ros::Time& stamp) {
  sensor_msgs::PointCloud2 msg;
  pcl::toROSMsg(umvs::to_pcl(cloud), msg);
  // Set after the conversion: PCL's header keeps microseconds only, and subscribers match the
  // stamp of the newest fused estimate exactly.
  msg.header.frame_id = frame;
  msg.header.stamp = stamp;
  return msg;
}

// The 2-D occupancy of the map's height band as nav_msgs/OccupancyGrid (REP 105: in the world
// frame, z up; cells row-major from the origin, 0 free, 100 occupied, -1 unknown).
nav_msgs::OccupancyGrid to_grid_msg(const umvs::OccupancyGrid2D& grid, const std::string& frame, const ros::Time& stamp,
                                    double z) {
  nav_msgs::OccupancyGrid msg;
  msg.header.frame_id = frame;
  msg.header.stamp = stamp;
  msg.info.map_load_time = stamp;
  msg.info.resolution = static_cast<float>(grid.resolution);
  msg.info.width = static_cast<uint32_t>(grid.width);
  msg.info.height = static_cast<uint32_t>(grid.height);
  msg.info.origin.position.x = grid.origin_x;
  msg.info.origin.position.y = grid.origin_y;
  msg.info.origin.position.z = z;
  msg.info.origin.orientation.w = 1.0;
  msg.data = grid.cells;
  return msg;
}

// The smallest window of `now` that differs from `before` (same size), as costmap_2d's static
// layer takes it on <map>_updates; empty (0 x 0) when nothing changed, so that its stamp still tells
// which estimates the grid includes.
map_msgs::OccupancyGridUpdate changed_window(const umvs::OccupancyGrid2D& before, const umvs::OccupancyGrid2D& now,
                                             const ros::Time& stamp, const std::string& frame) {
  map_msgs::OccupancyGridUpdate update;
  update.header.frame_id = frame;
  update.header.stamp = stamp;
  int x0 = now.width, y0 = now.height, x1 = -1, y1 = -1;
  for (int y = 0; y < now.height; ++y) {
    for (int x = 0; x < now.width; ++x) {
      const size_t i = static_cast<size_t>(y) * now.width + x;
      if (before.cells[i] == now.cells[i]) continue;
      x0 = std::min(x0, x);
      x1 = std::max(x1, x);
      y0 = std::min(y0, y);
      y1 = std::max(y1, y);
    }
  }
  if (x1 < 0) return update;
  update.x = x0;
  update.y = y0;
  update.width = static_cast<uint32_t>(x1 - x0 + 1);
  update.height = static_cast<uint32_t>(y1 - y0 + 1);
  update.data.clear();
  update.data.reserve(static_cast<size_t>(update.width) * update.height);
  for (int y = y0; y <= y1; ++y) {
    const auto row = now.cells.begin() + static_cast<std::ptrdiff_t>(y) * now.width;
    update.data.insert(update.data.end(), row + x0, row + x1 + 1);
  }
  return update;
}


}  // namespace

class FusionNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    try {
      node_ = fusion_node_config_from_ros(pnh);
      const FusionNodeConfig& c = node_;
      world_frame_ = c.world_frame;
      save_dir_ = c.save_dir;
      default_save_path_ = c.default_save_path;
      full_grid_period_ = c.full_grid_period;
      max_image_pixels_ = c.max_image_pixels;
      filters_ = c.filters;
      umvs::make_directories(save_dir_);
      fusion_ = std::make_unique<umvs::StreamingFusion>(c.fusion, c.window, static_cast<size_t>(c.max_points),
                                                        umvs::parse_device(c.device));
      if (c.occupancy) occupancy_ = std::make_unique<umvs::OccupancyMap>(c.occupancy_map);
    } catch (const std::exception& e) {
      NODELET_FATAL("fusion: invalid parameters: %s", e.what());
      throw;
    }
    cloud_pub_ = nh.advertise<sensor_msgs::PointCloud2>("cloud", 1, true);
    increment_pub_ = nh.advertise<sensor_msgs::PointCloud2>("cloud_increment", 5);
    if (occupancy_) {
      // A new subscriber gets the latched grid at once and a current whole one at the next publication.
      grid_pub_ = nh.advertise<nav_msgs::OccupancyGrid>(
          "occupancy_grid", 1,
          [this](const ros::SingleSubscriberPublisher&) {
            std::lock_guard<std::mutex> lock(mutex_);
            whole_grid_due_ = dirty_ = true;
          },
          ros::SubscriberStatusCallback(), ros::VoidConstPtr(), /*latch=*/true);
      grid_update_pub_ = nh.advertise<map_msgs::OccupancyGridUpdate>("occupancy_grid_updates", 10);
      save_map_srv_ = pnh.advertiseService("save_map", &FusionNodelet::onSaveMap, this);
    }
    estimate_sub_ = nh.subscribe("depth_estimate", 5, &FusionNodelet::onEstimate, this);
    save_srv_ = pnh.advertiseService("save_cloud", &FusionNodelet::onSave, this);
    reset_srv_ = pnh.advertiseService("reset", &FusionNodelet::onReset, this);
    timer_ = nh.createWallTimer(ros::WallDuration(1.0 / node_.publish_rate), &FusionNodelet::onTimer, this);
    reconfigure_ = std::make_unique<ReconfigureServer<unsup_mvs::FusionConfig>>(
        pnh, "fusion", to_reconfigure(node_), [this](const unsup_mvs::FusionConfig& r) { onReconfigure(r); });
    const auto& c = node_.fusion;
    NODELET_INFO("fusion: window %d, at most %d points, voxel %.3f m, a point needs %d agreeing views "
                 "(%.1f px, %.1f%% depth, confidence >= %.2f) and leaves when %d estimates in a row see through it "
                 "(0 = never), map published at %.1f Hz in '%s', clouds saved into %s",
                 node_.window, node_.max_points, c.voxel_size, c.min_agreeing_views, c.max_reprojection_px,
                 100 * c.max_relative_depth, c.min_confidence, c.clear_after_views, node_.publish_rate,
                 world_frame_.c_str(), save_dir_.c_str());
    if (filters_.any()) {
      NODELET_INFO("fusion: map filtered before publishing/saving: statistical mean_k %d (std x %.2f), radius %.4f m "
                   "(>= %d neighbours), voxel leaf %.4f m (0 = off)",
                   filters_.sor_mean_k, filters_.sor_std_mul, filters_.radius, filters_.radius_min_neighbors,
                   filters_.voxel_leaf);
    }
  }

  // New thresholds from dynamic_reconfigure: checked as at start-up, used from the next estimate.
  // Throws std::invalid_argument (naming the parameter) and changes nothing when they are invalid.
  void onReconfigure(const unsup_mvs::FusionConfig& request) {
    const FusionNodeConfig next = with_reconfigure(node_, request);
    next.validate();
    std::lock_guard<std::mutex> lock(mutex_);
    fusion_->set_config(next.fusion);
    if (occupancy_ && occupancy_->set_config(next.occupancy_map)) {
      NODELET_WARN("fusion: occupancy resolution now %.3f m: the occupancy map starts again, empty",
                   next.occupancy_map.resolution);
    }
    node_ = next;
    dirty_ = true;  // the grid's band may have changed
  }

  void onEstimate(const unsup_mvs::DepthEstimateConstPtr& msg) {
    umvs::FusionView view;
    try {
      if (!msg->world_frame.empty() && msg->world_frame != world_frame_) {
        throw std::invalid_argument("its pose is in '" + msg->world_frame + "', this node fuses in '" + world_frame_ + "'");
      }
      // Bounded before anything is allocated for them (see docs/reliability.md, resource bounds).
      umvs::check_image_msg(msg->depth, static_cast<uint64_t>(max_image_pixels_));
      umvs::check_image_msg(msg->confidence, static_cast<uint64_t>(max_image_pixels_));
      if (!msg->image.data.empty()) umvs::check_image_msg(msg->image, static_cast<uint64_t>(max_image_pixels_));
      view.id = msg->keyframe_id;
      view.depth = umvs::image_msg_to_float(msg->depth);
      view.confidence = umvs::image_msg_to_float(msg->confidence);
      view.camera = umvs::posed_camera_from_msgs(msg->camera_info, msg->pose, /*rectified=*/true);
      if (!msg->image.data.empty()) {
        view.color = umvs::image_msg_to_rgb8(msg->image);
        if (view.color.size(0) != view.depth.size(0) || view.color.size(1) != view.depth.size(1)) view.color = torch::Tensor();
      }
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(2.0, "fusion: depth estimate %u skipped: %s", msg->keyframe_id, e.what());
      return;
    }
    std::lock_guard<std::mutex> lock(mutex_);
    try {
      const auto t0 = ros::WallTime::now();
      const umvs::PointCloud added = fusion_->add(view);
      // The octree takes every confident pixel: free space needs the rays, not only agreed points.
      if (occupancy_) warn_about(occupancy_->integrate(view.depth, view.confidence, view.camera), view.camera);
      ++estimates_;
      if (!added.empty() && increment_pub_.getNumSubscribers() > 0) {
        increment_pub_.publish(to_cloud_msg(added, world_frame_, msg->header.stamp));
      }
      // The map is republished after every fused estimate, with its stamp: subscribers can tell
      // which estimates it includes even when the last one added no point.
      last_stamp_ = msg->header.stamp;
      dirty_ = true;
      NODELET_INFO_THROTTLE(2.0,
                            "fusion: depth estimate %u added %zu points in %.2f s; %zu points from %ld estimates, "
                            "%ld cleared as free space",
                            msg->keyframe_id, added.size(), (ros::WallTime::now() - t0).toSec(), fusion_->cloud().size(),
                            estimates_, static_cast<long>(fusion_->points_cleared()));
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(2.0, "fusion: depth estimate %u skipped: %s", msg->keyframe_id, e.what());
    }
  }

  // One warning when a problem starts (not one per depth map), one line when it ends.
  void warn_about(const umvs::OccupancyIntegration& r, const umvs::Camera& camera) {
    const auto& m = node_.occupancy_map;
    if (r.camera_outside && !camera_outside_) {
      const Eigen::Vector3d c = camera.center();
      NODELET_WARN("fusion: a camera at (%.1f, %.1f, %.1f) m is outside the occupancy map's extent [%.1f..%.1f] x "
                   "[%.1f..%.1f] x [%.1f..%.1f] m (~occupancy/extent): its depth maps are left out of the map (bad "
                   "pose, or a map that should be larger)", c.x(), c.y(), c.z(), m.min_x, m.max_x, m.min_y, m.max_y,
                   m.min_z, m.max_z);
    } else if (!r.camera_outside && camera_outside_) {
      NODELET_INFO("fusion: the camera is back inside the occupancy map's extent");
    }
    camera_outside_ = r.camera_outside;
    if (r.at_node_cap && !at_node_cap_) {
      NODELET_WARN("fusion: the occupancy map reached ~occupancy/max_nodes (%ld nodes): new space is no longer "
                   "mapped, known cells still update", static_cast<long>(m.max_nodes));
    }
    at_node_cap_ = at_node_cap_ || r.at_node_cap;
  }

  void onTimer(const ros::WallTimerEvent&) {
    umvs::PointCloud map;
    umvs::OccupancyGrid2D grid;
    bool whole_grid = false;
    double grid_z = 0.0;  // node_ is read under the lock: onReconfigure replaces it
    ros::Time stamp;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!dirty_) return;
      map = fusion_->cloud();
      if (occupancy_) grid = occupancy_->project(node_.grid_min_z, node_.grid_max_z);
      whole_grid = whole_grid_due_;
      whole_grid_due_ = false;
      grid_z = node_.grid_min_z;
      stamp = last_stamp_;
      dirty_ = false;
    }
    if (occupancy_) publish_grid(grid, stamp, grid_z, whole_grid);
    // Filtered outside the lock: estimates keep being fused meanwhile.
    try {
      cloud_pub_.publish(to_cloud_msg(filtered(map), world_frame_, stamp));
    } catch (const std::exception& e) {
      NODELET_ERROR_THROTTLE(2.0, "fusion: map not published: %s", e.what());
    }
  }

  // The map as published and saved: after the ~filter/ stages, if any.
  umvs::PointCloud filtered(const umvs::PointCloud& map) const {
    return filters_.any() ? umvs::filter_cloud(map, filters_) : map;
  }

  bool onSave(unsup_mvs::SaveCloud::Request& req, unsup_mvs::SaveCloud::Response& res) {
    const std::string requested = req.path.empty() ? default_save_path_ : req.path;
    std::string path;
    try {
      // Relative paths land in ~save_dir; nothing is written (or created) outside it.
      path = umvs::resolve_inside(save_dir_, requested);
    } catch (const std::exception& e) {
      res.success = false;
      res.message = std::string("refused: ") + e.what() + " (~save_dir); nothing written";
      NODELET_ERROR("fusion: save_cloud %s", res.message.c_str());
      return true;
    }
    try {
      umvs::cloud_file_format(path);  // .ply or .pcd, checked before anything is touched
    } catch (const std::exception& e) {
      res.success = false;
      res.message = std::string("refused: ") + e.what() + "; nothing written";
      NODELET_ERROR("fusion: save_cloud %s", res.message.c_str());
      return true;
    }
    umvs::PointCloud copy;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      copy = fusion_->cloud();
    }
    res.num_points = copy.size();
    if (copy.empty()) {
      res.success = false;
      res.message = "the cloud is empty; nothing written to " + path;
      NODELET_WARN("fusion: %s", res.message.c_str());
      return true;
    }
    try {
      copy = filtered(copy);
      res.num_points = copy.size();
      umvs::write_cloud(path, copy);
      res.success = true;
      res.message = "wrote " + std::to_string(copy.size()) + " points to " + path;
      NODELET_INFO("fusion: %s", res.message.c_str());
    } catch (const std::exception& e) {
      res.success = false;
      res.message = std::string("cannot save the cloud: ") + e.what();
      NODELET_ERROR("fusion: %s", res.message.c_str());
    }
    return true;
  }

  // ~save_map: the OctoMap as a binary .bt (octomap's tools, octomap_server), only inside ~save_dir,
  // written atomically. Answers num_points = occupied leaves.
  bool onSaveMap(unsup_mvs::SaveCloud::Request& req, unsup_mvs::SaveCloud::Response& res) {
    const std::string requested = req.path.empty() ? std::string("unsup_mvs_map.bt") : req.path;
    try {
      const std::string path = umvs::resolve_inside(save_dir_, requested);
      if (std::filesystem::path(path).extension() != ".bt") {
        throw std::invalid_argument("'" + requested + "' is not a .bt file (OctoMap's binary format)");
      }
      std::lock_guard<std::mutex> lock(mutex_);
      occupancy_->save(path);
      res.num_points = occupancy_->occupied_leaves();
      res.success = true;
      res.message = "wrote " + std::to_string(res.num_points) + " occupied leaves to " + path;
      NODELET_INFO("fusion: %s", res.message.c_str());
    } catch (const std::exception& e) {
      res.success = false;
      res.message = std::string("refused: ") + e.what() + "; nothing written";
      NODELET_ERROR("fusion: save_map %s", res.message.c_str());
    }
    return true;
  }

  // The whole grid when it is new, asked for (a new subscriber) or its period is due, else the
  // window that changed since the last publication.
  void publish_grid(const umvs::OccupancyGrid2D& grid, const ros::Time& stamp, double z, bool whole) {
    const auto now = ros::WallTime::now();
    const bool same_shape = published_grid_.width == grid.width && published_grid_.height == grid.height &&
                            published_grid_.resolution == grid.resolution && published_grid_.origin_x == grid.origin_x &&
                            published_grid_.origin_y == grid.origin_y && published_grid_z_ == z;
    if (whole || !same_shape || (now - last_full_grid_).toSec() >= full_grid_period_) {
      grid_pub_.publish(to_grid_msg(grid, world_frame_, stamp, z));
      last_full_grid_ = now;
    } else {
      grid_update_pub_.publish(changed_window(published_grid_, grid, stamp, world_frame_));
    }
    published_grid_ = grid;
    published_grid_z_ = z;
  }

  bool onReset(unsup_mvs::ResetFusion::Request&, unsup_mvs::ResetFusion::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    const size_t before = fusion_->cloud().size();
    fusion_->reset();
    if (occupancy_) occupancy_->clear();
    estimates_ = 0;
    dirty_ = true;  // publish the empty map once
    res.success = true;
    res.message = "cleared " + std::to_string(before) + " points";
    NODELET_INFO("fusion: %s", res.message.c_str());
    return true;
  }

  FusionNodeConfig node_;  // as started, then as reconfigured (changed only by onReconfigure)
  std::string world_frame_, save_dir_, default_save_path_;
  // Depth maps are a quarter of the network input; 2048 x 2048 keeps the window (about 21 bytes per
  // pixel per estimate, docs/fusion.md) under 1 GB at the default window of 8.
  int max_image_pixels_ = FusionNodeConfig{}.max_image_pixels;
  umvs::CloudFilterConfig filters_;
  std::mutex mutex_;
  std::unique_ptr<umvs::StreamingFusion> fusion_;
  std::unique_ptr<umvs::OccupancyMap> occupancy_;  // null when ~occupancy/enabled is false
  long estimates_ = 0;
  bool dirty_ = false;
  ros::Time last_stamp_;
  ros::Publisher cloud_pub_, increment_pub_, grid_pub_, grid_update_pub_;
  // The grid as last published (timer thread only), when it went out whole, and the warnings' states.
  umvs::OccupancyGrid2D published_grid_;
  double published_grid_z_ = 0.0, full_grid_period_ = FusionNodeConfig{}.full_grid_period;
  ros::WallTime last_full_grid_;
  bool camera_outside_ = false, at_node_cap_ = false;
  bool whole_grid_due_ = false;  // under mutex_: a subscriber connected
  ros::Subscriber estimate_sub_;
  ros::ServiceServer save_srv_, reset_srv_, save_map_srv_;
  ros::WallTimer timer_;
  std::unique_ptr<ReconfigureServer<unsup_mvs::FusionConfig>> reconfigure_;
};

boost::shared_ptr<nodelet::Nodelet> make_fusion_nodelet() { return boost::make_shared<FusionNodelet>(); }

}  // namespace umvs_ros

PLUGINLIB_EXPORT_CLASS(umvs_ros::FusionNodelet, nodelet::Nodelet)
