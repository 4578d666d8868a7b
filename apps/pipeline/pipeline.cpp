#include "apps/pipeline/pipeline.h"

#include <spdlog/spdlog.h>

#include <atomic>
#include <cassert>
#include <chrono>
#include <cmath>
#include <exception>
#include <memory>
#include <sstream>
#include <thread>
#include <unordered_map>

#include "apps/pipeline/bounded_queue.h"
#include "apps/pipeline/keyframe_conversion.h"
#include "calib/error.h"

namespace omni {

std::string PipelineOptions::Check() const {
  for (const auto& [name, check] :
       {std::pair<const char*, std::string>{"prefetch", prefetch.Check()},
        {"tracks", tracks.Check()},
        {"tracker", tracker.Check()},
        {"sculptor", sculptor.Check()},
        {"loop", loop.Check()}})
    if (!check.empty()) return std::string(name) + "." + check;
  if (queue_capacity < 1) return "queue_capacity: expected at least 1";
  if (max_frames < 0) return "max_frames: expected 0 (all) or more";
  if (snapshot_every < 0) return "snapshot_every: expected 0 (none) or more";
  if (!(progress_period > 0.0)) return "progress_period: expected a positive number of seconds";
  return {};
}

std::string PipelineFramesCsvHeader() {
  return "frame,name,loaded,corners,matched,tracked,keyframe,inliers,ms,status";
}

std::string PipelineFramesCsvRow(const PipelineFrameRow& row) {
  std::ostringstream o;
  std::string status = row.result.status;
  for (char& c : status)
    if (c == ',' || c == '\n') c = ';';
  o << row.frame << ',' << row.name << ',' << row.loaded << ',' << row.corners << ',' << row.matched
    << ',' << row.result.tracked << ',' << row.result.keyframe << ',' << row.result.inliers << ','
    << row.ms << ',' << status;
  return o.str();
}

std::string PipelineKeyframesCsvHeader() { return KeyframeStatsCsvHeader() + ",queue_ms,replay"; }

std::string PipelineKeyframesCsvRow(const PipelineKeyframeRow& row) {
  std::ostringstream o;
  o << KeyframeStatsCsvRow(row.surface) << ',' << row.queue_ms << ',' << row.replay;
  return o.str();
}

SculptorOptions ReplaySculptorOptions(const SculptorOptions& base, LoopReplay mode, double scale,
                                      size_t keyframes) {
  SculptorOptions options = base;
  if (mode != LoopReplay::kBatch || !(scale > 0.0) || keyframes == 0) return options;
  // One batch of them all, with the first sculpting's s so that the filters and the Steiner
  // grid keep their meaning (§5.1); the later keyframes one by one.
  options.scale = scale;
  options.init_keyframes = static_cast<int>(keyframes);
  options.batch_init = true;
  options.batch_with_known_scale = true;
  return options;
}

namespace {

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// One keyframe to sculpt, or (replay) every finalised keyframe of a corrected map.
struct QueuedKeyframe {
  std::vector<SurfaceKeyframe> keyframes;
  bool replay = false;
  Clock::time_point pushed;
};

}  // namespace

PipelineResult RunPipeline(const Drive& drive, const PipelineOptions& options,
                           const PipelineCallbacks& callbacks) {
  ThrowIfInvalid(options.Check(), "PipelineOptions");
  const Rig& rig = drive.rig();
  PipelineResult result;
  result.frames_total = options.max_frames > 0
                            ? std::min<size_t>(drive.NumFrames(), options.max_frames)
                            : drive.NumFrames();
  BoundedQueue<QueuedKeyframe> queue(static_cast<size_t>(options.queue_capacity));
  std::atomic<size_t> frames_done{0}, keyframes_sculpted{0}, triangles{0};
  std::atomic<int> num_keyframes{0}, num_points{0};
  std::atomic<bool> sfm_done{false}, surface_done{false}, abort{false};
  std::exception_ptr sfm_error, surface_error;
  const auto start = Clock::now();

  std::thread sfm_thread([&] {
    try {
      TrackBuilder builder(rig, options.tracks);
      Tracker tracker(rig, options.tracker);
      std::unique_ptr<LoopCloser> closer;
      if (options.loop_closure) closer = std::make_unique<LoopCloser>(rig, options.loop);
      auto hand_over = [&] {
        for (FinalizedKeyframe& keyframe : tracker.TakeFinalized()) {
          queue.Push({{ToSurfaceKeyframe(keyframe)}, false, Clock::now()});
          result.keyframes.push_back(std::move(keyframe));
        }
      };
      // Stopped and joined when this scope ends (an abort, an error, or the last frame).
      FramePrefetcher prefetcher(drive, result.frames_total, options.prefetch);
      for (size_t f = 0; f < result.frames_total && !abort; ++f) {
        const auto frame_start = Clock::now();
        PipelineFrameRow row;
        row.frame = f;
        row.name = drive.FrameName(f);
        std::optional<PrefetchedFrame> next = prefetcher.Next();
        if (!next) break;  // cannot happen: the prefetcher delivers every frame until stopped
        assert(next->frame == f);
        std::vector<cv::Mat> images;
        try {
          next->Rethrow();
          images = std::move(next->images);
          row.loaded = true;
        } catch (const InputError& error) {
          result.skipped.push_back("frame " + row.name + " skipped: " + error.what());
          spdlog::warn("{}", result.skipped.back());
          row.result.status = "skipped: unreadable image";
        }
        result.load_seconds += SecondsSince(frame_start);
        if (row.loaded) {
          const TrackedFrame frame = builder.AddFrame(images, ReprojectionPredictor(tracker, rig));
          row.corners = frame.num_corners;
          row.matched = frame.num_matched;
          row.result = tracker.AddFrame(frame.observations, builder.MapPointSearcher());
          if (!row.result.tracked)
            spdlog::warn("frame {}: not tracked ({})", row.name, row.result.status);
          hand_over();
          LoopClosureEvent event;
          const auto loop_start = Clock::now();
          std::vector<Rigid3d> poses_before;
          if (closer && row.result.keyframe) poses_before = tracker.KeyframePoses();
          const bool closed =
              closer && row.result.keyframe && closer->AddKeyframe(images, frame, &tracker, &event);
          if (closer && row.result.keyframe)
            result.loop_closure_seconds += SecondsSince(loop_start);
          if (closed) {
            spdlog::info("reconstruct: {}", event.Summary());
            result.loop_closures.push_back(event);
            double rotation_deg = 0.0;
            const std::vector<Rigid3d> poses_after = tracker.KeyframePoses();
            const size_t k = static_cast<size_t>(event.keyframe);
            if (k < poses_before.size() && k < poses_after.size())
              rotation_deg =
                  poses_after[k].rotation.angularDistance(poses_before[k].rotation) * 180.0 / M_PI;
            result.loop_correction_rotation_deg.push_back(rotation_deg);
            result.keyframes = tracker.FinalizedSnapshot();
            queue.Push({ToSurfaceKeyframes(result.keyframes), true, Clock::now()});
          }
          num_keyframes = tracker.NumKeyframes();
          num_points = tracker.NumPoints();
        }
        row.ms = 1e3 * SecondsSince(frame_start);
        result.frames.push_back(std::move(row));
        ++frames_done;
      }
      if (!abort) {
        tracker.Finish();
        hand_over();
        if (result.skipped.size() == result.frames_total)
          throw InputError(drive.folder().string(), "images", "no frame could be read");
        if (tracker.NumKeyframes() < 2)
          throw InputError(drive.folder().string(), "images",
                           "the SfM could not initialise (fewer than 2 keyframes)");
      }
      result.sfm_front = builder.StageTimings();
      result.sfm_back = tracker.StageTimings();
    } catch (...) {
      sfm_error = std::current_exception();
    }
    result.sfm_seconds = SecondsSince(start);
    queue.Close();  // the surface thread drains what is queued, then finishes
    sfm_done = true;
  });

  std::thread surface_thread([&] {
    try {
      auto sculptor = std::make_unique<IncrementalSculptor>(options.sculptor);
      std::unordered_map<uint32_t, double> queue_ms;
      int replay = 0;
      auto record = [&](const std::vector<KeyframeStats>& stats) {
        const size_t before = keyframes_sculpted;
        for (const KeyframeStats& s : stats) {
          const auto it = queue_ms.find(s.keyframe.value);
          result.surface_rows.push_back({s, it == queue_ms.end() ? 0.0 : it->second, replay});
          triangles = s.triangles;
        }
        keyframes_sculpted = sculptor->NumProcessedKeyframes();
        if (keyframes_sculpted < before) return;  // a replay began
        const size_t k = static_cast<size_t>(options.snapshot_every);
        if (k > 0 && callbacks.snapshot && !stats.empty() && keyframes_sculpted / k != before / k)
          callbacks.snapshot(stats.back().keyframe, sculptor->ExtractMesh());
      };
      while (std::optional<QueuedKeyframe> item = queue.Pop()) {
        const double waited =
            std::chrono::duration<double, std::milli>(Clock::now() - item->pushed).count();
        const auto busy = Clock::now();
        if (item->replay) {
          // The map was corrected: sculpt the corrected keyframes from scratch.
          ++replay;
          sculptor = std::make_unique<IncrementalSculptor>(ReplaySculptorOptions(
              options.sculptor, options.loop_replay, sculptor->scale(), item->keyframes.size()));
          keyframes_sculpted = 0;
        }
        for (const SurfaceKeyframe& keyframe : item->keyframes) {
          queue_ms[keyframe.id.value] = waited;
          record(sculptor->AddKeyframe(keyframe));
        }
        result.surface_seconds += SecondsSince(busy);
        if (item->replay) {
          const double replay_seconds = SecondsSince(busy);
          result.replay_seconds += replay_seconds;
          result.loop_replay_seconds.push_back(replay_seconds);
          result.loop_replay_keyframes.push_back(item->keyframes.size());
        }
      }
      if (!sfm_error) {
        const auto busy = Clock::now();
        record(sculptor->Finish());
        result.mesh = sculptor->ExtractMesh();
        result.surface_seconds += SecondsSince(busy);
      }
    } catch (...) {
      surface_error = std::current_exception();
      abort = true;
      queue.Close();
    }
    surface_done = true;
  });

  auto report = [&] {
    if (!callbacks.progress) return;
    PipelineProgress progress;
    progress.frames_done = frames_done;
    progress.frames_total = result.frames_total;
    progress.keyframes = num_keyframes;
    progress.points = num_points;
    progress.keyframes_sculpted = keyframes_sculpted;
    progress.triangles = triangles;
    progress.seconds = SecondsSince(start);
    callbacks.progress(progress);
  };
  auto last_report = Clock::now();
  while (!(sfm_done && surface_done)) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (SecondsSince(last_report) >= options.progress_period) {
      report();
      last_report = Clock::now();
    }
  }
  sfm_thread.join();
  surface_thread.join();
  if (sfm_error) std::rethrow_exception(sfm_error);
  if (surface_error) std::rethrow_exception(surface_error);
  report();
  result.seconds = SecondsSince(start);
  result.queue_max_size = queue.MaxSize();
  result.queue_blocked_pushes = queue.BlockedPushes();
  result.queue_blocked_seconds = queue.BlockedSeconds();
  return result;
}

}  // namespace omni
