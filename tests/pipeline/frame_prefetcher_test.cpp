// The frame prefetcher of `omnisculpt reconstruct` and `omnisculpt sfm`
// (pipeline/frame_prefetcher.h): frames in order, a frame's reading error delivered with it,
// never more than frames_ahead frames decoded ahead of the consumer, a clean early stop.

#include "pipeline/frame_prefetcher.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <stdexcept>
#include <thread>

#include "calib/error.h"
#include "tests/calib/options_error_check.h"

namespace omni {
namespace {

using std::chrono::milliseconds;

// A frame's fake images: `cameras` 1x1 images holding the frame number and the camera.
std::vector<cv::Mat> FakeImages(size_t frame, int cameras) {
  std::vector<cv::Mat> images;
  for (int c = 0; c < cameras; ++c)
    images.push_back(cv::Mat(1, 1, CV_32S, cv::Scalar(static_cast<int>(frame) * 10 + c)));
  return images;
}

// Waits at most 2 s for `condition`.
template <typename Condition>
bool WaitFor(Condition condition) {
  for (int i = 0; i < 400 && !condition(); ++i) std::this_thread::sleep_for(milliseconds(5));
  return condition();
}

TEST(PipelineFramePrefetcher, OptionsAreChecked) {
  EXPECT_TRUE(FramePrefetcherOptions().Check().empty());
  FramePrefetcherOptions options;
  options.frames_ahead = 0;
  EXPECT_FALSE(options.Check().empty());
  EXPECT_TRUE(testing::ThrowsOptionsError(
      [&] {
        FramePrefetcher prefetcher(
            3, [](size_t frame) { return FakeImages(frame, 1); }, options);
      },
      "FramePrefetcherOptions.frames_ahead: expected"));
}

TEST(PipelineFramePrefetcher, DeliversEveryFrameInOrderWithItsImages) {
  constexpr size_t kFrames = 100;
  FramePrefetcherOptions options;
  options.frames_ahead = 3;
  std::atomic<int> calls{0};
  FramePrefetcher prefetcher(
      kFrames,
      [&](size_t frame) {
        ++calls;
        if (frame % 7 == 0) std::this_thread::sleep_for(milliseconds(1));  // uneven decoding
        return FakeImages(frame, 2);
      },
      options);
  for (size_t f = 0; f < kFrames; ++f) {
    if (f % 13 == 0) std::this_thread::sleep_for(milliseconds(2));  // uneven consumer
    std::optional<PrefetchedFrame> frame = prefetcher.Next();
    ASSERT_TRUE(frame.has_value()) << f;
    EXPECT_EQ(frame->frame, f);
    EXPECT_TRUE(frame->loaded());
    ASSERT_EQ(frame->images.size(), 2u);
    EXPECT_EQ(frame->images[0].at<int>(0, 0), static_cast<int>(f * 10));
    EXPECT_EQ(frame->images[1].at<int>(0, 0), static_cast<int>(f * 10 + 1));
  }
  EXPECT_FALSE(prefetcher.Next().has_value());
  EXPECT_FALSE(prefetcher.Next().has_value());
  EXPECT_EQ(calls, static_cast<int>(kFrames));  // each frame decoded once
  EXPECT_LE(prefetcher.MaxReady(), 3u);
  EXPECT_GE(prefetcher.WaitSeconds(), 0.0);
}

TEST(PipelineFramePrefetcher, AFrameThatCannotBeReadComesWithItsErrorAndTheNextOnesFollow) {
  FramePrefetcher prefetcher(6, [](size_t frame) {
    if (frame == 2) throw InputError("images/cam1/000002.png", "image", "cannot be decoded");
    if (frame == 4) throw std::runtime_error("not an input error");
    return FakeImages(frame, 1);
  });
  for (size_t f = 0; f < 6; ++f) {
    std::optional<PrefetchedFrame> frame = prefetcher.Next();
    ASSERT_TRUE(frame.has_value());
    EXPECT_EQ(frame->frame, f);
    if (f == 2) {
      EXPECT_FALSE(frame->loaded());
      EXPECT_TRUE(frame->images.empty());
      try {
        frame->Rethrow();
        ADD_FAILURE() << "no error";
      } catch (const InputError& error) {
        EXPECT_NE(std::string(error.what()).find("000002.png"), std::string::npos) << error.what();
      }
    } else if (f == 4) {
      EXPECT_FALSE(frame->loaded());
      EXPECT_THROW(frame->Rethrow(), std::runtime_error);
    } else {
      EXPECT_TRUE(frame->loaded());
      EXPECT_NO_THROW(frame->Rethrow());
      ASSERT_EQ(frame->images.size(), 1u);
      EXPECT_EQ(frame->images[0].at<int>(0, 0), static_cast<int>(f * 10));
    }
  }
  EXPECT_FALSE(prefetcher.Next().has_value());
}

// The bound: frame f starts decoding only once the consumer has begun taking frame
// f - frames_ahead (f < begun + frames_ahead, `begun` counted before each Next()); and the
// prefetcher does fill its bound while the consumer is busy.
TEST(PipelineFramePrefetcher, NeverDecodesMoreThanItsBoundAhead) {
  constexpr int kAhead = 4;
  constexpr size_t kFrames = 40;
  FramePrefetcherOptions options;
  options.frames_ahead = kAhead;
  std::atomic<int> begun{0}, started{0}, violations{0};
  FramePrefetcher prefetcher(
      kFrames,
      [&](size_t frame) {
        if (static_cast<int>(frame) >= begun + kAhead) ++violations;
        started = static_cast<int>(frame) + 1;
        return FakeImages(frame, 1);
      },
      options);
  // A busy consumer: the prefetcher fills its bound (frames 0..3) and then waits.
  ASSERT_TRUE(WaitFor([&] { return started == kAhead; }));
  std::this_thread::sleep_for(milliseconds(50));
  EXPECT_EQ(started, kAhead);
  for (size_t f = 0; f < kFrames; ++f) {
    ++begun;
    std::optional<PrefetchedFrame> frame = prefetcher.Next();
    ASSERT_TRUE(frame.has_value());
    EXPECT_EQ(frame->frame, f);
    if (f == 10) {  // taking one frame lets exactly one more be decoded
      const size_t expected = std::min(kFrames, f + 1 + kAhead);
      ASSERT_TRUE(WaitFor([&] { return started == static_cast<int>(expected); }));
      std::this_thread::sleep_for(milliseconds(30));
      EXPECT_EQ(started, static_cast<int>(expected));
    }
  }
  EXPECT_EQ(violations, 0);
  EXPECT_EQ(prefetcher.MaxReady(), static_cast<size_t>(kAhead));
}

TEST(PipelineFramePrefetcher, StoppingEarlyJoinsTheThreadAndDecodesNoMore) {
  std::atomic<int> started{0};
  {
    FramePrefetcherOptions options;
    options.frames_ahead = 2;
    FramePrefetcher prefetcher(
        100000,
        [&](size_t frame) {
          ++started;
          return FakeImages(frame, 1);
        },
        options);
    for (int i = 0; i < 3; ++i) ASSERT_TRUE(prefetcher.Next().has_value());
    ASSERT_TRUE(WaitFor([&] { return started == 5; }));  // 3 taken + 2 ahead, then blocked
    // Destroyed here while its thread waits for room.
  }
  EXPECT_EQ(started, 5);

  // Stop() while a frame is being decoded: that frame is dropped, Next() returns nothing.
  std::atomic<bool> decoding{false}, release{false};
  FramePrefetcher slow(10, [&](size_t frame) {
    decoding = true;
    while (!release) std::this_thread::sleep_for(milliseconds(1));
    return FakeImages(frame, 1);
  });
  ASSERT_TRUE(WaitFor([&] { return decoding.load(); }));
  std::thread releaser([&] {
    std::this_thread::sleep_for(milliseconds(20));
    release = true;
  });
  slow.Stop();
  releaser.join();
  EXPECT_FALSE(slow.Next().has_value());
  slow.Stop();  // twice is harmless
}

TEST(PipelineFramePrefetcher, ZeroFramesGivesNothing) {
  FramePrefetcher prefetcher(0, [](size_t frame) { return FakeImages(frame, 1); });
  EXPECT_FALSE(prefetcher.Next().has_value());
}

}  // namespace
}  // namespace omni
