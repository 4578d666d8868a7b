#pragma once
// Skeleton of the incremental rig SfM on bearings (docs/design.md §9): frames come as
// bearings already associated into tracks (the matching layer's job); the tracker initialises
// from two keyframes (relative pose in RANSAC + triangulation), resects every frame (P3P / GP3P
// in RANSAC), selects keyframes (Mouragnon et al.), triangulates new points, runs the local
// bundle adjustment over the newest keyframes and finalises the keyframes that leave its
// window. Central mode: the rig is one camera at the mean camera centre; non-central mode: the
// true cam_from_rig offsets throughout. Poses are always world_from_rig of the rig frame.
//
// Long tracks: once a frame is resected, the live points of the recent keyframes are
// projected into every camera where the frame does not observe them and searched by the front
// end (MapPointSearchFn, sfm/map_point_search.h); a match re-labels the observation with the
// point's track. A point may so have two observations in one frame (and one keyframe), in two
// different cameras (neighbour overlap), never two in one camera. A point is handed to the
// surface (FinalizedKeyframe::points) with the first keyframe finalised after it is no longer
// observed by a newer keyframe (at most max_handover_delay keyframes after its creation), so
// that it carries its whole track; until then it keeps moving in the bundle adjustment.

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/absolute_pose_noncentral.h"
#include "sfm/bundle_adjustment.h"
#include "sfm/keyframe_selection.h"
#include "sfm/map_point_search.h"
#include "sfm/ransac.h"
#include "sfm/triangulation.h"

