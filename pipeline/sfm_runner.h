#pragma once
// The one per-frame SfM loop of `omnisculpt sfm`, `omnisculpt reconstruct` and the SfM
// benchmark. For each frame, in order: the prefetched images (pipeline/frame_prefetcher.h; a
// frame whose image cannot be read is reported and skipped) → the image front end
// (sfm/track_builder.h, search regions by reprojection once the pose is predicted) → the tracker
// (sfm/tracker.h: resection, triangulation, keyframes, local bundle adjustment) → what the
// tracker made of the frame back to the front end (a keyframe becomes the reference of a later
// re-localisation; after a frame not tracked the next ones are matched against it) → the loop
// closer on each new keyframe (sfm/loop_closure.h) → the keyframes that left the local window,
// handed over in order. One row per frame (stats/sfm_frames.csv) and the run's outcome: did it
// give a usable map, and if not, why.

#include <cstddef>
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/drive.h"
#include "calib/rig.h"
#include "pipeline/frame_prefetcher.h"
#include "sfm/loop_closure.h"
#include "sfm/track_builder.h"
#include "sfm/tracker.h"

namespace omni {

struct SfmRunnerOptions {
  FramePrefetcherOptions prefetch;
  // Each frame's Harris corners are detected on the prefetch thread, ahead of its tracking
  // (DetectFrameCorners), so that the SfM thread spends its time on tracking and detection
  // uses a core the tracking leaves idle; the result is the same either way.
  bool detect_ahead = true;
  TrackBuilderOptions tracks;
  // Central mode (tracker.central): false: the front end continues its tracks without the pool
  // there (tracks.continuation_pool taken as 1). On by default in both modes: in central mode
  // the pool raised the surface's pixel F@0.5 on every drive measured (+0.014 to +0.022 on five
  // multi-camera drives) and kept a single camera from losing its way (no ATE above 6 cm in 12
  // runs, against 15 and 75 cm in two of 12 without it), at a median ATE 1.2 times that of a
  // run without it that did not fail (docs/figures.md F50, F62).
  bool continuation_pool_in_central_mode = true;
  TrackerOptions tracker;
  // Revisits recognised among the old keyframes, verified, and the map corrected (pose graph
  // and global bundle adjustment); the corrected finalised keyframes are handed over again.
  bool loop_closure = true;
  LoopClosureOptions loop;
  // When the input ends: a global bundle adjustment of every keyframe and point (the first two
  // keyframes fixed), and the corrected map handed over again (map_corrected), as after a loop
  // closure.
  bool final_bundle_adjustment = true;
  // When a global adjustment (after a loop closure) ran late in the drive, the final one frees
  // only the keyframes added since and the local window before them (as many as the tracker's
  // free and fixed keyframes), the older ones held fixed: a tail adjustment, when that is at most
  // final_bundle_adjustment_tail_share of the keyframes. The keyframes before the window have not
  // moved since they were adjusted with the whole map. False: always the whole map.
  bool final_bundle_adjustment_tail = true;
  double final_bundle_adjustment_tail_share = 0.5;
  // Central mode: the final adjustment uses the cameras' true offsets at a scale it estimates
  // (Tracker::GlobalBundleAdjust), not the central approximation of the rest of the run. Off:
  // on the tiny and short drives it took the keyframes' ATE 13 % and 4 % lower but made the
  // final adjustment 4 times slower, 15 to 20 % of the run (docs/figures.md F33).
  bool final_bundle_adjustment_true_offsets = false;
  // Before the final adjustment, the points that are one place seen by two tracks are fused
  // (Tracker::GlobalBundleAdjust; radians, 0: none).
  double final_bundle_adjustment_merge_angle = 0.0;
  // The final adjustment adjusts the tracked frames between keyframes too (those after its
  // first free keyframe; Tracker::GlobalBundleAdjust's frames), each with the observations it
  // was tracked with, at least final_frame_refinement_checks.min_inliers of them: three to four
  // times the rays for the points, so better points and keyframes. On 30 starts of 60 frames of
  // the short drive the keyframes' error fell to 0.89 times in geometric mean (better on 25),
  // for the final adjustment 2.5 to 20 times the time, a fraction of a second there
  // (docs/figures.md F74). Only when it frees at most final_bundle_adjustment_frames_max_keyframes
  // keyframes (0: any number): a whole drive of 400 frames without a loop took 4.5 instead of 1.1
  // s, one of 1550 frames 32 instead of 4.5 s, for 15 % and 1 % less error. Those frames take their
  // adjusted pose; final_frame_refinement poses the others.
  bool final_bundle_adjustment_frames = true;
  int final_bundle_adjustment_frames_max_keyframes = 60;
  // A frame the motion model does not track is matched again by descriptors against the last
  // keyframes, newest first (TrackBuilderOptions::rematch_keyframes of them), and retried.
  bool descriptor_retry = true;
  // Non-central mode: while there is no map, the cameras whose fields of view overlap are
  // matched with each other, so that a rig that does not move starts a metric map from its
  // own baseline (TrackerOptions::stereo_initialisation).
  bool stereo_matching = true;
  // The frames of the input the run reads: max_frames of them (0: to the end) from first_frame
  // on (`--frames A:B`). Rows, keyframes and outputs keep the input's frame indices, so that two
  // runs over overlapping ranges of one drive name their shared frames alike.
  int first_frame = 0;
  int max_frames = 0;
  // A run is usable when the SfM initialised and at least this share of the frames read was
  // tracked; below it the map covers too little of the drive (tracking was lost for good).
  double usable_tracked_frames_share = 0.5;
  // A tracked frame between two keyframes follows both when the keyframes are corrected (local
  // adjustments, loop closures, the final adjustment): its pose relative to each, blended by
  // where it lies between them (TrackedFramePoses). Off: it follows the keyframe it was tracked
  // from alone, which carries it rigidly, so a change of the map's scale after it was tracked
  // (non-central mode, where the offsets set the scale) moves it off its keyframes.
  bool frame_poses_between_keyframes = true;
  // After the final adjustment (at the end of the input when there is none): each tracked frame
  // that is not a keyframe is posed again against the final map, from its pose between its
  // keyframes, by a motion-only adjustment of the rig on the observations of map points it was
  // tracked with (Tracker::RefineFramePose, its checks in final_frame_refinement_checks); a
  // frame that does not pass them keeps that pose. frame_poses.tum then has the keyframes'
  // accuracy (docs/figures.md F39).
  bool final_frame_refinement = true;
  FramePoseRefinementOptions final_frame_refinement_checks;
  // Non-central mode: a map whose scale comes from the rig (its camera offsets, a stereo pair)
  // is called metric only when the largest camera offset is at least this share of the points'
  // median depth. Below it the offsets fix the scale only to a few per cent: the ladybug-like rig
  // (5 cm for points about 10 m away, 0.5 %) ended 0.91 to 1.07 times metric over 24 runs of 60
  // frames and 0.96 to 1.06 times over 12 whole drives with a loop; the car rig (1.3 m for
  // points 20 m away, 6.6 %) within 0.2 % (docs/figures.md F68). The map is then reported as of
  // arbitrary scale, near metres.
  double min_metric_offset_depth_ratio = 0.01;

