#pragma once
// Skeleton of the incremental rig SfM on bearings (issue 8; DESIGN.md §6): frames come as
// bearings already associated into tracks (the matching layer's job); the tracker initialises
// from two keyframes (relative pose in RANSAC + triangulation), resects every frame (P3P / GP3P
// in RANSAC), selects keyframes (Mouragnon et al.), triangulates new points, runs the local
// bundle adjustment over the newest keyframes and finalises the keyframes that leave its
// window. Central mode: the rig is one camera at the mean camera centre; non-central mode: the
// true cam_from_rig offsets throughout. Poses are always world_from_rig of the rig frame.

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/bundle_adjustment.h"
#include "sfm/keyframe_selection.h"
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
  int num_free_keyframes = 3;                 // issue 8: newest n keyframes free (default 3)
  int num_fixed_keyframes = 7;                // and the N before them fixed (7–10)
  int min_init_points = 50;        // points triangulated for the initialisation to be accepted
  int min_resection_inliers = 30;  // fewer: the frame is reported as not tracked
  // Never a silently wrong map: a resected centre farther from the constant-velocity
  // prediction than max_jump_ratio times a step (the larger of the last step and the mean step
  // so far) times the frames since the last tracked one is rejected as a wrong pose.
  double max_jump_ratio = 4.0;

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
  std::string status;  // why not tracked, or what happened
};

struct FinalizedRay {
  int keyframe = -1;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();    // optical centre, world
  int camera = -1;                                     // the observing camera of the keyframe
  Eigen::Vector3d bearing = Eigen::Vector3d::UnitZ();  // the observation, that camera's frame
};
struct FinalizedPoint {
  int point = -1;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  std::vector<FinalizedRay> rays;
};
// A keyframe that left the adjustment window: its pose and points no longer move (DESIGN.md
// §4: the keyframe handed to the surface).
struct FinalizedKeyframe {
  int keyframe = -1;
  int frame = -1;
  Rigid3d world_from_rig;
  Eigen::Vector3d center = Eigen::Vector3d::Zero();  // c_t
  std::vector<FinalizedPoint> points;                // the points created with this keyframe
};

class Tracker {
 public:
  Tracker(const Rig& rig, const TrackerOptions& options);
  ~Tracker();
  Tracker(const Tracker&) = delete;
  Tracker& operator=(const Tracker&) = delete;

  FrameResult AddFrame(const std::vector<TrackObservation>& observations);
  // Finalises every keyframe still in the window (end of the sequence).
  void Finish();
  // Keyframes finalised since the last call.
  std::vector<FinalizedKeyframe> TakeFinalized();

  // Constant-velocity prediction of the next frame's world_from_rig (the motion between the
  // last two tracked frames applied once more); false before the initialisation or after a
  // frame that was not tracked (then the last tracked pose is given, with no velocity).
  bool PredictPose(Rigid3d* world_from_rig) const;
  // The map point of a track, if it has one (world frame).
  bool TrackPosition(int track, Eigen::Vector3d* position) const;
  // Seconds spent in each stage since the start.
  struct Timings {
    double resect = 0.0;
    double triangulate = 0.0;
    double bundle_adjustment = 0.0;
  };
  Timings StageTimings() const;

  int NumKeyframes() const;
  int NumPoints() const;
  // world_from_rig of each keyframe and the frame index it came from.
  std::vector<Rigid3d> KeyframePoses() const;
  std::vector<int> KeyframeFrames() const;

  // ---- Map access and correction (loop closure, issue 9) ----
  // The live points a keyframe observes: (track id, position in the world).
  std::vector<std::pair<int, Eigen::Vector3d>> KeyframeTrackPoints(int keyframe) const;
  // Moves keyframe k by the similarity of the world new_from_old[k] (one per keyframe; the rig
  // frame itself is not scaled) and every point with the keyframe that created it.
  void ApplyCorrection(const std::vector<Sim3d>& new_from_old);
  // Fuses the points of two tracks found to be the same place (a loop's matches): the point of
  // `drop` gives its observations to the point of `keep` and dies; the track follows.
  void MergeTracks(const std::vector<std::pair<int, int>>& drop_keep);
  // Adjusts every keyframe (the first two fixed: the gauge) and every live point (Ceres, sparse
  // Schur); observations found to be outliers are dropped.
  BundleAdjustmentSummary GlobalBundleAdjust();
  // The keyframes finalised so far, rebuilt from the current map (after a correction), in order.
  std::vector<FinalizedKeyframe> FinalizedSnapshot() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace omni
