#include "pipeline/sfm_runner.h"

#include <spdlog/spdlog.h>

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "calib/error.h"

namespace omni {
namespace {

using Clock = std::chrono::steady_clock;
double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// The distance between keyframe k and the one before it (k >= 1), as the map is now.
double KeyframeDistance(const Tracker& tracker, int k) {
  return (tracker.KeyframePose(k).translation - tracker.KeyframePose(k - 1).translation).norm();
}

// The final pose of `keyframe` in the run's keyframes, when it has one.
bool FinalKeyframePose(const SfmRunResult& run, int keyframe, Rigid3d* world_from_keyframe) {
  if (keyframe < 0 || static_cast<size_t>(keyframe) >= run.keyframes.size() ||
      run.keyframes[keyframe].keyframe != keyframe)
    return false;
  *world_from_keyframe = run.keyframes[keyframe].world_from_rig;
  return true;
}

// The tracker's options of a run: the frames keep their observations for the final refinement.
TrackerOptions RunnerTrackerOptions(const SfmRunnerOptions& options) {
  TrackerOptions tracker = options.tracker;
  if (options.final_frame_refinement || options.final_bundle_adjustment_frames)
    tracker.keep_frame_observations = true;
  return tracker;
}

// A tracked row's pose from its keyframes' final poses (see TrackedFramePoses).
Rigid3d BlendedFramePose(const SfmRunResult& run, const SfmFrameRow& row) {
  Rigid3d world_from_reference, world_from_next;
  if (!FinalKeyframePose(run, row.reference_keyframe, &world_from_reference))
    return row.result.world_from_rig;
  const Rigid3d from_reference = world_from_reference * row.keyframe_from_rig;
  if (!FinalKeyframePose(run, row.next_keyframe, &world_from_next)) return from_reference;
  const Rigid3d from_next = world_from_next * row.next_keyframe_from_rig;
  const double w = row.next_keyframe_weight;
  return Rigid3d(from_reference.rotation.slerp(w, from_next.rotation),
                 (1.0 - w) * from_reference.translation + w * from_next.translation);
}

}  // namespace

std::string SfmRunnerOptions::Check() const {
  for (const auto& [name, check] :
       {std::pair<const char*, std::string>{"prefetch", prefetch.Check()},
        {"tracks", tracks.Check()},
        {"tracker", tracker.Check()},
        {"loop", loop.Check()}})
    if (!check.empty()) return std::string(name) + "." + check;
  if (first_frame < 0) return "first_frame: expected 0 or more";
  if (max_frames < 0) return "max_frames: expected 0 (all) or more";
  if (!(usable_tracked_frames_share >= 0.0 && usable_tracked_frames_share <= 1.0))
    return "usable_tracked_frames_share: expected a share in [0, 1]";
  if (!(final_bundle_adjustment_tail_share >= 0.0 && final_bundle_adjustment_tail_share <= 1.0))
    return "final_bundle_adjustment_tail_share: expected a share in [0, 1]";
  if (final_bundle_adjustment_frames_max_keyframes < 0)
    return "final_bundle_adjustment_frames_max_keyframes: expected 0 (any) or a count";
  if (!(final_bundle_adjustment_merge_angle >= 0.0 && final_bundle_adjustment_merge_angle < 0.1))
    return "final_bundle_adjustment_merge_angle: expected 0 (none) or an angle below 0.1 rad";
  if (const std::string check = final_frame_refinement_checks.Check(); !check.empty())
    return "final_frame_refinement_checks." + check;
  if (!(min_metric_offset_depth_ratio >= 0.0))
    return "min_metric_offset_depth_ratio: expected a ratio of 0 or more";
  return {};
}

std::string SfmFramesCsvHeader() {
  return "frame,name,loaded,corners,matched,predicted,epipolar,relocalising,tracked,keyframe,"
         "inliers,ms,status";
}

std::string SfmFramesCsvRow(const SfmFrameRow& row) {
  std::string status = row.result.status;
  for (char& c : status)
    if (c == ',' || c == '\n') c = ';';
  std::ostringstream o;
  o << row.frame << ',' << row.name << ',' << row.loaded << ',' << row.corners << ',' << row.matched
    << ',' << row.predicted << ',' << row.epipolar << ',' << row.relocalising << ','
    << row.result.tracked << ',' << row.result.keyframe << ',' << row.result.inliers << ','
    << row.ms << ',' << status;
  return o.str();
}

const char* SfmOutcomeName(SfmOutcome outcome) {
  switch (outcome) {
    case SfmOutcome::kUsable:
      return "usable";
    case SfmOutcome::kNotInitialised:
      return "not_initialised";
    case SfmOutcome::kTrackingLost:
      return "tracking_lost";
  }
  return "unknown";
}

TrackBuilderOptions SfmFrontEndOptions(const SfmRunnerOptions& options) {
  TrackBuilderOptions tracks = options.tracks;
  if (options.tracker.central && !options.continuation_pool_in_central_mode)
    tracks.continuation_pool = 1.0;
  return tracks;
}

size_t SfmFramesToRun(const SfmRunnerOptions& options, size_t input_frames) {
  const size_t first = static_cast<size_t>(std::max(0, options.first_frame));
  const size_t available = input_frames > first ? input_frames - first : 0;
  return options.max_frames > 0 ? std::min<size_t>(available, options.max_frames) : available;
}

void ConfigureAllocatorForSfm() {
#ifdef __GLIBC__
  static std::once_flag once;
  std::call_once(once, [] {
    mallopt(M_MMAP_THRESHOLD, 256 << 20);
    mallopt(M_TRIM_THRESHOLD, 512 << 20);
  });
#endif
}

int FinalAdjustmentFirstFreeKeyframe(const SfmRunnerOptions& options, int num_keyframes,
                                     int keyframes_at_global_adjustment) {
  if (!options.final_bundle_adjustment_tail || keyframes_at_global_adjustment <= 0 ||
      keyframes_at_global_adjustment > num_keyframes)
    return 0;
  const int window = options.tracker.num_free_keyframes + options.tracker.num_fixed_keyframes;
  const int first_free = keyframes_at_global_adjustment - window;
  if (first_free <= 0) return 0;
  const int free = num_keyframes - first_free;
  return free <= options.final_bundle_adjustment_tail_share * num_keyframes ? first_free : 0;
}

SfmFrameSource DriveFrameSource(const Drive& drive) {
  SfmFrameSource source;
  source.folder = drive.folder().string();
  source.num_frames = drive.NumFrames();
  source.load = [&drive](size_t frame) { return LoadGrayFrame(drive, frame); };
  source.name = [&drive](size_t frame) { return drive.FrameName(frame); };
  return source;
}

struct SfmRunner::Impl {
  Impl(const Rig& rig_, const SfmRunnerOptions& options_, const SfmRunnerCallbacks& callbacks_)
      : rig(rig_),
        options(options_),
        callbacks(callbacks_),
        builder(rig_, SfmFrontEndOptions(options_)),
        tracker(rig_, RunnerTrackerOptions(options_)) {
    if (options.loop_closure) closer = std::make_unique<LoopCloser>(rig, options.loop);
  }

