// The bounded queue between the SfM and the surface threads (pipeline/bounded_queue.h) and the
// sfm→surface keyframe conversion (pipeline/keyframe_conversion.h).

#include "pipeline/bounded_queue.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <optional>
#include <thread>
#include <vector>

#include "pipeline/keyframe_conversion.h"

namespace omni {
namespace {

TEST(BoundedQueue, KeepsOrderAndNeverHoldsMoreThanItsCapacity) {
  BoundedQueue<int> queue(3);
  constexpr int kItems = 200;
  std::thread producer([&] {
    for (int i = 0; i < kItems; ++i) ASSERT_TRUE(queue.Push(i));
    queue.Close();
  });
  std::vector<int> received;
  while (std::optional<int> item = queue.Pop()) {
    if (received.size() % 20 == 0) std::this_thread::sleep_for(std::chrono::milliseconds(2));
    received.push_back(*item);
  }
  producer.join();
  ASSERT_EQ(received.size(), static_cast<size_t>(kItems));
  for (int i = 0; i < kItems; ++i) EXPECT_EQ(received[i], i);
  EXPECT_LE(queue.MaxSize(), 3u);
  EXPECT_GE(queue.MaxSize(), 1u);
  EXPECT_GT(queue.BlockedPushes(), 0u);  // the slow consumer made the producer wait
}

TEST(BoundedQueue, CloseReleasesABlockedProducerAndDrainsForTheConsumer) {
  BoundedQueue<int> queue(1);
  ASSERT_TRUE(queue.Push(1));
  std::atomic<int> push_result{-1};
  std::thread producer([&] { push_result = queue.Push(2) ? 1 : 0; });  // blocks: full
  std::this_thread::sleep_for(std::chrono::milliseconds(20));
  EXPECT_EQ(push_result, -1);
  queue.Close();
  producer.join();
  EXPECT_EQ(push_result, 0);
  std::optional<int> item = queue.Pop();
  ASSERT_TRUE(item.has_value());
  EXPECT_EQ(*item, 1);
  EXPECT_FALSE(queue.Pop().has_value());
}

// PopLatest returns the last queued item that supersedes those before it (here: negative
// ones), dropping what precedes it; an item at the front is returned as Pop would.
TEST(BoundedQueue, PopLatestDropsWhatTheLastSupersedingItemReplaces) {
  BoundedQueue<int> queue(8);
  for (int item : {-1, 2, 3, -4, 5, -6, 7}) ASSERT_TRUE(queue.Push(item));
  const auto supersedes = [](int item) { return item < 0; };
  std::vector<int> dropped;
  const auto drop = [&dropped](int item) { dropped.push_back(item); };
  std::optional<int> item = queue.PopLatest(supersedes, drop);
  ASSERT_TRUE(item.has_value());
  EXPECT_EQ(*item, -6);
  EXPECT_EQ(dropped, (std::vector<int>{-1, 2, 3, -4, 5}));
  item = queue.PopLatest(supersedes, drop);
  ASSERT_TRUE(item.has_value());
  EXPECT_EQ(*item, 7);
  EXPECT_EQ(dropped.size(), 5u);

  ASSERT_TRUE(queue.Push(-8));
  ASSERT_TRUE(queue.Push(9));
  item = queue.PopLatest(supersedes, drop);  // the superseding item is the first: nothing dropped
  ASSERT_TRUE(item.has_value());
  EXPECT_EQ(*item, -8);
  EXPECT_EQ(dropped.size(), 5u);
  queue.Close();
  item = queue.PopLatest(supersedes, drop);
  ASSERT_TRUE(item.has_value());
  EXPECT_EQ(*item, 9);
  EXPECT_FALSE(queue.PopLatest(supersedes, drop).has_value());
}

TEST(KeyframeConversion, CarriesIdsCentrePositionsAndRays) {
  FinalizedKeyframe keyframe;
  keyframe.keyframe = 7;
  keyframe.frame = 21;
  keyframe.center = Eigen::Vector3d(1, 2, 3);
  FinalizedPoint point;
  point.point = 42;
  point.position = Eigen::Vector3d(4, 5, 6);
  point.rays = {{7, Eigen::Vector3d(1, 2, 3)}, {5, Eigen::Vector3d(0, 2, 3)}};
  point.frame_rays = {{6, 19, 2, Eigen::Vector3d(0.5, 2, 3)}};
  keyframe.points = {point, point};
  keyframe.points[1].point = 43;
  const SurfaceKeyframe converted = ToSurfaceKeyframe(keyframe);
  EXPECT_EQ(converted.id, KeyframeId(7));
  EXPECT_EQ(converted.centre, keyframe.center);
  ASSERT_EQ(converted.points.size(), 2u);
  EXPECT_EQ(converted.points[0].id, PointId(42));
  EXPECT_EQ(converted.points[1].id, PointId(43));
  EXPECT_EQ(converted.points[0].position, point.position);
  // The keyframes' rays, then the tracked frames' under the keyframe before them.
  ASSERT_EQ(converted.points[0].rays.size(), 3u);
  EXPECT_EQ(converted.points[0].rays[1].keyframe, KeyframeId(5));
  EXPECT_EQ(converted.points[0].rays[1].origin, Eigen::Vector3d(0, 2, 3));
  EXPECT_EQ(converted.points[0].rays[2].keyframe, KeyframeId(6));
  EXPECT_EQ(converted.points[0].rays[2].origin, Eigen::Vector3d(0.5, 2, 3));
  EXPECT_EQ(ToSurfaceKeyframes({keyframe, keyframe}).size(), 2u);
}

}  // namespace
}  // namespace omni
