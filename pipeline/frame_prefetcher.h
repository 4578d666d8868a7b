#pragma once
// Decodes the images of the next frames of a drive on a thread of its own, so that
// the SfM thread of `omnisculpt reconstruct` and `omnisculpt sfm` does not wait ~3 ms per PNG
// (a drive's frame: its cameras' images decoded in parallel, LoadGrayFrame):
// frames are delivered in order, each with its images or the error that reading one of them
// raised (the caller reports and skips it, or rethrows). At most frames_ahead frames are decoded
// (or being decoded) and not yet taken, so memory stays bounded however slow the consumer is.
// Destroying the prefetcher (or Stop) before the last frame stops the decoding and joins the
// thread. A `prepare` step, when given, runs on the same thread on each frame that loaded
// (the SfM loop detects the frame's corners there, ahead of its tracking).

#include <condition_variable>
#include <cstddef>
#include <deque>
#include <exception>
#include <functional>
#include <mutex>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "calib/drive.h"
#include "sfm/track_builder.h"

namespace omni {

struct FramePrefetcherOptions {
  // Frames decoded ahead of the consumer at most (each holds one image per camera: 6 grey
  // 384x512 images are 1.2 MB). 1: the next frame only.
  int frames_ahead = 4;
  // The prefetch thread runs this much nicer than the thread that made the prefetcher (Linux
  // thread niceness, 0 to 19; 0: the same priority). It works ahead of the SfM, which sets the
  // pace: when both want a core the SfM gets it, and the frames ahead absorb the delay
  // (docs/figures.md F86). Its parallel work (a frame's cameras) runs on TBB's workers, at
  // theirs.
  int thread_nice = 10;

  std::string Check() const;
};

struct PrefetchedFrame {
  size_t frame = 0;
  std::vector<cv::Mat> images;  // one per camera; empty when an image could not be read
  std::exception_ptr error;     // what reading the frame threw (an InputError for bad images)
  // The frame's corners when the prefetcher's prepare step detected them (empty otherwise:
  // the consumer detects them itself).
  std::optional<FrameCorners> corners;

  bool loaded() const { return !error; }
  void Rethrow() const {
    if (error) std::rethrow_exception(error);
  }
};

// The grey images (Drive::LoadGray) of one frame of `drive`, one per camera, the cameras
// decoded in parallel (TBB: the prefetch thread and the idle core of a waiting SfM thread);
// when images cannot be read, the error of the lowest camera among them is thrown, as a
// serial loop would.
std::vector<cv::Mat> LoadGrayFrame(const Drive& drive, size_t frame);

class FramePrefetcher {
 public:
  // The images of one frame, one per camera; throws (InputError) when one cannot be read.
  using Loader = std::function<std::vector<cv::Mat>(size_t frame)>;
  // Work on a frame that loaded, on the prefetch thread before the frame is delivered; what it
  // throws is dropped (the consumer then does that work itself and meets the error there).
  using Prepare = std::function<void(PrefetchedFrame* frame)>;

  // Frames 0 .. num_frames-1 of `loader`; decoding starts at once.
  FramePrefetcher(size_t num_frames, Loader loader, const FramePrefetcherOptions& options = {},
                  Prepare prepare = {});
  // The grey images (LoadGrayFrame) of the first num_frames frames of `drive`, which must
  // outlive the prefetcher.
  FramePrefetcher(const Drive& drive, size_t num_frames,
                  const FramePrefetcherOptions& options = {});
  ~FramePrefetcher();
  FramePrefetcher(const FramePrefetcher&) = delete;
  FramePrefetcher& operator=(const FramePrefetcher&) = delete;

  // The next frame in order, waiting for it to be decoded; nothing after the last (or after
  // Stop).
  std::optional<PrefetchedFrame> Next();
  // Stops decoding (the frame being decoded is finished and dropped) and joins the thread.
  void Stop();

  // Seconds Next() waited for a frame to be decoded, in total.
  double WaitSeconds() const;
  // The most frames that were decoded and not yet taken at once (never above frames_ahead).
  size_t MaxReady() const;

 private:
  void Run();

  const size_t num_frames_;
  const size_t frames_ahead_;
  const int thread_nice_;
  Loader loader_;
  Prepare prepare_;
  mutable std::mutex mutex_;
  std::condition_variable ready_, room_;
  std::deque<PrefetchedFrame> frames_;  // decoded, not yet taken, in order
  size_t in_flight_ = 0;                // frames decoded or being decoded, not yet taken
  size_t next_to_take_ = 0;
  bool stop_ = false;
  double wait_seconds_ = 0.0;
  size_t max_ready_ = 0;
  std::thread thread_;
};

}  // namespace omni
