// What `umvs fuse` reads and runs (io/fusion_input.h), as library calls.
#include <gtest/gtest.h>
#include <torch/types.h>

#include <sstream>

#include "test_util.h"
#include "unsup_mvs/io/fusion_input.h"

namespace umvs {
namespace {

TEST(FusionInput, ExactDepthOfARoomFusesIntoOneCloud) {
  const std::string data = test::write_room("fusion_input_room", 5, true, 64, 48, 5);
  const FusionInput input = load_fusion_input(data + "/depth_gt", data);
  ASSERT_EQ(input.views.size(), 5u);
  EXPECT_EQ(input.depth_dir, data + "/depth_gt");
  for (size_t i = 0; i < input.views.size(); ++i) {
    EXPECT_EQ(input.views[i].camera.width, 64);
    EXPECT_EQ(input.views[i].color.size(2), 3);
    EXPECT_FALSE(input.sources[i].empty());
    for (int s : input.sources[i]) EXPECT_NE(s, static_cast<int>(i));
  }
  FusionConfig config;
  config.min_agreeing_views = 2;
  std::ostringstream log;
  const PointCloud batch = fuse_input(input, config, false, 0, torch::kCPU, log);
  EXPECT_GT(batch.size(), size_t{64 * 48});  // exact depth: most pixels of most views agree
  EXPECT_NE(log.str().find("sources"), std::string::npos) << log.str();
  std::ostringstream stream_log;
  const PointCloud streamed = fuse_input(input, config, true, 5, torch::kCPU, stream_log);
  EXPECT_GT(streamed.size(), batch.size() / 4);
  EXPECT_NE(stream_log.str().find("new points"), std::string::npos) << stream_log.str();

  const FusionInput two = load_fusion_input(data + "/depth_gt", data, {0, 1});
  ASSERT_EQ(two.views.size(), 2u);
  for (const auto& s : two.sources) EXPECT_LE(s.size(), 1u);  // only the views loaded
}

TEST(FusionInput, NamesWhatIsMissing) {
  const std::string data = test::write_room("fusion_input_missing", 5, true, 32, 24, 3);
  try {
    load_fusion_input(data + "/depth_gt", "");
    FAIL() << "a depth folder without --data accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("has no cams/: give --data"), std::string::npos) << e.what();
  }
  EXPECT_THROW(load_fusion_input(data + "/nothing", data), std::invalid_argument);
}

TEST(FusionInput, BoxesAreSixOrderedNumbers) {
  const BoundingBox box = parse_box("0,0,0,1,2,3", "bbox");
  EXPECT_EQ(box[4], 2.0);
  PointCloud cloud;
  cloud.points = {{0.5f, 1.0f, 1.0f}, {0.5f, 2.5f, 1.0f}, {1.0f, 2.0f, 3.0f}};
  EXPECT_EQ(points_inside(cloud, box), 2u);
  for (const char* bad : {"0,0,0,1,2", "0,0,0,1,2,x", "1,0,0,1,2,3", "0,0,0,1,2,nan"}) {
    try {
      parse_box(bad, "bbox");
      ADD_FAILURE() << bad << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("--bbox needs xmin,ymin,zmin,xmax,ymax,zmax"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace umvs