  // "" or the first bad field ("tracker.keyframes.min_tracked_share: expected ...").
  std::string Check() const;
};

// One row per frame of the input (stats/sfm_frames.csv).
struct SfmFrameRow {
  size_t frame = 0;
  std::string name;
  bool loaded = false;  // false: an image could not be read, the frame was skipped
  int corners = 0, matched = 0, predicted = 0;
  int epipolar = 0;           // of matched: found along their epipolar segment
  bool relocalising = false;  // matched against the last keyframe after a lost frame
  FrameResult result;
  double ms = 0.0;  // waiting for the images, tracking and, for a keyframe, the local
                    // adjustment and the loop closer
  // A tracked frame's pose relative to the newest keyframe when it was tracked, so that a
  // correction of the keyframes (loop closure, final adjustment) carries the frame along.
  int reference_keyframe = -1;
  Rigid3d keyframe_from_rig;
  // The first keyframe after the frame (-1: none yet), the frame's pose relative to it when it
  // was made, and the frame's place between the two: 0 at the reference, 1 at this one (its
  // distances to both then).
  int next_keyframe = -1;
  Rigid3d next_keyframe_from_rig;
  double next_keyframe_weight = 0.0;
  // SfmRunnerOptions::final_frame_refinement: the frame's pose refined against the final map
  // (world_from_rig), which TrackedFramePoses then gives; pose_adjusted: that pose came from the
  // final adjustment itself (SfmRunnerOptions::final_bundle_adjustment_frames).
  bool pose_refined = false;
  bool pose_adjusted = false;
  Rigid3d refined_world_from_rig;
};

// world_from_rig of every tracked frame: its refined pose when it has one
// (SfmFrameRow::pose_refined), else its reference keyframe's final pose times the relative pose
// it was tracked with, blended with the pose relative to the next keyframe when the row has one
// (positions linearly, rotations by slerp, by next_keyframe_weight), so that the frame follows a
// change of scale between its keyframes (for frame_poses.tum).
struct SfmFramePose {
  size_t frame = 0;
  Rigid3d world_from_rig;
};
struct SfmRunResult;
std::vector<SfmFramePose> TrackedFramePoses(const SfmRunResult& run);

// A run of frames read but not tracked, between tracked frames or to the end (row indices,
// inclusive).
struct SfmUntrackedRun {
  size_t first = 0, last = 0;
  bool to_the_end = false;
};

std::string SfmFramesCsvHeader();
std::string SfmFramesCsvRow(const SfmFrameRow& row);

// A loop closure and the rotation its correction applied to the revisiting keyframe.
struct SfmLoopClosure {
  LoopClosureEvent event;
  double correction_rotation_deg = 0.0;
};

// Whether the run gave a map to use. Anything but kUsable is a failed run (the commands say
// why on stderr and exit with a code of their own, apps/commands.h).
enum class SfmOutcome {
  kUsable,
  kNotInitialised,  // fewer than two keyframes: no map
  kTrackingLost,    // a map, but fewer than usable_tracked_frames_share of the frames
                    // read were tracked
};

struct SfmRunResult {
  std::vector<FinalizedKeyframe> keyframes;  // every keyframe, in order, final poses and points
  // The same keyframes and points with each point's complete track (Tracker::FinalizedSnapshot
  // with all_rays), for sparse/.
  std::vector<FinalizedKeyframe> model_keyframes;
  std::vector<SfmFrameRow> frames;
  std::vector<std::string> skipped;  // one message per unreadable frame
  std::vector<SfmLoopClosure> loop_closures;
  size_t frames_total = 0;  // frames of the run (max_frames applied)
  size_t frames_tracked = 0;
  // The first frame of the last run of untracked frames that lasts to the end of the input
  // (frames_total when the last frame read was tracked).
  size_t lost_from = 0;
  std::vector<SfmUntrackedRun> untracked_runs;  // after the first tracked frame
  SfmOutcome outcome = SfmOutcome::kNotInitialised;
  std::string outcome_reason;  // one line: what happened, for stderr and the run's summary
  // The front end's corners per image, their least response (a share of the image's strongest)
  // and its pool (SfmFrontEndOptions: 1, none).
  int corners_per_image = 0;
  double corner_quality = 0.0;
  // The keyframe rule's share (KeyframeSelectionOptions::min_tracked_share).
  double min_tracked_share = 0.0;
  // KeyframeSelectionOptions::min_followed_track_share.
  double min_followed_track_share = 0.0;
  double continuation_pool = 1.0;
  // The epipolar search's near end (TrackBuilderOptions::epipolar_min_depth, 0: off), its bands'
  // narrowest and widest half widths (epipolar_search_radius, epipolar_max_search_radius:
  // working-image pixels) and the matches it gave, over the frames (SfmFrameRow::epipolar).
  double epipolar_min_depth = 0.0;
  double epipolar_search_radius = 0.0;
  double epipolar_max_search_radius = 0.0;
  long epipolar_matches = 0;
  // Where the map's scale comes from (Tracker::ScaleSource), and whether it is in metres
  // (Tracker::MetricScale); both say "arbitrary, near metres" instead when the offsets are small
  // against the depth (SfmRunnerOptions::min_metric_offset_depth_ratio).
  std::string scale_source;
  bool metric_scale = false;
  // What the offsets weigh against: the largest camera offset (m) and the points' median depth.
  double largest_camera_offset = 0.0;
  double median_point_depth = 0.0;
  // Their ratio (0 without points): SfmRunnerOptions::min_metric_offset_depth_ratio.
  double offset_depth_ratio = 0.0;

