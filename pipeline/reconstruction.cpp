#include "pipeline/reconstruction.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <unordered_map>

#include "calib/error.h"
#include "pipeline/bounded_queue.h"
#include "pipeline/keyframe_conversion.h"
#include "pipeline/thread_priority.h"

namespace omni {

SculptorOptions PipelineOptions::DefaultSculptor() {
  SculptorOptions sculptor;
  sculptor.keyframes_per_step = 3;
  // A second round of enclosed free cells: on the SfM's points it lowers the false matter in
  // front of the walls on every drive measured (on the perfect SfM's, `surface --from-gt`, it
  // does not: the surface command keeps one; docs/figures.md F58).
  sculptor.enclosed_free_rounds = 2;
  // The aperture bound at 4° instead of 5°: the SfM's points with the narrower apertures fill
  // holes of surface.ply and bound the closed δO better (F@0.5 +0.002 to +0.012 and the closed
  // q90 7 to 41 cm lower on nine drives and modes, docs/figures.md F59).
  sculptor.min_aperture_deg = 4.0;
  // The rays of the points that this bound drops (a third of the SfM's points on demo) still
  // carve, 0.1° short of them: F@0.2 and F@0.5 higher on ten runs of ten (six drives, both
  // modes) and the errors above 1 m in front of the truth lower on nine; `surface --from-gt`,
  // whose points are exact, keeps 0 (docs/figures.md F66).
  sculptor.uncertain_ray_margin_deg = 0.1;
  return sculptor;
}

std::string PipelineOptions::Check() const {
  for (const auto& [name, check] :
       {std::pair<const char*, std::string>{"sfm", sfm.Check()}, {"sculptor", sculptor.Check()}})
    if (!check.empty()) return std::string(name) + "." + check;
  if (queue_capacity < 1) return "queue_capacity: expected at least 1";
  if (surface_thread_nice < 0 || surface_thread_nice > 19)
    return "surface_thread_nice: expected 0 to 19";
  if (snapshot_every < 0) return "snapshot_every: expected 0 (none) or more";
  if (!(progress_period > 0.0)) return "progress_period: expected a positive number of seconds";
  return {};
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

double ReplayScale(double scale, double reference_spacing,
                   const std::vector<SurfaceKeyframe>& keyframes, size_t count, double max_change,
                   double* new_spacing) {
  const double spacing = MeanKeyframeSpacing(keyframes, count);
  if (new_spacing) *new_spacing = spacing;
  if (!(scale > 0.0) || !(reference_spacing > 0.0) || !(spacing > 0.0)) return scale;
  const double ratio = spacing / reference_spacing;
  if (ratio <= max_change && ratio >= 1.0 / max_change) return scale;
  return scale * ratio;
}

namespace {

// Every keyframe in one batch at s.
FinalBatch SculptOneBatch(const SculptorOptions& base, double scale,
                          const std::vector<SurfaceKeyframe>& keyframes) {
  FinalBatch batch;
  const auto start = std::chrono::steady_clock::now();
  batch.sculptor = std::make_unique<IncrementalSculptor>(
      ReplaySculptorOptions(base, LoopReplay::kBatch, scale, keyframes.size()));
  for (const SurfaceKeyframe& keyframe : keyframes) {
    for (const KeyframeStats& st : batch.sculptor->AddKeyframe(keyframe)) batch.stats.push_back(st);
  }
  for (const KeyframeStats& st : batch.sculptor->Finish()) batch.stats.push_back(st);
  batch.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return batch;
}

}  // namespace

FinalBatch SculptFinalBatch(const SculptorOptions& base, const IncrementalSculptor& streamed,
                            const std::vector<KeyframeStats>& streamed_stats,
                            const std::vector<SurfaceKeyframe>& keyframes) {
  const bool incremental = std::any_of(streamed_stats.begin(), streamed_stats.end(),
                                       [](const KeyframeStats& st) { return !st.batch; });
  if (!(streamed.scale() > 0.0) || !incremental) return {};
  FinalBatch batch = SculptOneBatch(base, streamed.scale(), keyframes);
  batch.keyframe_spacing = streamed.keyframe_spacing();
  return batch;
}

FinalBatch SculptBatchOnly(const SculptorOptions& base,
                           const std::vector<SurfaceKeyframe>& keyframes) {
  // The keyframe-by-keyframe sculpting sculpts one by one what comes after its first batch.
  const bool incremental = !base.batch_init || (base.scale > 0.0 && !base.batch_with_known_scale) ||
                           keyframes.size() > static_cast<size_t>(base.init_keyframes);
  double spacing = 0.0;
  const double scale = MeasureScale(base, keyframes, &spacing);
  if (!(scale > 0.0) || !incremental) return {};
  FinalBatch batch = SculptOneBatch(base, scale, keyframes);
  batch.keyframe_spacing = spacing;
  return batch;
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
  PipelineResult result;
  const SfmFrameSource source = DriveFrameSource(drive);
  const size_t frames_total = SfmFramesToRun(options.sfm, source.num_frames);
  BoundedQueue<QueuedKeyframe> queue(static_cast<size_t>(options.queue_capacity));
  std::atomic<size_t> frames_done{0}, keyframes_sculpted{0}, triangles{0};
  std::atomic<int> num_keyframes{0}, num_points{0};
  std::atomic<bool> sfm_done{false}, surface_done{false}, abort{false};
  std::exception_ptr sfm_error, surface_error;
  const auto start = Clock::now();

  std::thread sfm_thread([&] {
    try {
      SfmRunnerCallbacks sfm_callbacks;
      sfm_callbacks.keyframe_finalised = [&queue](const FinalizedKeyframe& keyframe) {
        queue.Push({{ToSurfaceKeyframe(keyframe)}, false, Clock::now()});
      };
      sfm_callbacks.map_corrected = [&queue](const std::vector<FinalizedKeyframe>& keyframes) {
        queue.Push({ToSurfaceKeyframes(keyframes), true, Clock::now()});
      };
      sfm_callbacks.frame_done = [&](const SfmFrameRow&, int keyframes, int points) {
        num_keyframes = keyframes;
        num_points = points;
        ++frames_done;
      };
      sfm_callbacks.stop = [&abort] { return abort.load(); };
      result.sfm = RunSfm(drive.rig(), source, options.sfm, sfm_callbacks);
    } catch (...) {
      sfm_error = std::current_exception();
    }
    queue.Close();  // the surface thread drains what is queued, then finishes
    // The SfM's result is final: the caller's work on it overlaps the surface's last keyframes
    // (a loop closure's or the final adjustment's replay, the final smoothing).
    if (!sfm_error && !abort && callbacks.sfm_finished) {
      try {
        callbacks.sfm_finished(result.sfm, queue.BlockedSeconds());
      } catch (...) {
        sfm_error = std::current_exception();
      }
    }
    sfm_done = true;
  });

  std::thread surface_thread([&] {
    LowerThisThreadPriority(options.surface_thread_nice, "surface");
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
        if (k > 0 && callbacks.snapshot && !stats.empty() && keyframes_sculpted / k != before / k) {
          PipelineSnapshot snapshot;
          snapshot.last_keyframe = stats.back().keyframe;
          snapshot.closed = sculptor->ExtractMesh();
          snapshot.observed = sculptor->ExtractObservedMesh(&snapshot.observed_points);
          callbacks.snapshot(snapshot);
        }
      };
      // A replay re-sculpts every keyframe from scratch: the keyframes queued before it are
      // skipped, once the sculptor's s is known (the replay takes that s, so the surface is
      // the same whether the surface thread was behind or not).
      const auto supersedes = [&](const QueuedKeyframe& queued) {
        return options.skip_superseded_keyframes && queued.replay && sculptor->scale() > 0.0;
      };
      const auto skip = [&](const QueuedKeyframe& queued) {
        result.surface_keyframes_skipped += queued.keyframes.size();
        if (!queued.replay) return;
        // A replay skipped for a later one keeps its number and its entry (0 s, 0 keyframes).
        ++replay;
        result.loop_replay_seconds.push_back(0.0);
        result.loop_replay_keyframes.push_back(0);
      };
      // The first sculptor's keyframe spacing, which its s was measured with (the reference of
      // ReplayScale).
      double reference_spacing = 0.0;
      while (std::optional<QueuedKeyframe> item = queue.PopLatest(supersedes, skip)) {
        const double waited =
            std::chrono::duration<double, std::milli>(Clock::now() - item->pushed).count();
        const auto busy = Clock::now();
        if (item->replay) {
          // The map was corrected: sculpt the corrected keyframes from scratch, at the first
          // sculpting's s unless the correction rescaled the map.
          ++replay;
          if (reference_spacing == 0.0) reference_spacing = sculptor->keyframe_spacing();
          double spacing = 0.0;
          const double scale =
              ReplayScale(sculptor->scale(), reference_spacing, item->keyframes,
                          static_cast<size_t>(options.sculptor.init_keyframes), 1.25, &spacing);
          if (scale != sculptor->scale()) {
            spdlog::warn(
                "surface: the corrected map's keyframes are {:.3g} times as far apart as when s "
                "was measured (the SfM's map was rescaled): s {:.4g} -> {:.4g}",
                spacing / reference_spacing, sculptor->scale(), scale);
            reference_spacing = spacing;
          }
          sculptor = std::make_unique<IncrementalSculptor>(ReplaySculptorOptions(
              options.sculptor, options.loop_replay, scale, item->keyframes.size()));
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
        result.closed_mesh = sculptor->ExtractMesh(&result.closed_mesh_points);
        result.mesh = sculptor->ExtractObservedMesh(&result.mesh_points, &result.observed);
        result.final_smoothing = sculptor->DeferredSmoothingStats();
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
    progress.frames_total = frames_total;
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
