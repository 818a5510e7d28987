#include <gtest/gtest.h>

#include <condition_variable>
#include <mutex>
#include <thread>
#include <vector>

#include "unsup_mvs/core/latest_slot.h"
#include "unsup_mvs/core/timing_log.h"

namespace umvs {
namespace {

TEST(LatestSlot, NewerItemReplacesTheWaitingOneAndCountsItDropped) {
  LatestSlot<int> slot;
  EXPECT_FALSE(slot.waiting());
  EXPECT_FALSE(slot.try_take().has_value());
  EXPECT_FALSE(slot.put(1));
  EXPECT_TRUE(slot.waiting());
  EXPECT_EQ(slot.dropped(), 0);
  EXPECT_TRUE(slot.put(2));  // 1 was still waiting: dropped
  EXPECT_TRUE(slot.put(3));  // and 2
  EXPECT_EQ(slot.dropped(), 2);
  EXPECT_EQ(slot.take(), 3);
  EXPECT_FALSE(slot.waiting());
  EXPECT_FALSE(slot.try_take().has_value());
  EXPECT_FALSE(slot.put(4));  // the slot was empty: nothing dropped
  EXPECT_EQ(slot.try_take(), 4);
  EXPECT_EQ(slot.dropped(), 2);
}

TEST(LatestSlot, WithCapacityTheNewestItemsWaitInOrder) {
  LatestSlot<int> slot(3);
  EXPECT_EQ(slot.capacity(), 3u);
  for (int i = 1; i <= 3; ++i) EXPECT_FALSE(slot.put(i));
  EXPECT_TRUE(slot.put(4));  // 1 was the oldest waiting: dropped
  EXPECT_TRUE(slot.put(5));  // and 2
  EXPECT_EQ(slot.dropped(), 2);
  EXPECT_EQ(slot.take(), 3);
  EXPECT_EQ(slot.take(), 4);
  EXPECT_FALSE(slot.put(6));  // room again
  EXPECT_EQ(slot.try_take(), 5);
  EXPECT_EQ(slot.try_take(), 6);
  EXPECT_FALSE(slot.waiting());
  EXPECT_EQ(slot.dropped(), 2);
  EXPECT_THROW(LatestSlot<int>(0), std::invalid_argument);
}

TEST(LatestSlot, CloseEndsTakeAndIgnoresLaterItems) {
  LatestSlot<int> slot;
  slot.put(1);
  slot.close();
  EXPECT_TRUE(slot.closed());
  EXPECT_FALSE(slot.take().has_value());  // even with an item waiting
  EXPECT_FALSE(slot.try_take().has_value());
  EXPECT_FALSE(slot.put(2));
  EXPECT_EQ(slot.dropped(), 0);  // neither counts as dropped
  slot.close();                  // idempotent
  EXPECT_FALSE(slot.take().has_value());
}

TEST(LatestSlot, CloseWakesAWaitingTake) {
  LatestSlot<int> slot;
  std::optional<int> got = 42;
  std::thread consumer([&] { got = slot.take(); });  // blocks (or finds the slot closed)
  slot.close();
  consumer.join();
  EXPECT_FALSE(got.has_value());
}

// A consumer that keeps up (the producer waits until each item was taken) loses nothing.
TEST(LatestSlot, ConsumerThatKeepsUpGetsEveryItem) {
  LatestSlot<int> slot;
  std::mutex m;
  std::condition_variable cv;
  std::vector<int> received;
  std::thread consumer([&] {
    while (auto item = slot.take()) {
      std::lock_guard<std::mutex> lock(m);
      received.push_back(*item);
      cv.notify_all();
    }
  });
  for (int i = 0; i < 200; ++i) {
    slot.put(i);
    std::unique_lock<std::mutex> lock(m);
    cv.wait(lock, [&] { return received.size() == static_cast<size_t>(i + 1); });
  }
  slot.close();
  consumer.join();
  ASSERT_EQ(received.size(), 200u);
  for (int i = 0; i < 200; ++i) EXPECT_EQ(received[i], i);
  EXPECT_EQ(slot.dropped(), 0);
}

// While the consumer is busy (held at a gate after taking item 0), items 1..4 arrive: 1, 2 and 3
// are dropped, 4 is what the consumer gets next.
TEST(LatestSlot, BusyConsumerGetsOnlyTheNewestItem) {
  LatestSlot<int> slot;
  std::mutex m;
  std::condition_variable cv;
  std::vector<int> received;
  bool gate_open = false;
  std::thread consumer([&] {
    while (auto item = slot.take()) {
      std::unique_lock<std::mutex> lock(m);
      received.push_back(*item);
      cv.notify_all();
      cv.wait(lock, [&] { return gate_open; });  // "processing"
    }
  });
  slot.put(0);
  {
    std::unique_lock<std::mutex> lock(m);
    cv.wait(lock, [&] { return received.size() == 1; });  // consumer took 0 and is busy
  }
  EXPECT_FALSE(slot.put(1));
  EXPECT_TRUE(slot.put(2));
  EXPECT_TRUE(slot.put(3));
  EXPECT_TRUE(slot.put(4));
  EXPECT_EQ(slot.dropped(), 3);
  {
    std::lock_guard<std::mutex> lock(m);
    gate_open = true;
  }
  cv.notify_all();
  {
    std::unique_lock<std::mutex> lock(m);
    cv.wait(lock, [&] { return received.size() == 2; });
  }
  EXPECT_FALSE(slot.waiting());
  slot.close();
  consumer.join();
  EXPECT_EQ(received, (std::vector<int>{0, 4}));
  EXPECT_EQ(slot.dropped(), 3);
}

// Two producers race one consumer: every item is either received or counted dropped, exactly
// once, and each producer's items arrive in the order it put them.
TEST(LatestSlot, EveryItemIsReceivedOrCountedDroppedUnderContention) {
  constexpr int kPerProducer = 20000;
  constexpr int kSentinel = -1;
  LatestSlot<int> slot;
  std::vector<int> received;
  std::thread consumer([&] {
    while (auto item = slot.take()) {
      if (*item == kSentinel) return;
      received.push_back(*item);
    }
  });
  auto produce = [&](int base) {
    for (int i = 0; i < kPerProducer; ++i) slot.put(base + i);
  };
  std::thread a(produce, 0), b(produce, 1000000);
  a.join();
  b.join();
  slot.put(kSentinel);  // last put: nothing replaces it, the consumer takes it and stops
  consumer.join();
  // The sentinel may have replaced one last waiting item (counted dropped).
  EXPECT_EQ(static_cast<int64_t>(received.size()) + slot.dropped(), 2 * kPerProducer);
  int last_a = -1, last_b = -1;
  for (int v : received) {
    int& last = v < 1000000 ? last_a : last_b;
    EXPECT_GT(v, last);
    last = v;
  }
  EXPECT_FALSE(slot.waiting());
}


TEST(TimingLog, PercentilesCoverTheLatestWindowAndTheCountEveryItem) {
  TimingLog log(10);
  EXPECT_EQ(log.summary("a", "b"), "none yet");
  for (int i = 1; i <= 25; ++i) log.add(i, 100 + i);  // the window keeps 16 ... 25
  EXPECT_EQ(log.count(), 25u);
  // Nearest rank over 10 values: p50 is the 5th (20), p90 the 9th (24).
  EXPECT_EQ(log.summary("a", "b"), "a p50 20.00 s, p90 24.00 s; b p50 120.00 s, p90 124.00 s");
  EXPECT_DOUBLE_EQ(percentile({3, 1, 2}, 50), 2.0);
  EXPECT_DOUBLE_EQ(percentile({}, 90), 0.0);
}
}  // namespace
}  // namespace umvs