  // The tracker counts the frames it was given; a skipped frame is not given, so its frame
  // indices are mapped back to the input's.
  int InputFrame(int tracker_frame) const {
    return tracker_frame >= 0 && static_cast<size_t>(tracker_frame) < input_frames.size()
               ? static_cast<int>(input_frames[tracker_frame])
               : tracker_frame;
  }
  // The inverse: the tracker's index of an input frame, −1 when it was not given to the tracker.
  int TrackerFrame(size_t frame) const {
    const auto given = std::lower_bound(input_frames.begin(), input_frames.end(), frame);
    return given != input_frames.end() && *given == frame
               ? static_cast<int>(given - input_frames.begin())
               : -1;
  }

  // The row's pose relative to keyframe `keyframe` (none when the tracker has no such
  // keyframe).
  void SetReference(SfmFrameRow* row, int keyframe) const {
    row->reference_keyframe = -1;
    if (keyframe < 0 || keyframe >= tracker.NumKeyframes()) return;
    row->reference_keyframe = keyframe;
    row->keyframe_from_rig = tracker.KeyframePose(keyframe).Inverse() * row->result.world_from_rig;
  }
  // The row's pose relative to keyframe `keyframe`, a keyframe after it, as it is now in the
  // map: the pose its reference keyframe carries it to, its offset from the reference scaled by
  // `scale` (the change of the map's scale since the row was tracked); the offset from the
  // reference is kept at that scale too, so that both describe the frame in one state of the map.
  void SetNextReference(SfmFrameRow* row, int keyframe, double scale = 1.0) const {
    if (!options.frame_poses_between_keyframes || !row->result.tracked || row->result.keyframe ||
        row->reference_keyframe < 0 || row->next_keyframe >= 0 ||
        keyframe <= row->reference_keyframe || keyframe >= tracker.NumKeyframes())
      return;
    row->keyframe_from_rig.translation *= scale;
    const Rigid3d world_from_rig =
        tracker.KeyframePose(row->reference_keyframe) * row->keyframe_from_rig;
    const Rigid3d next_from_rig = tracker.KeyframePose(keyframe).Inverse() * world_from_rig;
    const double to_reference = row->keyframe_from_rig.translation.norm();
    const double to_next = next_from_rig.translation.norm();
    row->next_keyframe = keyframe;
    row->next_keyframe_from_rig = next_from_rig;
    row->next_keyframe_weight =
        to_reference + to_next > 0.0 ? to_reference / (to_reference + to_next) : 0.0;
  }
  // A new keyframe: the tracked frames since the previous keyframe row get it as their next.
  // `scale`: the change of scale of the new keyframe's adjustment (its previous two keyframes'
  // distance after it over before).
  void SetNextReferences(int keyframe, double scale) {
    if (result.frames.empty()) return;
    for (size_t r = result.frames.size(); r-- > 0;) {
      SfmFrameRow& row = result.frames[r];
      if (row.result.keyframe) break;
      SetNextReference(&row, keyframe, scale);
    }
  }
  // The first keyframe made from a frame after input frame `frame` (-1: none).
  int KeyframeAfter(size_t frame) const {
    const std::vector<int> frames = tracker.KeyframeFrames();
    for (size_t k = 0; k < frames.size(); ++k)
      if (InputFrame(frames[k]) > static_cast<int>(frame)) return static_cast<int>(k);
    return -1;
  }
  // The tracker's second thoughts on earlier frames (see Tracker::TakeRevisedFrames).
  void ApplyRevisions() {
    for (Tracker::RevisedFrame& revision : tracker.TakeRevisedFrames()) {
      const size_t input = static_cast<size_t>(InputFrame(revision.frame));
      auto row =
          std::lower_bound(result.frames.begin(), result.frames.end(), input,
                           [](const SfmFrameRow& r, size_t frame) { return r.frame < frame; });
      if (row == result.frames.end() || row->frame != input) continue;
      row->result = revision.result;
      // Frames resected in a new map: relative to its first keyframe.
      SetReference(&*row, row->result.tracked ? 0 : -1);
      row->next_keyframe = -1;
      SetNextReference(&*row, KeyframeAfter(row->frame));
      if (!row->result.tracked)
        spdlog::warn("frame {}: not tracked ({})", row->name, row->result.status);
    }
  }