  // Wall seconds of the SfM thread: waiting for decoded images, the front end, the tracker's
  // stages, loop detection and correction, and the whole run.
  double load_seconds = 0.0;
  TrackBuilder::Timings front;
  Tracker::Timings back;
  double loop_closure_seconds = 0.0;
  // The final global bundle adjustment: its time, and the RMS angle of the observations
  // (radians) before and after it; 0 when it did not run.
  double final_bundle_adjustment_seconds = 0.0;
  double final_rms_angle_before = 0.0, final_rms_angle_after = 0.0;
  // The keyframes it left free (all but the gauge, or a tail: final_bundle_adjustment_tail), and
  // the frames it adjusted with them (final_bundle_adjustment_frames).
  int final_free_keyframes = 0;
  int final_adjusted_frames = 0;
  // SfmRunnerOptions::final_frame_refinement: its time, the frames it tried (tracked, not
  // keyframes) and those whose refined pose was taken.
  double final_frame_refinement_seconds = 0.0;
  size_t frames_refinement_tried = 0, frames_refined = 0;
  double seconds = 0.0;
};

// What the runner reads: frames in order, each the images of every camera (throws InputError
// when one cannot be read) and its name.
struct SfmFrameSource {
  std::string folder;  // named in errors
  size_t num_frames = 0;
  FramePrefetcher::Loader load;  // 8-bit grey images, one per camera
  std::function<std::string(size_t frame)> name;
};
// The grey images and frame names of `drive`, which must outlive the source.
SfmFrameSource DriveFrameSource(const Drive& drive);

// The first keyframe the final adjustment leaves free, 0 for the whole map (but the gauge):
// with final_bundle_adjustment_tail, after a global adjustment when the map had
// keyframes_at_global_adjustment keyframes (0: none), the local window before those and every
// keyframe since, when that is at most final_bundle_adjustment_tail_share of num_keyframes.
int FinalAdjustmentFirstFreeKeyframe(const SfmRunnerOptions& options, int num_keyframes,
                                     int keyframes_at_global_adjustment);

struct SfmRunnerCallbacks {
  // On the runner's thread, in order: a keyframe that left the local window (its pose and
  // points no longer move).
  std::function<void(const FinalizedKeyframe&)> keyframe_finalised;
  // On the runner's thread, after a loop closure or the final bundle adjustment corrected the
  // map: every keyframe finalised so far, rebuilt from the corrected map (the later
  // keyframe_finalised calls continue it).
  std::function<void(const std::vector<FinalizedKeyframe>&)> map_corrected;
  // On the runner's thread, after each frame (its row), with the tracker's counts.
  std::function<void(const SfmFrameRow&, int keyframes, int points)> frame_done;
  // Polled before each frame: true stops the run (no outcome checks, no Finish()).
  std::function<bool()> stop;
};

// The per-frame step, for callers that feed frames themselves; RunSfm is the loop over a
// source. Throws OptionsError for bad options.
class SfmRunner {
 public:
  SfmRunner(const Rig& rig, const SfmRunnerOptions& options,
            const SfmRunnerCallbacks& callbacks = {});
  ~SfmRunner();
  SfmRunner(const SfmRunner&) = delete;
  SfmRunner& operator=(const SfmRunner&) = delete;