namespace omni {

struct TrackerOptions {
  bool central = true;
  RansacOptions relative_ransac;   // initialisation
  RansacOptions resection_ransac;  // every frame
  TriangulationOptions triangulation;
  KeyframeSelectionOptions keyframes;
  BundleAdjustmentOptions bundle_adjustment;  // its mode follows `central`
  int num_free_keyframes = 3;                 // the newest n keyframes are free
  int num_fixed_keyframes = 7;                // and the N before them fixed (7–10)
  // Threads of the global adjustments (after a loop closure, at the end: one-off solves of the
  // whole map, the SfM thread waits for them). With more than one, Ceres sums the reduced
  // system's blocks in the order its threads reach them, so the map differs in its last bits
  // from run to run and the runs drift apart: one keeps a run repeatable.
  int global_bundle_adjustment_threads = 1;
  // The global adjustments stop when an iteration lowers the cost by less than this share
  // (Ceres's function_tolerance; the local adjustments keep bundle_adjustment.function_tolerance,
  // the one after a loop closure LoopClosureOptions's): 1e-8 took 13 iterations on the paper
  // drive's 485 keyframes to move the RMS angle by 0.0001 degrees (docs/figures.md F42, F43).
  double global_bundle_adjustment_function_tolerance = 1e-6;
  // Non-central initialisation: the generalised relative pose replaces the central five-point
  // one only when it triangulates this many times as many points.
  double noncentral_init_margin = 1.2;
  int min_init_points = 50;  // points triangulated for the initialisation to be accepted
  // A two-frame initialisation from the front end's matches (not from a retry by descriptors)
  // needs at least this share of the first keyframe's observations tracked to the frame: when
  // the search without a motion prior lost most of them (a turn, fast flow at the image's edges
  // in a forward camera), the pose of what little it matched was wrong by metres on a single
  // camera's starts, and the frame is left to the descriptors' retry. Good first pairs keep 0.4
  // or more with one camera, 0.25 or more with six (docs/figures.md F79). 0: off.
  double min_init_track_share = 0.15;
  // The initialisation starts again from the current frame (a new first keyframe) when this
  // many frames after the first keyframe could not initialise (a bad first frame, a rig that
  // does not move), or at once when the first keyframe has fewer than min_init_points
  // observations (a black frame).
  int max_init_frames = 10;
  // One-frame initialisation (non-central mode): the tracks that two cameras of the first
  // keyframe observe (overlapping cameras, matched by the front end) are triangulated with the
  // rig's own baseline; with enough such points the map starts metric from
  // that one frame. Their rays must be this far apart (radians: a stereo pair's baseline is
  // short).
  bool stereo_initialisation = true;
  int min_stereo_points = 30;
  double stereo_min_ray_angle = 0.5 * M_PI / 180.0;
  // A stereo map too thin to resect the next frames from (near points only, few tracked on):
  // while it has one keyframe, a frame that fails the resection tries the two-frame
  // initialisation with the first keyframe instead, scaled to metres by the stereo points the
  // two maps share (at least min_stereo_scale_points, else the map keeps the two-frame
  // solution's scale); the frames that failed meanwhile are resected in the new map.
  bool stereo_map_fallback = true;
  // Non-central mode: the adjustments hold only the first keyframe fixed, so that the rig's
  // camera offsets give the map its scale in metres (the first step of a two-frame
  // initialisation is then only a starting value). How well the offsets observe the scale
  // depends on their size against the depth of the points (Tracker::MedianPointDepth). false:
  // the first two keyframes are fixed, and the scale is that of the initialisation.
  bool scale_from_offsets = true;
  // With scale_from_offsets: when the adjustment of the first two keyframes makes their
  // distance more than this many times larger than the initialisation's unit step (a keyframe
  // step beyond 100 m: the offsets, lost against the depths, did not observe the scale), it is
  // solved again with both keyframes fixed, the scale held for the adjustments of three
  // keyframes and more to set. A map made too small is left to them: its offsets, large
  // against its depths, observe the scale well (docs/figures.md F68).
  double max_initial_scale_growth = 100.0;
  int min_stereo_scale_points = 8;
  int min_resection_inliers = 30;  // fewer: the frame is reported as not tracked
  // ... unless at least min_consistent_inliers of them are at least consistent_inlier_share of
  // the matches with a map point (few matches that nearly all agree: a narrow camera in a
  // turn, a frame after a gap); 0: off.
  int min_consistent_inliers = 15;
  double consistent_inlier_share = 0.75;
  // The resection may try a prior pose before its RANSAC (sfm/ransac.h PosePrior); both are off
  // by default: on the demo drive they halved the resection's time but moved the ATE both ways
  // (docs/figures.md F23). The frame's first resection: the motion model's
  // prediction, taken when (refined on its inliers) it explains at least this share of the
  // frame's observations of map points (1: never tried). The resection after the map-point
  // search: the frame's first resection, taken when it keeps at least its inliers.
  double resection_prior_share = 1.0;
  bool resection_prior_after_search = false;
  // Non-central mode: how the resection's RANSAC makes its hypotheses (GP3P, the P3P of one
  // camera, or the P3P from the cameras' mean centre), each scored and the best refined with the
  // true offsets (NoncentralAbsolutePoseOptions::hypotheses).
  NoncentralHypotheses noncentral_resection_hypotheses = NoncentralHypotheses::kGp3p;
  // The resection's RANSAC counts its hypotheses' inliers within resection_ransac.max_angle_error
  // times this and refines the best on them, then keeps as the frame's inliers those within
  // max_angle_error (Central/NoncentralAbsolutePoseOptions::consensus_angle_factor). 1: one
  // angle for all; 0: by mode, ResectionConsensusAngleFactor(). The map points are a pixel or two
  // off, more than the sub-pixel max_angle_error, which kept half of them out of the count: in
  // non-central mode a consensus three times as wide needs a tenth of the samples (demo: 165 a
  // resection, 16) and the refinement on them brings the keyframes closer to the truth (0.84
  // times the ATE over 8 drives and 3 seeds); in central mode the approximation bends the rays
  // by several times the angle, and the wider consensus takes them in (1.08 times the ATE):
  // one angle there (docs/figures.md F52).
  double resection_consensus_angle_factor = 0.0;
  static constexpr double kNoncentralResectionConsensus = 3.0;
  double ResectionConsensusAngleFactor() const {
    if (resection_consensus_angle_factor > 0.0) return resection_consensus_angle_factor;
    return central ? 1.0 : kNoncentralResectionConsensus;
  }
  // Never a silently wrong map: a resected centre farther from the constant-velocity
  // prediction than max_jump_ratio times a step (the larger of the last step and the mean step
  // so far) times the frames since the last tracked one is rejected as a wrong pose.
  double max_jump_ratio = 4.0;
  // Map-point re-observation: the points of the newest this-many keyframes are searched.
  int map_search_keyframes = 10;
  // A point goes to the surface with the first keyframe finalised once no newer keyframe
  // observes it, or at the latest with keyframe created_by + max_handover_delay (0: always
  // with the keyframe that created it, the old behaviour).
  int max_handover_delay = 12;
  // When the chained tracks do not resect a frame, the map points are searched around the
  // constant-velocity prediction with the search radius times this.
  double predicted_search_radius_scale = 3.0;
  // Wide baselines without a motion prior (a turn, a low frame rate, after a gap): when the
  // frame cannot be resected, its 2-D matches with a posed frame (the last tracked frame or one
  // of the last keyframes, the one sharing the most tracks) give the relative pose (five-point
  // RANSAC on the rig-axis bearings, the central approximation), its scale the matches that are
  // map points (a one-parameter consensus within scale_max_angle_error), then the map points are
  // searched around that pose (the predicted search radius) and the frame resected again; the
  // resection must pass as any other. At least min_relative_matches shared tracks, of which
  // min_relative_inliers inliers and min_scale_points agreeing map points. false: off.
  // When the resection still fails (a map too thin for the new view: every wide step a
  // keyframe with few points), the relative pose alone is taken with at least
  // min_relative_inliers_alone inliers and min_scale_points_alone agreeing map points, and the
  // frame becomes a keyframe, so that its matches with the reference are triangulated.
  bool relative_pose_fallback = true;
  int min_relative_inliers_alone = 20;
  int min_scale_points_alone = 8;
  // RetryFrame's resections (observations matched by descriptors: corners detected again in
  // another view, a pixel or so off, not followed windows) count inliers within
  // resection_ransac.max_angle_error times this.
  double retry_angle_error_scale = 3.0;
  int min_relative_matches = 30;
  int min_relative_inliers = 20;
  int min_scale_points = 6;
  double scale_max_angle_error = 0.01;
  // After the search, resect the frame again with the re-observations (a second RANSAC).
  bool resect_after_search = true;
  // Whether the points the search found count as tracked in the keyframe decision.
  bool reobserved_count_as_tracked = true;
  // A re-observation is kept when its bearing is within this angle of its point seen from the
  // resected pose (radians; the search radius bounds it already; the central approximation
  // bends near points by up to offset / depth).
  double reobservation_max_angle_error = 0.006;
  // Rays of the tracked frames between keyframes (docs/design.md §7): a point handed to the
  // surface also carries the optical centres of the frames that observed it without being
  // keyframes: the resection's inliers and the agreeing re-observations of its point, and, for a
  // point triangulated at a later keyframe, the frames since the oldest keyframe of the
  // triangulation window whose observation of its track lies within
  // reobservation_max_angle_error of it. Every frame_ray_step-th tracked frame after a keyframe
  // (1: all); 0: keyframe rays only (the paper). A frame's pose is kept relative to the keyframe
  // before it, so that it follows that keyframe's corrections.
  int frame_ray_step = 1;
  // A frame ray is handed over only when its direction from the point is at least this far
  // from every ray handed over before it (the point's keyframe rays, then its frame rays in
  // order; radians, 0: all of them). Closer rays carve nearly the same cells (docs/figures.md
  // F34: 1 degree keeps the surface's figures with a fifth fewer rays).
  double frame_ray_min_angle = 1.0 * M_PI / 180.0;
  // Frame points, for the surface only: at each keyframe, the tracks without a map point that
  // the frames recorded for frame_ray_step saw and that ended before it (not seen by the
  // keyframe) are triangulated from those frames' poses (`triangulation`'s checks), and handed
  // over with the keyframe before their frames, flagged FinalizedPoint::frame_point, their
  // rays the frames' rays. They are not in the map: no adjustment, resection or search sees
  // them, so they cost the SfM a triangulation each; they are triangulated again from the
  // frames' poses whenever the keyframes are handed over (after a correction, the frames
  // follow their keyframes). Without them, a track that lives between two keyframes gives the
  // surface nothing: most tracks do (figures.md F56). Needs frame_ray_step > 0.
  bool frame_points = true;
  // Each tracked frame that is not a keyframe keeps its observations of map points (the
  // resection's inliers and the agreeing re-observations), so that RefineFramePose can pose it
  // again against the map as it is later (after the final adjustment). false: none kept.
  bool keep_frame_observations = false;

