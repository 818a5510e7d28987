// A thread-safe slot that holds at most `capacity` waiting items (1 unless asked): put() beyond
// that drops the oldest waiting item (counted as dropped), take() waits for the oldest item or
// close(). The inference nodelet's queue: while the network is busy only the newest keyframe
// sets wait, so the latency stays bounded.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <deque>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <utility>

namespace umvs {

template <typename T>
class LatestSlot {
 public:
  explicit LatestSlot(size_t capacity = 1) : capacity_(capacity) {
    if (capacity < 1) throw std::invalid_argument("LatestSlot: capacity must be >= 1");
  }

  // Stores `item`; when `capacity` items already wait, the oldest is dropped and counted.
  // Returns true when one was dropped. After close() the item is discarded (not counted) and
  // false returned.
  bool put(T item) {
    bool replaced = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (closed_) return false;
      replaced = items_.size() >= capacity_;
      if (replaced) {
        ++dropped_;
        items_.pop_front();
      }
      items_.push_back(std::move(item));
    }
    cv_.notify_one();
    return replaced;
  }

  // Waits until an item waits (returns it and empties the slot) or the slot is closed (returns
  // nothing, even when an item still waits).
  std::optional<T> take() {
    std::unique_lock<std::mutex> lock(mutex_);
    cv_.wait(lock, [this] { return closed_ || !items_.empty(); });
    if (closed_) return std::nullopt;
    return pop(lock);
  }

  // The waiting item if there is one, without waiting.
  std::optional<T> try_take() {
    std::unique_lock<std::mutex> lock(mutex_);
    if (closed_ || items_.empty()) return std::nullopt;
    return pop(lock);
  }

  // Wakes every take(); later put()s are ignored. Idempotent.
  void close() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closed_ = true;
    }
    cv_.notify_all();
  }

  int64_t dropped() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return dropped_;
  }
  bool waiting() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return !items_.empty();
  }
  size_t capacity() const { return capacity_; }
  bool closed() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return closed_;
  }

 private:
  std::optional<T> pop(std::unique_lock<std::mutex>&) {
    std::optional<T> out = std::move(items_.front());
    items_.pop_front();
    return out;
  }

  mutable std::mutex mutex_;
  std::condition_variable cv_;
  const size_t capacity_;
  std::deque<T> items_;
  int64_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace umvs