  // One frame: `frame.images` (one per camera) or `frame.error` (the frame is skipped).
  // `wait_seconds` is the time spent waiting for its images (counted in its row).
  const SfmFrameRow& AddFrame(PrefetchedFrame frame, const std::string& name,
                              double wait_seconds = 0.0);
  // End of the input: finalises the keyframes still in the window and decides the outcome.
  // Throws InputError when no frame could be read.
  SfmRunResult Finish();

  const Tracker& tracker() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// The front end's options of a run: `tracks`, without the pool in central mode when
// continuation_pool_in_central_mode is off.
TrackBuilderOptions SfmFrontEndOptions(const SfmRunnerOptions& options);

// The frames a run over an input of `input_frames` frames reads (first_frame and max_frames
// applied).
size_t SfmFramesToRun(const SfmRunnerOptions& options, size_t input_frames);

// Runs the SfM over the frames of `source` (first_frame and max_frames applied), the images decoded
// ahead on their own thread. Stopped early by callbacks.stop (the result then holds what was done).
SfmRunResult RunSfm(const Rig& rig, const SfmFrameSource& source, const SfmRunnerOptions& options,
                    const SfmRunnerCallbacks& callbacks = {});

// The process's allocator set for the SfM (once; glibc only): every frame allocates and frees
// the same large image buffers (Harris responses, pyramids); above glibc's default mmap
// threshold each is a fresh mapping, and the page faults cost about half of the detection time.
void ConfigureAllocatorForSfm();

const char* SfmOutcomeName(SfmOutcome outcome);

}  // namespace omni