  std::string Check() const;
};

struct TrackObservation {
  int track = -1;                                      // the same physical point across frames
  int camera = 0;                                      // index into Rig::cameras
  Eigen::Vector3d bearing = Eigen::Vector3d::UnitZ();  // unit, camera frame
};

struct FrameResult {
  bool tracked = false;
  bool keyframe = false;
  Rigid3d world_from_rig;
  int inliers = 0;
  int reobserved = 0;  // observations the map-point search gave a map point (new or re-labelled)
  std::string status;  // why not tracked, or what happened
};

// Tracker::RefineFramePose: the refined pose is taken when at least min_inliers and at least
// min_inlier_share of the frame's observations of live points stay inliers of the adjustment
// (within bundle_adjustment.max_outlier_angle) and their RMS angle is not larger than from the
// starting pose.
struct FramePoseRefinementOptions {
  int min_inliers = 15;
  double min_inlier_share = 0.7;
  int max_iterations = 20;

  std::string Check() const;
};

// A tracked frame that is not a keyframe, adjusted with the keyframes and points by
// Tracker::GlobalBundleAdjust: its index among the frames given to AddFrame, its pose (the
// start, then the adjusted one) and whether it was adjusted (it needs kept observations,
// TrackerOptions::keep_frame_observations, of at least min_frame_observations points of the
// adjustment).
struct AdjustedFrame {
  int frame = -1;
  Rigid3d world_from_rig;
  bool adjusted = false;
};

struct FramePoseRefinement {
  bool refined = false;  // false: the starting pose is kept (world_from_rig is that pose)
  Rigid3d world_from_rig;
  int observations = 0;  // the frame's kept observations of points still alive
  int inliers = 0;       // of them, those the adjustment kept
  // RMS angle over the inliers from the starting pose and from the refined one (radians).
  double rms_angle_before = 0.0, rms_angle_after = 0.0;
};

struct FinalizedRay {
  int keyframe = -1;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();    // optical centre, world
  int camera = -1;                                     // the observing camera of the keyframe
  Eigen::Vector3d bearing = Eigen::Vector3d::UnitZ();  // the observation, that camera's frame
};
// The optical centre of a tracked frame between keyframes that observed the point
// (TrackerOptions::frame_ray_step); `keyframe` is the keyframe before that frame.
struct FinalizedFrameRay {
  int keyframe = -1;
  int frame = -1;  // the tracker's count of frames (SfmRunner's results: the drive's index)
  int camera = -1;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // optical centre, world
};
struct FinalizedPoint {
  int point = -1;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  std::vector<FinalizedRay> rays;             // keyframes (sparse/, colours, the surface)
  std::vector<FinalizedFrameRay> frame_rays;  // tracked frames between them (the surface)
  // A frame point (TrackerOptions::frame_points): no keyframe ray, not in the map; `point` is
  // kFramePointIdBase + its index among the frame points.
  bool frame_point = false;
};
constexpr int kFramePointIdBase = 1 << 30;
// A keyframe that left the adjustment window: its pose and points no longer move (docs/design.md
// §7: the keyframe handed to the surface).
struct FinalizedKeyframe {
  int keyframe = -1;
  int frame = -1;
  Rigid3d world_from_rig;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // c_t
  std::vector<FinalizedPoint> points;  // the points handed over with this keyframe (see top)
};

// Track lengths of the points handed over (the rays the surface and the COLMAP model get).
// Over the map's points (the frame points are counted apart: they have no keyframe rays).
struct TrackStats {
  int points = 0;
  int frame_points = 0;         // TrackerOptions::frame_points handed over
  double mean_keyframes = 0.0;  // distinct keyframes observing a point
  double median_keyframes = 0.0;
  double mean_rays = 0.0;
  double mean_frame_rays = 0.0;     // rays of tracked frames between keyframes (the surface's)
  double multi_camera_share = 0.0;  // points observed by two or more cameras of the rig
  // Points with two rays (from their optical centres) more than min_aperture apart: those
  // that pass the aperture filter of the surface (paper §5.1: 10°).
  double aperture_ok_share = 0.0;
};
TrackStats ComputeTrackStats(const std::vector<FinalizedKeyframe>& keyframes,
                             double min_aperture = 10.0 * M_PI / 180.0);

class Tracker {
 public:
  Tracker(const Rig& rig, const TrackerOptions& options);
  ~Tracker();
  Tracker(const Tracker&) = delete;
  Tracker& operator=(const Tracker&) = delete;

