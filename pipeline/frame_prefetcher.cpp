#include "pipeline/frame_prefetcher.h"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <utility>

#include "calib/error.h"
#include "pipeline/thread_priority.h"

namespace omni {

std::string FramePrefetcherOptions::Check() const {
  if (frames_ahead < 1) return "frames_ahead: expected at least 1";
  if (thread_nice < 0 || thread_nice > 19) return "thread_nice: expected 0 to 19";
  return {};
}

std::vector<cv::Mat> LoadGrayFrame(const Drive& drive, size_t frame) {
  const size_t num_cameras = drive.rig().NumCameras();
  std::vector<cv::Mat> images(num_cameras);
  std::vector<std::exception_ptr> errors(num_cameras);
  // One task per camera: a PNG of a car rig's 1920x1200 camera takes 15-20 ms to decode.
  tbb::parallel_for(size_t{0}, num_cameras, [&](size_t c) {
    try {
      images[c] = drive.LoadGray(frame, c);
    } catch (...) {
      errors[c] = std::current_exception();
    }
  });
  for (const std::exception_ptr& error : errors)
    if (error) std::rethrow_exception(error);
  return images;
}

FramePrefetcher::FramePrefetcher(size_t num_frames, Loader loader,
                                 const FramePrefetcherOptions& options, Prepare prepare)
    : num_frames_(num_frames),
      frames_ahead_(static_cast<size_t>(std::max(options.frames_ahead, 1))),
      thread_nice_(options.thread_nice),
      loader_(std::move(loader)),
      prepare_(std::move(prepare)) {
  ThrowIfInvalid(options.Check(), "FramePrefetcherOptions");
  thread_ = std::thread([this] { Run(); });
}

FramePrefetcher::FramePrefetcher(const Drive& drive, size_t num_frames,
                                 const FramePrefetcherOptions& options)
    : FramePrefetcher(
          num_frames, [&drive](size_t frame) { return LoadGrayFrame(drive, frame); }, options) {}

FramePrefetcher::~FramePrefetcher() { Stop(); }

void FramePrefetcher::Run() {
  LowerThisThreadPriority(thread_nice_, "image prefetch");
  // The loader's and the prepare step's parallel work runs in an arena of its own: a thread of
  // the consumer waiting in a parallel loop of its own then never picks up a task of this one
  // (TBB lets a waiting thread run any task of its arena), which would make the consumer wait
  // for the next frame's decoding or detection.
  tbb::task_arena arena;
  for (size_t f = 0; f < num_frames_; ++f) {
    {
      std::unique_lock<std::mutex> lock(mutex_);
      room_.wait(lock, [&] { return stop_ || in_flight_ < frames_ahead_; });
      if (stop_) return;
      ++in_flight_;
    }
    PrefetchedFrame frame;
    frame.frame = f;
    arena.execute([&] {
      try {
        frame.images = loader_(f);
      } catch (...) {
        frame.images.clear();
        frame.error = std::current_exception();
      }
      if (prepare_ && frame.loaded()) {
        try {
          prepare_(&frame);
        } catch (...) {
          frame.corners.reset();
        }
      }
    });
    std::lock_guard<std::mutex> lock(mutex_);
    if (stop_) return;
    frames_.push_back(std::move(frame));
    max_ready_ = std::max(max_ready_, frames_.size());
    ready_.notify_one();
  }
}

std::optional<PrefetchedFrame> FramePrefetcher::Next() {
  std::unique_lock<std::mutex> lock(mutex_);
  if (stop_ || next_to_take_ >= num_frames_) return std::nullopt;
  if (frames_.empty()) {
    const auto start = std::chrono::steady_clock::now();
    ready_.wait(lock, [&] { return stop_ || !frames_.empty(); });
    wait_seconds_ +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (frames_.empty()) return std::nullopt;
  }
  PrefetchedFrame frame = std::move(frames_.front());
  frames_.pop_front();
  --in_flight_;
  ++next_to_take_;
  room_.notify_one();
  return frame;
}

void FramePrefetcher::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
    frames_.clear();
    room_.notify_all();
    ready_.notify_all();
  }
  if (thread_.joinable()) thread_.join();
}

double FramePrefetcher::WaitSeconds() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return wait_seconds_;
}

size_t FramePrefetcher::MaxReady() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return max_ready_;
}

}  // namespace omni
