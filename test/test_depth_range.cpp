#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include "unsup_mvs/core/depth_range.h"

namespace umvs {
namespace {

// n depths evenly spaced over [lo, hi].
std::vector<float> even_depths(double lo, double hi, int n = 1000) {
  std::vector<float> d;
  for (int i = 0; i < n; ++i) d.push_back(static_cast<float>(lo + (hi - lo) * i / (n - 1)));
  return d;
}

// What depth_range_from_samples makes of even_depths(lo, hi, 1000): the samples at index
// round(0.02 * 999) = 20 and round(0.98 * 999) = 979, widened by 20 %.
double even_near(double lo, double hi) { return (lo + (hi - lo) * 20 / 999) / 1.2; }
double even_far(double lo, double hi) { return (lo + (hi - lo) * 979 / 999) * 1.2; }

TEST(DepthRange, ConfiguredBoundsBeforeAnyEstimate) {
  const DepthRangeTracker t(0.3, 10.0);
  EXPECT_FALSE(t.has_estimate());
  EXPECT_DOUBLE_EQ(t.range().near, 0.3);
  EXPECT_DOUBLE_EQ(t.range().far, 10.0);
  EXPECT_DOUBLE_EQ(t.bounds().near, 0.3);
  EXPECT_DOUBLE_EQ(t.bounds().far, 10.0);
}

TEST(DepthRange, RefusesImpossibleBounds) {
  const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(DepthRangeTracker(0.0, 1.0), std::invalid_argument);
  EXPECT_THROW(DepthRangeTracker(-1.0, 2.0), std::invalid_argument);
  EXPECT_THROW(DepthRangeTracker(2.0, 1.0), std::invalid_argument);
  EXPECT_THROW(DepthRangeTracker(1.0, 1.0), std::invalid_argument);
  EXPECT_THROW(DepthRangeTracker(1.0, inf), std::invalid_argument);
  EXPECT_THROW(DepthRangeTracker(nan, 2.0), std::invalid_argument);
}

TEST(DepthRange, EstimateInsideBoundsIsUsedAsIs) {
  DepthRangeTracker t(0.3, 10.0);
  EXPECT_TRUE(t.update_from_samples(even_depths(2.0, 4.0)));
  ASSERT_TRUE(t.has_estimate());
  EXPECT_NEAR(t.range().near, even_near(2.0, 4.0), 1e-6);  // 1.70003
  EXPECT_NEAR(t.range().far, even_far(2.0, 4.0), 1e-6);    // 4.75195
  EXPECT_NEAR(t.range().near, 1.700033, 1e-6);
  EXPECT_NEAR(t.range().far, 4.751952, 1e-6);
  // The bounds do not move.
  EXPECT_DOUBLE_EQ(t.bounds().near, 0.3);
  EXPECT_DOUBLE_EQ(t.bounds().far, 10.0);
}

TEST(DepthRange, EstimateIsClampedToTheBounds) {
  DepthRangeTracker t(1.0, 4.0);
  // 0.5 .. 8 m widens to ~0.44 .. ~9.4 m: both ends clamped.
  EXPECT_TRUE(t.update_from_samples(even_depths(0.5, 8.0)));
  ASSERT_TRUE(t.has_estimate());
  EXPECT_DOUBLE_EQ(t.range().near, 1.0);
  EXPECT_DOUBLE_EQ(t.range().far, 4.0);
  // Only the far end outside: near from the estimate, far clamped.
  EXPECT_TRUE(t.update_from_samples(even_depths(2.0, 5.0)));
  EXPECT_NEAR(t.range().near, even_near(2.0, 5.0), 1e-6);
  EXPECT_DOUBLE_EQ(t.range().far, 4.0);
  // Only the near end outside.
  EXPECT_TRUE(t.update(0.2, 3.0));
  EXPECT_DOUBLE_EQ(t.range().near, 1.0);
  EXPECT_DOUBLE_EQ(t.range().far, 3.0);
}

TEST(DepthRange, TooFewUsableDepthsKeepThePreviousRange) {
  DepthRangeTracker t(0.3, 10.0);
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  // Before any estimate: still the bounds.
  EXPECT_FALSE(t.update_from_samples({}));
  EXPECT_FALSE(t.update_from_samples(std::vector<float>(5000, static_cast<float>(nan))));
  EXPECT_FALSE(t.has_estimate());
  EXPECT_DOUBLE_EQ(t.range().near, 0.3);
  EXPECT_DOUBLE_EQ(t.range().far, 10.0);

  ASSERT_TRUE(t.update_from_samples(even_depths(2.0, 4.0)));
  // 99 usable depths (at least 100 needed) among NaN, infinite, zero and negative ones.
  std::vector<float> bad = even_depths(5.0, 6.0, 99);
  bad.insert(bad.end(), {static_cast<float>(nan), static_cast<float>(inf), 0.0f, -1.0f});
  bad.insert(bad.end(), 500, -2.0f);
  EXPECT_FALSE(t.update_from_samples(bad));
  ASSERT_TRUE(t.has_estimate());
  EXPECT_NEAR(t.range().near, even_near(2.0, 4.0), 1e-6);
  EXPECT_NEAR(t.range().far, even_far(2.0, 4.0), 1e-6);
  // 100 usable ones are enough; the unusable ones are ignored.
  bad.push_back(6.0f);
  EXPECT_TRUE(t.update_from_samples(bad));
  EXPECT_NEAR(t.range().near, (5.0 + 2.0 / 98) / 1.2, 1e-5);  // 2nd percentile of 100: the 3rd smallest
  EXPECT_GT(t.range().far, 6.0);
}

TEST(DepthRange, EstimateOutsideTheBoundsFallsBackToThem) {
  DepthRangeTracker t(0.3, 10.0);
  ASSERT_TRUE(t.update_from_samples(even_depths(2.0, 4.0)));
  // All beyond depth_max: near 16.7 clamped to nothing (far 10 < near): the bounds again.
  EXPECT_TRUE(t.update_from_samples(even_depths(20.0, 30.0)));
  EXPECT_FALSE(t.has_estimate());
  EXPECT_DOUBLE_EQ(t.range().near, 0.3);
  EXPECT_DOUBLE_EQ(t.range().far, 10.0);
  // All below depth_min likewise.
  ASSERT_TRUE(t.update_from_samples(even_depths(2.0, 4.0)));
  EXPECT_TRUE(t.update_from_samples(even_depths(0.01, 0.2)));
  EXPECT_FALSE(t.has_estimate());
  EXPECT_DOUBLE_EQ(t.range().near, 0.3);
  EXPECT_DOUBLE_EQ(t.range().far, 10.0);
}

TEST(DepthRange, TooNarrowOrNonFiniteEstimateFallsBackToTheBounds) {
  DepthRangeTracker t(1.0, 4.0);
  EXPECT_TRUE(t.update(2.0, 2.11));  // far > 1.05 near
  EXPECT_DOUBLE_EQ(t.range().near, 2.0);
  EXPECT_DOUBLE_EQ(t.range().far, 2.11);
  EXPECT_FALSE(t.update(2.0, 2.09));  // narrower than 5 %
  EXPECT_DOUBLE_EQ(t.range().near, 1.0);
  EXPECT_DOUBLE_EQ(t.range().far, 4.0);
  ASSERT_TRUE(t.update(2.0, 3.0));
  EXPECT_FALSE(t.update(3.0, 2.0));  // reversed
  EXPECT_DOUBLE_EQ(t.range().near, 1.0);
  ASSERT_TRUE(t.update(2.0, 3.0));
  EXPECT_FALSE(t.update(std::numeric_limits<double>::quiet_NaN(), 3.0));
  EXPECT_DOUBLE_EQ(t.range().near, 1.0);
  EXPECT_DOUBLE_EQ(t.range().far, 4.0);
  ASSERT_TRUE(t.update(2.0, 3.0));
  EXPECT_FALSE(t.update(2.0, std::numeric_limits<double>::infinity()));
  EXPECT_DOUBLE_EQ(t.range().far, 4.0);
  // A clamped estimate that leaves less than 5 %: near 3.9 .. far clamped to 4.0.
  EXPECT_FALSE(t.update(3.9, 9.0));
  EXPECT_DOUBLE_EQ(t.range().near, 1.0);
}

TEST(DepthRange, ConfidentDepthsKeepPixelsAboveTheThreshold) {
  const std::vector<float> depth = {1, 2, 3, 4, 5};
  const std::vector<float> conf = {0.2f, 0.5f, 0.51f, 1.0f, std::numeric_limits<float>::quiet_NaN()};
  EXPECT_EQ(confident_depths(depth.data(), conf.data(), depth.size()), (std::vector<float>{3, 4}));
  EXPECT_EQ(confident_depths(depth.data(), conf.data(), depth.size(), 0.1f), (std::vector<float>{1, 2, 3, 4}));
  EXPECT_TRUE(confident_depths(depth.data(), conf.data(), 0).empty());
}

}  // namespace
}  // namespace umvs