  // search, when given, is asked for the map points of the recent keyframes once the frame
  // is resected (see MapPointSearchFn); the observations it re-labels count as tracked.
  FrameResult AddFrame(const std::vector<TrackObservation>& observations,
                       const MapPointSearchFn& search = {});
  // The frame last given to AddFrame again, with other observations (the front end matched it
  // again, e.g. by descriptors against an older keyframe), after AddFrame did not track it.
  FrameResult RetryFrame(const std::vector<TrackObservation>& observations,
                         const MapPointSearchFn& search = {});
  // Whether RetryFrame can take the last frame: false when it started the map or became a
  // keyframe or was tracked (nothing to retry).
  bool CanRetryFrame() const;
  // Whether a map exists (two keyframes, or one from the rig's own stereo baseline).
  bool Initialised() const;
  // Where the map's scale comes from: "metric (...)" when the rig's own baseline or offsets
  // fixed it, "arbitrary (...)" when only the motion's direction was observed; empty before
  // the initialisation.
  std::string ScaleSource() const;
  bool MetricScale() const;
  // The median distance of the live points from the first keyframe that observed them (map
  // units; 0 without points).
  double MedianPointDepth() const;
  // Frames whose result changed after they were added: the frames read while initialising,
  // resected once the map exists, and a first keyframe given up by a restart of the
  // initialisation (no longer tracked). Frame indices count the frames given to AddFrame.
  struct RevisedFrame {
    int frame = -1;
    FrameResult result;
  };
  std::vector<RevisedFrame> TakeRevisedFrames();
  // Finalises every keyframe still in the window (end of the sequence).
  void Finish();
  // Keyframes finalised since the last call.
  std::vector<FinalizedKeyframe> TakeFinalized();

