// The frame prefetcher of `omnisculpt reconstruct` and `omnisculpt sfm`
// (pipeline/frame_prefetcher.h): frames in order, a frame's reading error delivered with it,
// never more than frames_ahead frames decoded ahead of the consumer, a clean early stop.

#include "pipeline/frame_prefetcher.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <stdexcept>
#include <thread>

#include "calib/drive.h"
#include "calib/error.h"
#include "calib/rig_io.h"
#include "tests/calib/io_temp_dir.h"
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

int ThisThreadNiceness() {
  return getpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)));
}

// The niceness of the prefetch thread, read by the loader (which runs on it).
int PrefetchThreadNiceness(int thread_nice) {
  FramePrefetcherOptions options;
  options.thread_nice = thread_nice;
  std::atomic<int> niceness{-100};
  FramePrefetcher prefetcher(
      1,
      [&niceness](size_t frame) {
        niceness = ThisThreadNiceness();
        return FakeImages(frame, 1);
      },
      options);
  EXPECT_TRUE(prefetcher.Next().has_value());
  return niceness;
}

// The prefetch thread runs thread_nice nicer than the thread that made the prefetcher (capped
// at 19); 0 leaves it at the same priority; the caller's own priority is untouched.
TEST(PipelineFramePrefetcher, ThePrefetchThreadRunsNicerThanItsConsumer) {
  const int base = ThisThreadNiceness();
  EXPECT_EQ(PrefetchThreadNiceness(0), base);
  EXPECT_EQ(PrefetchThreadNiceness(4), std::min(19, base + 4));
  EXPECT_EQ(PrefetchThreadNiceness(19), 19);
  EXPECT_EQ(ThisThreadNiceness(), base);
  FramePrefetcherOptions options;
  options.thread_nice = 20;
  EXPECT_NE(options.Check().find("thread_nice: expected 0 to 19"), std::string::npos);
  options.thread_nice = -1;
  EXPECT_FALSE(options.Check().empty());
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

// The prepare step runs on the prefetch thread on every frame that loaded, before the frame is
// delivered; a frame that could not be read is not prepared, and what the step throws leaves
// the frame unprepared (the consumer does the work itself) rather than failing it.
TEST(PipelineFramePrefetcher, PreparesEachLoadedFrameOnItsThreadBeforeDeliveringIt) {
  const std::thread::id consumer = std::this_thread::get_id();
  std::atomic<int> on_consumer{0};
  FramePrefetcher prefetcher(
      6,
      [](size_t frame) {
        if (frame == 2) throw InputError("images/cam0/000002.png", "image", "cannot be decoded");
        return FakeImages(frame, 2);
      },
      FramePrefetcherOptions(),
      [&](PrefetchedFrame* frame) {
        if (std::this_thread::get_id() == consumer) ++on_consumer;
        if (frame->frame == 4) throw std::runtime_error("detection failed");
        FrameCorners corners;
        corners.prepared = frame->images;
        corners.corners.assign(frame->images.size(), {Eigen::Vector2d(frame->frame, 1.0)});
        frame->corners = std::move(corners);
      });
  for (size_t f = 0; f < 6; ++f) {
    std::optional<PrefetchedFrame> frame = prefetcher.Next();
    ASSERT_TRUE(frame.has_value());
    EXPECT_EQ(frame->frame, f);
    if (f == 2 || f == 4) {
      EXPECT_EQ(frame->loaded(), f == 4);
      EXPECT_FALSE(frame->corners.has_value()) << f;
      continue;
    }
    ASSERT_TRUE(frame->corners.has_value()) << f;
    ASSERT_EQ(frame->corners->corners.size(), 2u);
    EXPECT_EQ(frame->corners->corners[1][0].x(), static_cast<double>(f));
    EXPECT_EQ(frame->corners->prepared[1].at<int>(0, 0), static_cast<int>(f * 10 + 1));
  }
  EXPECT_EQ(on_consumer, 0);
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

// A drive of `cameras` cameras and 2 frames of 16x12 grey images, each camera's image a
// different grey level (frame * 100 + camera * 10 + 5); the images named in `corrupt`
// (camera, frame) are not PNGs.
std::filesystem::path WriteGreyDrive(const std::filesystem::path& root, int cameras,
                                     const std::vector<std::pair<int, int>>& corrupt) {
  Rig rig;
  rig.name = "ring";
  for (int c = 0; c < cameras; ++c) {
    Camera camera;
    camera.name = "cam" + std::to_string(c);
    camera.width = 16;
    camera.height = 12;
    camera.params = {10.0, 10.0, 7.5, 5.5};
    camera.cam_from_rig.translation = Eigen::Vector3d(0.1 * c, 0.0, 0.0);
    rig.cameras.push_back(camera);
  }
  WriteRigJson(rig, root / "rig.json");
  for (int c = 0; c < cameras; ++c) {
    const std::filesystem::path folder = root / "images" / rig.cameras[c].name;
    std::filesystem::create_directories(folder);
    for (int f = 0; f < 2; ++f) {
      const std::filesystem::path file = folder / ("00000" + std::to_string(f) + ".png");
      if (std::find(corrupt.begin(), corrupt.end(), std::make_pair(c, f)) != corrupt.end())
        std::ofstream(file, std::ios::binary) << "not a png";
      else
        EXPECT_TRUE(
            cv::imwrite(file.string(), cv::Mat(12, 16, CV_8UC1, cv::Scalar(f * 100 + c * 10 + 5))));
    }
  }
  return root;
}

TEST(PipelineLoadGrayFrame, GivesEachCameraItsOwnImageInOrder) {
  testing::TempDir dir;
  const Drive drive = Drive::Open(WriteGreyDrive(dir.path(), 6, {}));
  for (size_t f = 0; f < 2; ++f) {
    const std::vector<cv::Mat> images = LoadGrayFrame(drive, f);
    ASSERT_EQ(images.size(), 6u);
    for (size_t c = 0; c < 6; ++c) {
      ASSERT_EQ(images[c].type(), CV_8UC1);
      EXPECT_EQ(cv::norm(images[c], drive.LoadGray(f, c), cv::NORM_INF), 0.0) << f << " " << c;
      EXPECT_EQ(images[c].at<uint8_t>(3, 4), static_cast<int>(f * 100 + c * 10 + 5));
    }
  }
}

TEST(PipelineLoadGrayFrame, OfSeveralUnreadableImagesTheLowestCameraIsNamed) {
  testing::TempDir dir;
  const Drive drive = Drive::Open(WriteGreyDrive(dir.path(), 6, {{4, 1}, {2, 1}, {5, 1}}));
  EXPECT_EQ(LoadGrayFrame(drive, 0).size(), 6u);
  for (int attempt = 0; attempt < 20; ++attempt) {  // whichever task fails first
    try {
      LoadGrayFrame(drive, 1);
      ADD_FAILURE() << "no error";
    } catch (const InputError& error) {
      const std::string what = error.what();
      EXPECT_NE(what.find("cam2"), std::string::npos) << what;
      EXPECT_EQ(what.find("cam4"), std::string::npos) << what;
    }
  }
  // Through the prefetcher: the frame arrives with that error, the next frame's images after.
  FramePrefetcher prefetcher(drive, 2);
  std::optional<PrefetchedFrame> first = prefetcher.Next(), second = prefetcher.Next();
  ASSERT_TRUE(first && second);
  EXPECT_TRUE(first->loaded());
  EXPECT_FALSE(second->loaded());
  EXPECT_THROW(second->Rethrow(), InputError);
}

TEST(PipelineFramePrefetcher, ZeroFramesGivesNothing) {
  FramePrefetcher prefetcher(0, [](size_t frame) { return FakeImages(frame, 1); });
  EXPECT_FALSE(prefetcher.Next().has_value());
}

}  // namespace
}  // namespace omni