  // A keyframe's and its frame rays' frames, the input's.
  void ToInputFrames(FinalizedKeyframe* keyframe) const {
    keyframe->frame = InputFrame(keyframe->frame);
    for (FinalizedPoint& point : keyframe->points)
      for (FinalizedFrameRay& ray : point.frame_rays) ray.frame = InputFrame(ray.frame);
  }

  void HandOver() {
    for (FinalizedKeyframe& keyframe : tracker.TakeFinalized()) {
      ToInputFrames(&keyframe);
      if (callbacks.keyframe_finalised) callbacks.keyframe_finalised(keyframe);
      result.keyframes.push_back(std::move(keyframe));
    }
  }

  // After a correction of the map (a loop closure, the final adjustment): every finalised
  // keyframe rebuilt from the corrected map, handed over again.
  void HandOverCorrectedMap() {
    result.keyframes = tracker.FinalizedSnapshot();
    for (FinalizedKeyframe& keyframe : result.keyframes) ToInputFrames(&keyframe);
    if (callbacks.map_corrected) callbacks.map_corrected(result.keyframes);
  }

  // SfmRunnerOptions::final_frame_refinement, on the final map.
  void RefineFramePoses() {
    const auto start = Clock::now();
    double rms_before = 0.0, rms_after = 0.0;
    for (SfmFrameRow& row : result.frames) {
      if (row.pose_adjusted) continue;  // adjusted with the final map (final_adjusted_frames)
      row.pose_refined = false;
      if (!row.result.tracked || row.result.keyframe) continue;
      const int tracker_frame = TrackerFrame(row.frame);
      if (tracker_frame < 0) continue;
      ++result.frames_refinement_tried;
      const FramePoseRefinement refinement = tracker.RefineFramePose(
          tracker_frame, BlendedFramePose(result, row), options.final_frame_refinement_checks);
      if (!refinement.refined) continue;
      row.pose_refined = true;
      row.refined_world_from_rig = refinement.world_from_rig;
      ++result.frames_refined;
      rms_before += refinement.rms_angle_before;
      rms_after += refinement.rms_angle_after;
    }
    result.final_frame_refinement_seconds = SecondsSince(start);
    if (result.frames_refinement_tried == 0) return;  // none left (all adjusted with the map)
    const double refined = static_cast<double>(std::max<size_t>(1, result.frames_refined));
    spdlog::info(
        "sfm: {} of {} frames between keyframes refined against the final map in {:.2f} s: mean "
        "RMS angle {:.4f} -> {:.4f} degrees",
        result.frames_refined, result.frames_refinement_tried,
        result.final_frame_refinement_seconds, rms_before / refined * 180.0 / M_PI,
        rms_after / refined * 180.0 / M_PI);
  }