  // Constant-velocity prediction of the next frame's world_from_rig (the motion between the
  // last two tracked frames applied once more); false before the initialisation or after a
  // frame that was not tracked (then the last tracked pose is given, with no velocity).
  bool PredictPose(Rigid3d* world_from_rig) const;
  // The same, with the pose of the frame before (the last tracked frame) that the prediction
  // continues: the motion of the rig from the frame before to the next one. last_rotation_error:
  // how far the model's rotation was from the resected one on the frame before (radians; −1
  // when that frame had no prediction), a measure of how far to trust this one;
  // last_translation_error: the model's translation error on that frame across the resected
  // step, over the step's length (−1 likewise).
  bool PredictMotion(Rigid3d* previous_world_from_rig, Rigid3d* predicted_world_from_rig,
                     double* last_rotation_error = nullptr,
                     double* last_translation_error = nullptr) const;
  // The map point of a track, if it has one (world frame).
  bool TrackPosition(int track, Eigen::Vector3d* position) const;
  // Seconds spent in each stage since the start.
  struct Timings {
    double resect = 0.0;
    double triangulate = 0.0;
    double bundle_adjustment = 0.0;
    double map_search = 0.0;  // candidates and the front end's search (its time included)
  };
  Timings StageTimings() const;

  int NumKeyframes() const;
  int NumPoints() const;
  // world_from_rig of each keyframe and the frame index it came from.
  std::vector<Rigid3d> KeyframePoses() const;
  Rigid3d KeyframePose(int keyframe) const;  // one of them (0 <= keyframe < NumKeyframes())
  std::vector<int> KeyframeFrames() const;

