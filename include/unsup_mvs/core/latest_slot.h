// A thread-safe slot that holds at most one waiting item: put() replaces a waiting item (which
// is then counted as dropped), take() waits for an item or close(). The inference nodelet's
// queue: while the network is busy only the newest keyframe set waits (latest wins).
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>
#include <utility>

namespace umvs {

template <typename T>
class LatestSlot {
 public:
  // Stores `item`; a waiting item that nobody took is replaced and counted as dropped. Returns
  // true when one was dropped. After close() the item is discarded (not counted) and false
  // returned.
  bool put(T item) {
    bool replaced = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (closed_) return false;
      replaced = item_.has_value();
      if (replaced) ++dropped_;
      item_ = std::move(item);
    }
    cv_.notify_one();
    return replaced;
  }

  // Waits until an item waits (returns it and empties the slot) or the slot is closed (returns
  // nothing, even when an item still waits).
  std::optional<T> take() {
    std::unique_lock<std::mutex> lock(mutex_);
    cv_.wait(lock, [this] { return closed_ || item_.has_value(); });
    if (closed_) return std::nullopt;
    return pop(lock);
  }

  // The waiting item if there is one, without waiting.
  std::optional<T> try_take() {
    std::unique_lock<std::mutex> lock(mutex_);
    if (closed_ || !item_) return std::nullopt;
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
    return item_.has_value();
  }
  bool closed() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return closed_;
  }

 private:
  std::optional<T> pop(std::unique_lock<std::mutex>&) {
    std::optional<T> out = std::move(item_);
    item_.reset();
    return out;
  }

  mutable std::mutex mutex_;
  std::condition_variable cv_;
  std::optional<T> item_;
  int64_t dropped_ = 0;
  bool closed_ = false;
};

}  // namespace umvs