  const Rig& rig;
  const SfmRunnerOptions options;
  const SfmRunnerCallbacks callbacks;
  TrackBuilder builder;
  Tracker tracker;
  std::unique_ptr<LoopCloser> closer;
  SfmRunResult result;
  std::vector<size_t> input_frames;  // input frame of each frame given to the tracker
  Clock::time_point start = Clock::now();
};

SfmRunner::SfmRunner(const Rig& rig, const SfmRunnerOptions& options,
                     const SfmRunnerCallbacks& callbacks) {
  ThrowIfInvalid(options.Check(), "SfmRunnerOptions");
  impl_ = std::make_unique<Impl>(rig, options, callbacks);
}

SfmRunner::~SfmRunner() = default;

const Tracker& SfmRunner::tracker() const { return impl_->tracker; }

const SfmFrameRow& SfmRunner::AddFrame(PrefetchedFrame frame, const std::string& name,
                                       double wait_seconds) {
  Impl& s = *impl_;
  SfmRunResult& result = s.result;
  const auto frame_start = Clock::now();
  SfmFrameRow row;
  row.frame = frame.frame;
  row.name = name;
  result.load_seconds += wait_seconds;
  if (frame.error) {
    try {
      frame.Rethrow();
    } catch (const InputError& error) {
      result.skipped.push_back("frame " + name + " skipped: " + error.what());
      spdlog::warn("{}", result.skipped.back());
      row.result.status = "skipped: unreadable image";
    }
  } else {
    row.loaded = true;
    const PixelPredictor predict = ReprojectionPredictor(s.tracker, s.rig);
    const std::optional<RigMotion> motion = PredictedMotion(s.tracker);
    TrackedFrame tracked =
        frame.corners ? s.builder.AddDetectedFrame(std::move(*frame.corners), predict, motion)
                      : s.builder.AddFrame(frame.images, predict, motion);
    row.corners = tracked.num_corners;
    row.matched = tracked.num_matched;
    row.predicted = tracked.num_predicted;
    row.epipolar = tracked.num_epipolar;
    row.relocalising = tracked.relocalising;
    s.input_frames.push_back(row.frame);
    Tracker& tracker = s.tracker;
    if (s.options.stereo_matching && !s.options.tracker.central && !tracker.Initialised()) {
      const int stereo = s.builder.MatchOverlappingCameras(&tracked);
      spdlog::debug("frame {}: {} matches between overlapping cameras", name, stereo);
    }
    // The newest two keyframes before the frame: a new keyframe's adjustment may rescale them.
    const int keyframes_before = tracker.NumKeyframes();
    const double distance_before =
        keyframes_before >= 2 ? KeyframeDistance(tracker, keyframes_before - 1) : 0.0;
    row.result = tracker.AddFrame(tracked.observations, s.builder.MapPointSearcher());
    if (!row.result.tracked && s.options.descriptor_retry) {
      // Without a map only the first keyframe can help (the last tracked frame).
      const int references = tracker.Initialised() ? s.builder.NumRematchReferences()
                                                   : std::min(1, s.builder.NumRematchReferences());
      for (int reference = 0; reference < references && !row.result.tracked; ++reference) {
        // A frame that started the map (or became its keyframe) has nothing to retry.
        if (!tracker.CanRetryFrame()) break;
        if (!s.builder.RematchByDescriptors(reference, &tracked, [&tracker](int track) {
              Eigen::Vector3d position;
              return tracker.TrackPosition(track, &position);
            }))
          break;
        const FrameResult retry =
            tracker.RetryFrame(tracked.observations, s.builder.MapPointSearcher());
        row.matched = tracked.num_matched;
        row.relocalising = true;
        spdlog::debug("frame {}: by descriptors against reference {}: {} matched, {}", name,
                      reference, tracked.num_matched, retry.tracked ? "tracked" : retry.status);
        if (!retry.tracked) continue;
        row.result = retry;
        row.result.status += " (by descriptors, reference " + std::to_string(reference) + ")";
      }
    }
    s.builder.SetFrameResult(row.result.tracked, row.result.keyframe);
    if (row.result.tracked) {
      s.SetReference(&row, s.tracker.NumKeyframes() - 1);  // the newest keyframe
      if (row.result.keyframe) {
        double scale = 1.0;
        if (distance_before > 0.0 && tracker.NumKeyframes() == keyframes_before + 1) {
          const double distance_after = KeyframeDistance(tracker, keyframes_before - 1);
          if (distance_after > 0.0) scale = distance_after / distance_before;
        }
        s.SetNextReferences(tracker.NumKeyframes() - 1, scale);
      }
    } else if (!tracker.Initialised()) {
      // Held until the map starts: resected then (a warning only if that fails, below).
      spdlog::info("frame {}: not tracked yet ({})", name, row.result.status);
    } else {
      spdlog::warn("frame {}: not tracked ({}){}", name, row.result.status,
                   tracked.relocalising ? ", re-localising against the last keyframes" : "");
    }
    s.ApplyRevisions();
    s.HandOver();
    if (s.closer && row.result.keyframe) {
      const auto loop_start = Clock::now();
      const std::vector<Rigid3d> poses_before = s.tracker.KeyframePoses();
      LoopClosureEvent event;
      const bool closed = s.closer->AddKeyframe(frame.images, tracked, &s.tracker, &event);
      result.loop_closure_seconds += SecondsSince(loop_start);
      if (closed) {
        event.frame = s.InputFrame(event.frame);
        event.candidate_frame = s.InputFrame(event.candidate_frame);
        spdlog::info("sfm: {}", event.Summary());
        SfmLoopClosure closure;
        closure.event = event;
        const std::vector<Rigid3d> poses_after = s.tracker.KeyframePoses();
        const size_t k = static_cast<size_t>(event.keyframe);
        if (k < poses_before.size() && k < poses_after.size())
          closure.correction_rotation_deg =
              poses_after[k].rotation.angularDistance(poses_before[k].rotation) * 180.0 / M_PI;
        result.loop_closures.push_back(closure);
        s.HandOverCorrectedMap();
      }
    }
  }
  row.ms = 1e3 * (wait_seconds + SecondsSince(frame_start));
  result.frames.push_back(std::move(row));
  ++result.frames_total;
  const SfmFrameRow& done = result.frames.back();
  if (s.callbacks.frame_done)
    s.callbacks.frame_done(done, s.tracker.NumKeyframes(), s.tracker.NumPoints());
  return done;
}

SfmRunResult SfmRunner::Finish() {
  Impl& s = *impl_;
  s.tracker.Finish();
  s.HandOver();
  SfmRunResult& result = s.result;
  const TrackBuilderOptions front_end = SfmFrontEndOptions(s.options);
  result.corners_per_image = front_end.harris.max_corners;
  result.corner_quality = front_end.harris.quality_level;
  result.min_tracked_share = s.options.tracker.keyframes.min_tracked_share;
  result.min_followed_track_share = s.options.tracker.keyframes.min_followed_track_share;
  result.continuation_pool = front_end.continuation_pool;
  result.epipolar_min_depth = front_end.epipolar_min_depth;
  result.epipolar_search_radius = front_end.epipolar_search_radius;
  result.epipolar_max_search_radius = front_end.epipolar_max_search_radius;
  result.epipolar_matches = 0;
  for (const SfmFrameRow& row : result.frames) result.epipolar_matches += row.epipolar;
  if (s.options.final_bundle_adjustment && s.tracker.NumKeyframes() >= 3) {
    const auto ba_start = Clock::now();
    int points_merged = 0;
    const int keyframes_at_global_adjustment = s.tracker.KeyframesAtLastGlobalAdjustment();
    const int first_free = FinalAdjustmentFirstFreeKeyframe(s.options, s.tracker.NumKeyframes(),
                                                            keyframes_at_global_adjustment);
    // SfmRunnerOptions::final_bundle_adjustment_frames: the tracked frames after the first free
    // keyframe, from their poses between their keyframes.
    std::vector<AdjustedFrame> frames;
    std::vector<size_t> frame_rows;
    const int max_keyframes = s.options.final_bundle_adjustment_frames_max_keyframes;
    const bool with_frames =
        s.options.final_bundle_adjustment_frames &&
        (max_keyframes == 0 || s.tracker.NumKeyframes() - first_free <= max_keyframes);
    if (with_frames) {
      for (size_t r = 0; r < result.frames.size(); ++r) {
        const SfmFrameRow& row = result.frames[r];
        if (!row.result.tracked || row.result.keyframe || row.reference_keyframe < first_free)
          continue;
        const int tracker_frame = s.TrackerFrame(row.frame);
        if (tracker_frame < 0) continue;
        frames.push_back({tracker_frame, BlendedFramePose(result, row)});
        frame_rows.push_back(r);
      }
    }
    const BundleAdjustmentSummary summary = s.tracker.GlobalBundleAdjust(
        s.options.final_bundle_adjustment_true_offsets,
        s.options.final_bundle_adjustment_merge_angle, &points_merged, first_free, 0.0,
        with_frames ? &frames : nullptr, s.options.final_frame_refinement_checks.min_inliers);
    if (summary.success) {
      for (size_t i = 0; i < frames.size(); ++i) {
        if (!frames[i].adjusted) continue;
        SfmFrameRow& row = result.frames[frame_rows[i]];
        row.pose_adjusted = true;
        row.pose_refined = true;
        row.refined_world_from_rig = frames[i].world_from_rig;
        ++result.final_adjusted_frames;
      }
    }
    result.final_bundle_adjustment_seconds = SecondsSince(ba_start);
    if (summary.success) {
      result.final_rms_angle_before = summary.rms_angle_before;
      result.final_rms_angle_after = summary.rms_angle_after;
      result.final_free_keyframes = s.tracker.NumKeyframes() - first_free;
      s.HandOverCorrectedMap();
      spdlog::info(
          "sfm: final bundle adjustment of {} keyframes ({}) and {} frames in {:.2f} s: RMS angle "
          "{:.4f} -> {:.4f} degrees, {} iterations, {} outliers, {} points fused; camera offsets "
          "{}",
          result.keyframes.size(),
          first_free > 0 ? fmt::format("the last {} free, since the global adjustment at {}",
                                       result.final_free_keyframes, keyframes_at_global_adjustment)
                         : std::string("all free"),
          result.final_adjusted_frames, result.final_bundle_adjustment_seconds,
          summary.rms_angle_before * 180.0 / M_PI, summary.rms_angle_after * 180.0 / M_PI,
          summary.num_iterations, summary.removed_observations.size(), points_merged,
          s.options.tracker.central && s.options.final_bundle_adjustment_true_offsets
              ? fmt::format("true, {:.3f} map units per metre", summary.offset_scale)
              : std::string(s.options.tracker.central ? "none (central)" : "true, metric"));
    } else {
      spdlog::warn("sfm: the final bundle adjustment failed; the map is kept as it was");
    }
  }
  if (s.options.final_frame_refinement && s.tracker.Initialised()) s.RefineFramePoses();
  result.model_keyframes = s.tracker.FinalizedSnapshot(/*all_rays=*/true);
  for (FinalizedKeyframe& keyframe : result.model_keyframes) s.ToInputFrames(&keyframe);
  result.front = s.builder.StageTimings();
  result.back = s.tracker.StageTimings();
  result.seconds = SecondsSince(s.start);
  // What was tracked, after the revisions of the frames read while initialising.
  result.frames_tracked = 0;
  result.lost_from = 0;
  result.untracked_runs.clear();
  bool seen_tracked = false;
  for (size_t i = 0; i < result.frames.size(); ++i) {
    const SfmFrameRow& row = result.frames[i];
    if (row.result.tracked) {
      ++result.frames_tracked;
      result.lost_from = i + 1;
      seen_tracked = true;
    } else if (row.loaded && seen_tracked) {
      if (!result.untracked_runs.empty() && result.untracked_runs.back().last + 1 == i)
        result.untracked_runs.back().last = i;
      else
        result.untracked_runs.push_back({i, i, false});
    }
  }
  if (!result.untracked_runs.empty() &&
      result.untracked_runs.back().last + 1 == result.frames.size())
    result.untracked_runs.back().to_the_end = true;
  for (const SfmUntrackedRun& run : result.untracked_runs) {
    if (run.to_the_end) continue;
    spdlog::warn("sfm: frames {} to {} ({}) were not tracked; tracking resumed at frame {}",
                 result.frames[run.first].name, result.frames[run.last].name,
                 run.last - run.first + 1, result.frames[run.last + 1].name);
  }
  result.scale_source = s.tracker.ScaleSource();
  result.metric_scale = s.tracker.MetricScale();
  result.largest_camera_offset = s.rig.MaxCenterOffset();
  result.median_point_depth = s.tracker.MedianPointDepth();
  if (result.median_point_depth > 0.0)
    result.offset_depth_ratio = result.largest_camera_offset / result.median_point_depth;
  if (result.metric_scale &&
      !(result.offset_depth_ratio >= s.options.min_metric_offset_depth_ratio)) {
    result.metric_scale = false;
    result.scale_source = fmt::format(
        "arbitrary, near metres (the rig's camera offsets are {:.2g} % of the points' median "
        "depth, below the {:.2g} % that makes them fix the scale to a few per cent; the scale came "
        "from: {})",
        100.0 * result.offset_depth_ratio, 100.0 * s.options.min_metric_offset_depth_ratio,
        result.scale_source);
  }
  if (!result.scale_source.empty())
    spdlog::info("sfm: scale {}; largest camera offset {:.3f} m, median point depth {:.2f}",
                 result.scale_source, result.largest_camera_offset, result.median_point_depth);
  const size_t read = result.frames_total - result.skipped.size();
  const size_t lost_tail = result.frames_total - std::min(result.lost_from, result.frames_total);
  if (!s.tracker.Initialised()) {
    result.outcome = SfmOutcome::kNotInitialised;
    std::ostringstream why;
    why << "the SfM could not initialise (no two frames with enough parallax, no stereo map; "
        << result.frames_tracked << " of " << read << " frames read were tracked)";
    result.outcome_reason = why.str();
  } else if (static_cast<double>(result.frames_tracked) <
             s.options.usable_tracked_frames_share * static_cast<double>(read)) {
    result.outcome = SfmOutcome::kTrackingLost;
    std::ostringstream why;
    why << "tracking was lost: " << result.frames_tracked << " of " << read
        << " frames read were tracked";
    if (lost_tail > 0 && result.lost_from < result.frames.size())
      why << ", none from frame " << result.frames[result.lost_from].name << " on";
    why << " (below " << 100.0 * s.options.usable_tracked_frames_share << " %)";
    result.outcome_reason = why.str();
  } else {
    result.outcome = SfmOutcome::kUsable;
    std::ostringstream what;
    what << result.frames_tracked << " of " << read << " frames read were tracked";
    if (lost_tail > 0 && result.lost_from < result.frames.size())
      what << "; tracking was lost from frame " << result.frames[result.lost_from].name
           << " to the end (" << lost_tail << " frames)";
    result.outcome_reason = what.str();
    if (lost_tail > 0) spdlog::warn("sfm: {}", result.outcome_reason);
  }
  return std::move(result);
}

std::vector<SfmFramePose> TrackedFramePoses(const SfmRunResult& run) {
  std::vector<SfmFramePose> poses;
  for (const SfmFrameRow& row : run.frames) {
    if (!row.result.tracked) continue;
    poses.push_back(
        {row.frame, row.pose_refined ? row.refined_world_from_rig : BlendedFramePose(run, row)});
  }
  return poses;
}

SfmRunResult RunSfm(const Rig& rig, const SfmFrameSource& source, const SfmRunnerOptions& options,
                    const SfmRunnerCallbacks& callbacks) {
  ConfigureAllocatorForSfm();
  SfmRunner runner(rig, options, callbacks);
  const size_t num_frames = SfmFramesToRun(options, source.num_frames);
  bool stopped = false;
  {
    // Stopped and joined when this scope ends (a stop, an error, or the last frame).
    const size_t first = static_cast<size_t>(options.first_frame);
    FramePrefetcher::Prepare detect;
    if (options.detect_ahead) {
      const TrackBuilderOptions front_end = SfmFrontEndOptions(options);
      detect = [harris = FrontEndHarrisOptions(front_end),
                half_window = front_end.zncc.half_window](PrefetchedFrame* frame) {
        frame->corners = DetectFrameCorners(frame->images, harris, half_window);
      };
    }
    FramePrefetcher prefetcher(
        num_frames, [&source, first](size_t f) { return source.load(first + f); }, options.prefetch,
        std::move(detect));
    for (size_t f = first; f < first + num_frames; ++f) {
      if (callbacks.stop && callbacks.stop()) {
        stopped = true;
        break;
      }
      const auto wait_start = Clock::now();
      std::optional<PrefetchedFrame> next = prefetcher.Next();
      if (!next) break;      // cannot happen: the prefetcher delivers every frame until stopped
      next->frame += first;  // the input's index
      const double waited = SecondsSince(wait_start);
      runner.AddFrame(std::move(*next), source.name(f), waited);
    }
  }
  SfmRunResult result = runner.Finish();
  if (stopped) return result;
  if (!result.frames.empty() && result.skipped.size() == result.frames.size())
    throw InputError(source.folder, "images", "no frame could be read");
  return result;
}

}  // namespace omni
