// Percentiles of per-item times, for reports: `umvs bench --case pipeline` and the inference
// nodelet's ~stats service (processed, dropped, p50/p90), so that a run's speed is one line.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <string>
#include <vector>

namespace umvs {

// The p-th percentile (0-100) of `values` by the nearest rank; 0 for none.
inline double percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const auto rank = static_cast<size_t>(std::ceil(p / 100.0 * static_cast<double>(values.size())));
  return values[std::min(values.size() - 1, rank > 0 ? rank - 1 : 0)];
}

// Seconds of each processed item, two clocks per item (e.g. processing, and since the input was
// stamped), over the latest `window` items: a node that runs for days keeps bounded memory and
// sorts at most `window` values per summary. Safe to add from one thread and read from another.
class TimingLog {
 public:
  explicit TimingLog(size_t window = 1000) : window_(std::max<size_t>(1, window)) {}
  void add(double processing_s, double since_stamp_s) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (processing_.size() == window_) {  // the oldest leaves
      processing_.erase(processing_.begin());
      since_stamp_.erase(since_stamp_.begin());
    }
    processing_.push_back(processing_s);
    since_stamp_.push_back(since_stamp_s);
    ++count_;
  }
  // Items added so far, all of them (not only the window's).
  size_t count() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return count_;
  }
  // "<what> p50 0.41 s, p90 0.47 s; <since> p50 0.9 s, p90 1.2 s" over the window (no items: "none yet").
  std::string summary(const std::string& what, const std::string& since) const {
    std::lock_guard<std::mutex> lock(mutex_);
    if (processing_.empty()) return "none yet";
    char text[256];
    std::snprintf(text, sizeof(text), "%s p50 %.2f s, p90 %.2f s; %s p50 %.2f s, p90 %.2f s", what.c_str(),
                  percentile(processing_, 50), percentile(processing_, 90), since.c_str(),
                  percentile(since_stamp_, 50), percentile(since_stamp_, 90));
    return text;
  }

 private:
  mutable std::mutex mutex_;
  size_t window_;
  size_t count_ = 0;
  std::vector<double> processing_, since_stamp_;
};

}  // namespace umvs