  // ---- Map access and correction (loop closure) ----
  // The live points a keyframe observes: (track id, position in the world).
  std::vector<std::pair<int, Eigen::Vector3d>> KeyframeTrackPoints(int keyframe) const;
  // Moves keyframe k by the similarity of the world new_from_old[k] (one per keyframe; the rig
  // frame itself is not scaled) and every point with the keyframe that created it.
  void ApplyCorrection(const std::vector<Sim3d>& new_from_old);
  // Fuses the points of two tracks found to be the same place (a loop's matches): the point of
  // `drop` gives its observations to the point of `keep` and dies; the track follows.
  void MergeTracks(const std::vector<std::pair<int, int>>& drop_keep);
  // Adjusts every keyframe (the first two fixed: the gauge) and every live point (Ceres, sparse
  // Schur); observations found to be outliers are dropped. `true_offsets` in central mode: the
  // adjustment uses each camera's true offset, at a scale it estimates (the map's unit is not
  // the metre), instead of the central approximation; non-central mode has them anyway.
  // `merge_angle` > 0: first the points that are one place seen by two tracks are fused (two
  // points within merge_angle times their depth whose observations all fit one point within
  // merge_angle; *points_merged, if given, counts them).
  // `first_free_keyframe` > 0: a tail adjustment; the keyframes before it are held fixed too,
  // and the points that none of the free keyframes observes are left out.
  // `function_tolerance` > 0: the solve stops at this share of the cost instead of
  // TrackerOptions::global_bundle_adjustment_function_tolerance (0).
  // `frames`: tracked frames adjusted too, each a free pose with its kept observations of the
  // adjusted points (at least `min_frame_observations` of them, else it is left out): more rays
  // for every point. Their adjusted poses are written back.
  BundleAdjustmentSummary GlobalBundleAdjust(bool true_offsets = false, double merge_angle = 0.0,
                                             int* points_merged = nullptr,
                                             int first_free_keyframe = 0,
                                             double function_tolerance = 0.0,
                                             std::vector<AdjustedFrame>* frames = nullptr,
                                             int min_frame_observations = 15);
  // The number of keyframes the map had when the last global adjustment succeeded (0: none
  // since the map started).
  int KeyframesAtLastGlobalAdjustment() const;
  // A motion-only adjustment of tracked frame `frame` (not a keyframe; indices count the frames
  // given to AddFrame) from world_from_rig against the current map: the rig pose alone moves,
  // the points and keyframes stay, on the observations the frame kept
  // (TrackerOptions::keep_frame_observations), in the tracker's mode (central or the true
  // offsets) with the bundle adjustment's robust loss. Not refined when the frame kept none, or
  // the adjustment does not pass `options`.
  FramePoseRefinement RefineFramePose(int frame, const Rigid3d& world_from_rig,
                                      const FramePoseRefinementOptions& options = {}) const;
  // The keyframes finalised so far, rebuilt from the current map (after a correction), in order.
  // Each point's rays are those of keyframes up to the one that handed it over (the surface's
  // contract, docs/design.md §7); with all_rays, every keyframe that observes it (its complete
  // track, for a model of the whole map such as sparse/).
  std::vector<FinalizedKeyframe> FinalizedSnapshot(bool all_rays = false) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace omni
