#include "sfm/tracker.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <deque>
#include <limits>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "calib/error.h"
#include "sfm/absolute_pose_central.h"
#include "sfm/absolute_pose_noncentral.h"
#include "sfm/relative_pose_central.h"
#include "sfm/relative_pose_noncentral.h"

namespace omni {

namespace {

// The map point of each track (an index into the tracker's points), by track id: the front end
// numbers tracks from 0 on, one after the other, so a dense array (−1: no point) replaces a hash
// map on the tracker's busiest lookups.
class TrackToPoint {
 public:
  // The point of `track`, −1 for none.
  int Find(int track) const {
    return track >= 0 && static_cast<size_t>(track) < point_.size() ? point_[track] : -1;
  }
  bool Contains(int track) const { return Find(track) >= 0; }
  // The point of a track that has one (throws std::out_of_range otherwise).
  int At(int track) const {
    const int point = Find(track);
    if (point < 0) throw std::out_of_range("TrackToPoint: track without a point");
    return point;
  }
  void Set(int track, int point) {
    assert(track >= 0 && point >= 0);
    if (static_cast<size_t>(track) >= point_.size())
      point_.resize(std::max<size_t>(track + 1, 2 * point_.size()), -1);
    point_[track] = point;
  }
  void Erase(int track) {
    if (Find(track) >= 0) point_[track] = -1;
  }
  void Clear() { point_.clear(); }
  // f(track, point&) for every track with a point, by track id.
  template <typename F>
  void ForEach(F&& f) {
    for (size_t track = 0; track < point_.size(); ++track)
      if (point_[track] >= 0) f(static_cast<int>(track), point_[track]);
  }

 private:
  std::vector<int> point_;
};

}  // namespace

std::string TrackerOptions::Check() const {
  for (const auto& [name, check] :
       {std::pair<const char*, std::string>{"relative_ransac", relative_ransac.Check()},
        {"resection_ransac", resection_ransac.Check()},
        {"triangulation", triangulation.Check()},
        {"keyframes", keyframes.Check()},
        {"bundle_adjustment", bundle_adjustment.Check()}})
    if (!check.empty()) return std::string(name) + "." + check;
  if (num_free_keyframes < 1) return "num_free_keyframes: expected at least 1";
  if (!(max_initial_scale_growth > 1.0))
    return "max_initial_scale_growth: expected a factor above 1";
  if (num_fixed_keyframes < 1) return "num_fixed_keyframes: expected at least 1";
  if (global_bundle_adjustment_threads < 1)
    return "global_bundle_adjustment_threads: expected at least 1";
  if (!(global_bundle_adjustment_function_tolerance > 0.0 &&
        global_bundle_adjustment_function_tolerance < 1.0))
    return "global_bundle_adjustment_function_tolerance: expected a value in (0, 1)";
  if (min_init_points < 5) return "min_init_points: expected at least 5";
  if (!(min_init_track_share >= 0.0 && min_init_track_share < 1.0))
    return "min_init_track_share: expected a share in [0, 1)";
  if (max_init_frames < 1) return "max_init_frames: expected at least 1";
  if (min_stereo_points < 5) return "min_stereo_points: expected at least 5";
  if (min_stereo_scale_points < 3) return "min_stereo_scale_points: expected at least 3";
  if (!(stereo_min_ray_angle > 0.0))
    return "stereo_min_ray_angle: expected a positive angle (radians)";
  if (min_resection_inliers < 4) return "min_resection_inliers: expected at least 4";
  if (resection_consensus_angle_factor != 0.0 &&
      !ValidConsensusAngleFactor(resection_consensus_angle_factor))
    return "resection_consensus_angle_factor: expected 0 (by mode) or 1 to 100";
  if (min_consistent_inliers != 0 &&
      (min_consistent_inliers < 6 || min_consistent_inliers > min_resection_inliers))
    return "min_consistent_inliers: expected 0 or in [6, min_resection_inliers]";
  if (!(consistent_inlier_share > 0.5 && consistent_inlier_share <= 1.0))
    return "consistent_inlier_share: expected in (0.5, 1]";
  if (!(resection_prior_share > 0.0 && resection_prior_share <= 1.0))
    return "resection_prior_share: expected a share in (0, 1]";
  if (!(max_jump_ratio > 1.0)) return "max_jump_ratio: expected more than 1";
  if (map_search_keyframes < 1) return "map_search_keyframes: expected at least 1";
  if (max_handover_delay < 0) return "max_handover_delay: expected 0 or more keyframes";
  if (!(reobservation_max_angle_error > 0.0))
    return "reobservation_max_angle_error: expected a positive angle (radians)";
  if (!(noncentral_init_margin >= 1.0)) return "noncentral_init_margin: expected at least 1";
  if (!(retry_angle_error_scale >= 1.0)) return "retry_angle_error_scale: expected at least 1";
  if (min_relative_matches < 8) return "min_relative_matches: expected at least 8";
  if (min_relative_inliers < 5 || min_relative_inliers > min_relative_matches)
    return "min_relative_inliers: expected in [5, min_relative_matches]";
  if (min_scale_points < 1) return "min_scale_points: expected at least 1";
  if (min_relative_inliers_alone < min_relative_inliers)
    return "min_relative_inliers_alone: expected at least min_relative_inliers";
  if (min_scale_points_alone < min_scale_points)
    return "min_scale_points_alone: expected at least min_scale_points";
  if (!(scale_max_angle_error > 0.0))
    return "scale_max_angle_error: expected a positive angle (radians)";
  if (!(predicted_search_radius_scale >= 1.0))
    return "predicted_search_radius_scale: expected at least 1";
  if (frame_ray_step < 0) return "frame_ray_step: expected 0 (off) or a step of 1 or more";
  if (!(frame_ray_min_angle >= 0.0 && frame_ray_min_angle < M_PI))
    return "frame_ray_min_angle: expected an angle in [0, pi) (radians)";
  return {};
}

std::string FramePoseRefinementOptions::Check() const {
  if (min_inliers < 4) return "min_inliers: expected at least 4";
  if (!(min_inlier_share > 0.0 && min_inlier_share <= 1.0))
    return "min_inlier_share: expected a share in (0, 1]";
  if (max_iterations < 1) return "max_iterations: expected at least 1";
  return {};
}

struct Tracker::Impl {
  struct PointObservation {
    int keyframe;
    int camera;
    Eigen::Vector3d bearing;
  };
  // An observation by a tracked frame that is not a keyframe (TrackerOptions::frame_ray_step):
  // its frame stamp and camera.
  struct FrameObservation {
    int stamp;
    int camera;
  };
  struct Point {
    Eigen::Vector3d position;
    std::vector<PointObservation> observations;
    std::vector<FrameObservation> frame_observations;
    int created_by = -1;
    int handed_over_by = -1;  // the keyframe whose finalisation handed it to the surface
    int track = -1;
    bool alive = true;
  };
  struct Keyframe {
    int frame = -1;
    Rigid3d world_from_rig;
    std::vector<TrackObservation> observations;
    bool finalized = false;
  };

  Rig rig;
  TrackerOptions options;
  Eigen::Vector3d central_center = Eigen::Vector3d::Zero();  // c0 in the rig frame
  int num_frames = 0;
  std::vector<Keyframe> keyframes;
  // The number of keyframes when the last global adjustment succeeded (0: none since the map
  // started).
  int keyframes_at_global_adjustment = 0;
  std::vector<Point> points;
  TrackToPoint track_to_point;
  std::vector<int> pending;  // live points not handed over yet (indices into points)
  // The last search that listed a point as a candidate (a point is listed once per search even
  // when several keyframes observe it; a frame may search more than once).
  std::vector<int> point_stamp;
  int searches = 0;
  std::vector<FinalizedKeyframe> finalized;
  // The tracked frames whose rays the points carry: the keyframe before each and the frame's
  // pose relative to it (so that it moves with that keyframe), its step scaled with the distance
  // from that keyframe to the one before (the map's scale may change after the frame: the
  // adjustments of a non-central map take it from the initialisation's to the offsets').
  struct FrameStamp {
    int frame;
    int keyframe;
    Rigid3d keyframe_from_rig;
    double keyframe_step = 0.0;  // that distance when the frame was tracked; 0: not scaled
  };
  std::vector<FrameStamp> frame_stamps;
  // TrackerOptions::keep_frame_observations: each tracked frame's observations of map points
  // (track, camera, bearing in the camera frame, single precision), by frame.
  struct KeptObservation {
    int track;
    int camera;
    Eigen::Vector3f bearing;
  };
  std::unordered_map<int, std::vector<KeptObservation>> kept_observations;
  // The recorded frames of the triangulation window with their observations of tracks that had
  // no point yet: a point triangulated later gets their rays.
  struct RecentFrame {
    int stamp;
    std::vector<TrackObservation> observations;
  };
  std::deque<RecentFrame> recent_frames;
  // TrackerOptions::frame_points: each one's observations (frame stamp, observation) and the
  // keyframe it is handed over with (the last keyframe before its frames).
  struct FramePoint {
    int keyframe;
    std::vector<std::pair<int, TrackObservation>> observations;
  };
  std::vector<FramePoint> frame_points;
  std::vector<std::vector<int>> frame_points_by_keyframe;  // indices into frame_points
  std::unordered_set<int> frame_point_tracks;
  // Frame points from the recorded frames' tracks that ended before `keyframe`.
  void MakeFramePoints(int keyframe);
  // A frame point's rays from its frames' current poses.
  std::vector<WorldRay> FramePointRays(const FramePoint& point) const;
  int tracked_since_keyframe = 0;
  // Motion model: the last two tracked frames (frame index, world_from_rig), and the distance
  // travelled over the tracked steps so far.
  struct TrackedPose {
    int frame;
    Rigid3d world_from_rig;
  };
  std::vector<TrackedPose> last_tracked;  // at most two, oldest first
  // The angle between the motion model's rotation for the last frame resected and the
  // resection's (radians; −1: the frame had no prediction).
  double prediction_rotation_error = -1.0;
  // The part of the model's translation error across the resected step (the error along the
  // step moves no epipolar line), over the step's length; −1 with the rotation error's meaning.
  double prediction_translation_error = -1.0;
  // The observations of the last tracked frame (after the map-point search), a reference of
  // the relative-pose fallback; its pose is last_tracked.back() when the frames agree.
  int last_frame = -1;
  std::vector<TrackObservation> last_frame_observations;
  // The frames read after the first keyframe that did not initialise, for their resection
  // once the map exists; the results changed since the last TakeRevisedFrames.
  std::vector<std::pair<int, std::vector<TrackObservation>>> init_frames;
  std::vector<Tracker::RevisedFrame> revised;
  // A map exists: two keyframes, or points triangulated in the first by the rig's baseline.
  bool initialised = false;
  bool retrying = false;         // in RetryFrame: observations matched by descriptors
  bool map_from_stereo = false;  // the map started from the first keyframe's stereo points
  std::string scale_source;      // Tracker::ScaleSource
  bool metric_scale = false;
  double travelled = 0.0;
  int travelled_steps = 0;
  Tracker::Timings timings;

  void RecordTracked(int frame, const Rigid3d& world_from_rig) {
    if (!last_tracked.empty() && last_tracked.back().frame == frame - 1) {
      travelled +=
          (world_from_rig.translation - last_tracked.back().world_from_rig.translation).norm();
      ++travelled_steps;
    }
    last_tracked.push_back({frame, world_from_rig});
    if (last_tracked.size() > 2) last_tracked.erase(last_tracked.begin());
  }
  // Constant velocity: the step between the last two tracked frames applied once per frame
  // from the last tracked one to `frame`; without a velocity, the last tracked pose and false.
  // When frames between those two were not tracked (a gap), the step is the g-th root of
  // their relative motion (a constant screw motion: the rotation's angle over g, the
  // translation solving sum_i R^i t = t_between), up to kMaxPredictionGap frames apart.
  static constexpr int kMaxPredictionGap = 10;
  bool Predict(int frame, Rigid3d* world_from_rig) const {
    if (last_tracked.empty()) return false;
    const TrackedPose& last = last_tracked.back();
    *world_from_rig = last.world_from_rig;
    if (last_tracked.size() < 2) return false;
    const int gap = last.frame - last_tracked[0].frame;
    if (gap < 1 || gap > kMaxPredictionGap) return false;
    const Rigid3d between = last_tracked[0].world_from_rig.Inverse() * last.world_from_rig;
    Rigid3d step = between;
    if (gap > 1) {
      step.rotation = Eigen::Quaterniond::Identity().slerp(1.0 / gap, between.rotation);
      const Eigen::Matrix3d rotation = step.rotation.toRotationMatrix();
      Eigen::Matrix3d power = Eigen::Matrix3d::Identity(), sum = Eigen::Matrix3d::Zero();
      for (int i = 0; i < gap; ++i) {
        sum += power;
        power = rotation * power;
      }
      step.translation = sum.inverse() * between.translation;  // sum is invertible for gap>=1
    }
    for (int f = last.frame; f < frame; ++f) *world_from_rig = *world_from_rig * step;
    return true;
  }
  // Seconds since `start`, added to *total.
  static void AddSeconds(std::chrono::steady_clock::time_point start, double* total) {
    *total += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }

  // Bearing rotated to the rig axes (the central frame's bearing in central mode).
  Eigen::Vector3d RigBearing(const TrackObservation& observation) const {
    return rig.cameras[observation.camera].cam_from_rig.rotation.conjugate() * observation.bearing;
  }
  Eigen::Vector3d CenterInRig(int camera) const {
    return options.central ? central_center : rig.cameras[camera].cam_from_rig.Center();
  }
  WorldRay Ray(const Rigid3d& world_from_rig, int camera, const Eigen::Vector3d& bearing) const {
    const Eigen::Vector3d in_rig = rig.cameras[camera].cam_from_rig.rotation.conjugate() * bearing;
    return WorldRay{world_from_rig * CenterInRig(camera), world_from_rig.rotation * in_rig};
  }
  // The angle between an observation's ray from a frame posed at world_from_rig and the
  // direction from its optical centre to `position` (radians).
  double ObservationAngleError(const Rigid3d& world_from_rig, const TrackObservation& observation,
                               const Eigen::Vector3d& position) const {
    const WorldRay ray = Ray(world_from_rig, observation.camera, observation.bearing);
    const Eigen::Vector3d to_point = position - ray.center;
    return std::atan2(ray.direction.cross(to_point).norm(), ray.direction.dot(to_point));
  }
  // world_from_rig from the pose of the central frame F (rig axes, origin c0).
  Rigid3d RigFromCentral(const Rigid3d& world_from_central) const {
    return Rigid3d(world_from_central.rotation,
                   world_from_central.translation - world_from_central.rotation * central_center);
  }

  int AddPoint(int track, const Eigen::Vector3d& position, int created_by,
               std::vector<PointObservation> observations) {
    Point point;
    point.position = position;
    point.created_by = created_by;
    point.track = track;
    point.observations = std::move(observations);
    points.push_back(std::move(point));
    point_stamp.push_back(-1);
    const int index = static_cast<int>(points.size()) - 1;
    track_to_point.Set(track, index);
    pending.push_back(index);
    return index;
  }

  FrameResult Initialise(const std::vector<TrackObservation>& observations);
  // The keyframes the adjustments hold fixed: the first two (the gauge and the scale of the
  // initialisation) in central mode; the first only when the map has its scale from the rig
  // (a stereo map; non-central mode with scale_from_offsets: the offsets fix it).
  int GaugeKeyframes() const {
    return map_from_stereo || (!options.central && options.scale_from_offsets) ? 1 : 2;
  }
  // A stereo map of one keyframe, which a frame whose resection fails may replace
  // (TrackerOptions::stereo_map_fallback).
  bool ThinStereoMap() const {
    return options.stereo_map_fallback && map_from_stereo && keyframes.size() == 1;
  }
  // The two-frame initialisation in place of a thin stereo map, scaled by the stereo points
  // both share; the stereo map is kept when it fails.
  FrameResult InitialiseOverStereoMap(const std::vector<TrackObservation>& observations);
  // The frame num_frames - 1 becomes the first keyframe (a new start: the map so far is
  // dropped); in non-central mode its stereo tracks may give the map at once.
  FrameResult StartMap(const std::vector<TrackObservation>& observations);
  int TriangulateStereo();
  // Forgets every map point (a new start, or stereo points too few for a map).
  void ClearPoints() {
    points.clear();
    point_stamp.clear();
    track_to_point.Clear();
    pending.clear();
    frame_stamps.clear();
    recent_frames.clear();
    frame_points.clear();
    frame_points_by_keyframe.clear();
    frame_point_tracks.clear();
    kept_observations.clear();
  }
  // The first keyframe of the triangulation window of keyframe k.
  int TriangulationWindowBegin(int k) const {
    return std::max(0, k - options.num_free_keyframes - options.num_fixed_keyframes);
  }
  double KeyframeStep(int k) const {
    return k > 0 ? (keyframes[k].world_from_rig.translation -
                    keyframes[k - 1].world_from_rig.translation)
                       .norm()
                 : 0.0;
  }
  Rigid3d FrameStampPose(const FrameStamp& stamp) const {
    Rigid3d keyframe_from_rig = stamp.keyframe_from_rig;
    if (stamp.keyframe_step > 0.0)
      keyframe_from_rig.translation *= KeyframeStep(stamp.keyframe) / stamp.keyframe_step;
    return keyframes[stamp.keyframe].world_from_rig * keyframe_from_rig;
  }
  // A tracked frame that is not a keyframe: its observations of map points (by index into
  // `observations`) become frame rays of those points; those of tracks without a point are kept
  // for the triangulation of later keyframes.
  void RecordFrameRays(const Rigid3d& world_from_rig,
                       const std::vector<TrackObservation>& observations,
                       const std::vector<int>& of_map_points);
  // Whether a frame posed at world_from_rig has moved since the last frame that gave rays (or
  // the last keyframe) by at least kMinFrameRayStepShare of the mean step: a rig standing still
  // gives no rays that its last ones did not (and keeps no observations for them).
  static constexpr double kMinFrameRayStepShare = 0.25;
  bool MovedSinceLastRays(const Rigid3d& world_from_rig) const {
    if (travelled_steps == 0) return true;
    const int last = static_cast<int>(keyframes.size()) - 1;
    const Eigen::Vector3d last_center =
        !frame_stamps.empty() && frame_stamps.back().keyframe == last
            ? FrameStampPose(frame_stamps.back()).translation
            : keyframes[last].world_from_rig.translation;
    return (world_from_rig.translation - last_center).norm() >=
           kMinFrameRayStepShare * travelled / travelled_steps;
  }
  // A frame observation of `point`; in central mode one per frame (two cameras of a frame share
  // its one optical centre).
  void AddFrameObservation(Point* point, int stamp, int camera) {
    if (options.central && !point->frame_observations.empty() &&
        point->frame_observations.back().stamp == stamp)
      return;
    point->frame_observations.push_back({stamp, camera});
  }
  // The frame rays of the points just created from `new_tracks` (track → point).
  void AddRecentFrameRays(const std::unordered_map<int, int>& new_tracks);
  // Initialise or Track, and what follows from it (the motion model, the frames read while
  // initialising).
  FrameResult Process(const std::vector<TrackObservation>& observations,
                      const MapPointSearchFn& search);
  FrameResult Track(const std::vector<TrackObservation>& observations,
                    const MapPointSearchFn& search);
  // The map-point search of a frame posed at world_from_rig (see MapPointSearchFn).
  std::vector<Reobservation> SearchMapPoints(const std::vector<TrackObservation>& observations,
                                             const Rigid3d& world_from_rig, double radius_scale,
                                             const MapPointSearchFn& search);
  // Applies it: re-labels and appends observations; returns how many.
  int Reobserve(std::vector<TrackObservation>* observations, const Rigid3d& world_from_rig,
                double radius_scale, const MapPointSearchFn& search);
  struct Resection {
    std::vector<Eigen::Vector3d> bearings, positions;
    std::vector<int> cameras, observation_index;
    RansacResult ransac;
    Rigid3d world_from_rig;
    bool ok = false;
  };
  // The resection's RANSAC options: in RetryFrame, the threshold times retry_angle_error_scale.
  RansacOptions ResectionRansac() const {
    RansacOptions ransac = options.resection_ransac;
    if (retrying) ransac.max_angle_error *= options.retry_angle_error_scale;
    return ransac;
  }
  // P3P / GP3P in RANSAC on the observations of live map points; a prior pose (world_from_rig)
  // is tried first and taken without the RANSAC when it has accept_inliers inliers.
  Resection Resect(const std::vector<TrackObservation>& observations,
                   const Rigid3d* prior_world_from_rig = nullptr, int accept_inliers = 0);
  // The relative-pose fallback (TrackerOptions::relative_pose_fallback): a pose of the frame
  // from its 2-D matches with a posed frame and the scale of its map points; false when none.
  struct RelativeMotion {
    Rigid3d world_from_rig;
    int inliers = 0;       // of the relative pose
    int scale_points = 0;  // map points that agree with the scale
  };
  bool PoseFromRelativeMotion(const std::vector<TrackObservation>& observations,
                              RelativeMotion* motion) const;
  // The observations of live map points and the inliers of a given pose (no estimation).
  Resection EvaluatePose(const std::vector<TrackObservation>& observations,
                         const Rigid3d& world_from_rig) const;
  void TriangulateNewPoints(int keyframe);
  // max_scale_growth > 0 (the initialisation's adjustment of the first two keyframes, in
  // non-central mode): when the adjustment makes the distance between them more than this many
  // times larger, it is solved again with both fixed (the scale held).
  void LocalBundleAdjustment(double max_scale_growth = 0.0);
  void FinalizeUpTo(int end);
  // The "keyframe finalised" event of keyframe k: its pose and the points handed over with it
  // (their rays from keyframes up to k).
  FinalizedKeyframe MakeFinalized(int k, const std::vector<int>& handed_points,
                                  bool all_rays = false) const;
};

FrameResult Tracker::Impl::Initialise(const std::vector<TrackObservation>& observations) {
  FrameResult result;
  result.status = "initialising";
  std::unordered_map<int, int> first;
  const Keyframe& keyframe0 = keyframes[0];
  for (size_t i = 0; i < keyframe0.observations.size(); ++i)
    first.emplace(keyframe0.observations[i].track, static_cast<int>(i));
  std::vector<Eigen::Vector3d> bearings0, bearings1;
  std::vector<int> cameras0, cameras1, tracks;
  std::vector<int> index0, index1;
  for (size_t j = 0; j < observations.size(); ++j) {
    const auto it = first.find(observations[j].track);
    if (it == first.end()) continue;
    const TrackObservation& a = keyframe0.observations[it->second];
    const TrackObservation& b = observations[j];
    bearings0.push_back(options.central ? RigBearing(a) : a.bearing);
    bearings1.push_back(options.central ? RigBearing(b) : b.bearing);
    cameras0.push_back(a.camera);
    cameras1.push_back(b.camera);
    index0.push_back(it->second);
    index1.push_back(static_cast<int>(j));
  }
  if (static_cast<int>(bearings0.size()) < options.min_init_points) return result;
  if (!retrying &&
      static_cast<double>(bearings0.size()) <
          options.min_init_track_share * static_cast<double>(keyframe0.observations.size())) {
    result.status = "initialising (few of the first keyframe's tracks followed)";
    return result;
  }

  // Candidate poses of the second keyframe: the central five-point solution (unit baseline;
  // on rig-axis bearings), and in non-central mode also the generalised solution (metric
  // baseline, but the scale is ill-conditioned when the camera offsets are small for the
  // scene depth). The candidate that triangulates the most well-conditioned points wins.
  std::vector<Eigen::Vector3d> rig_bearings0, rig_bearings1;
  for (size_t i = 0; i < bearings0.size(); ++i) {
    rig_bearings0.push_back(RigBearing(keyframe0.observations[index0[i]]));
    rig_bearings1.push_back(RigBearing(observations[index1[i]]));
  }
  struct Candidate {
    Rigid3d world_from_rig1;
    std::vector<std::pair<int, Eigen::Vector3d>> points;
    bool metric = false;  // the generalised solution: the offsets give the scale
  };
  std::vector<Candidate> candidates;
  {
    CentralRelativePoseOptions relative;
    relative.ransac = options.relative_ransac;
    Rigid3d central0_from_central1;
    const RansacResult ransac = EstimateCentralRelativePose(rig_bearings0, rig_bearings1, relative,
                                                            &central0_from_central1);
    if (ransac.success) {
      // World = rig frame of keyframe 0; world_from_central0 = (I, c0).
      const Rigid3d world_from_central0(Eigen::Quaterniond::Identity(), central_center);
      candidates.push_back({RigFromCentral(world_from_central0 * central0_from_central1), {}});
    }
  }
  if (!options.central) {
    NoncentralRelativePoseOptions relative;
    relative.ransac = options.relative_ransac;
    Rigid3d rig0_from_rig1;
    const RansacResult ransac = EstimateNoncentralRelativePose(rig, bearings0, cameras0, bearings1,
                                                               cameras1, relative, &rig0_from_rig1);
    if (ransac.success) candidates.push_back({rig0_from_rig1, {}, true});
  }
  Candidate* best = nullptr;
  for (Candidate& candidate : candidates) {
    for (size_t i = 0; i < bearings0.size(); ++i) {
      const TrackObservation& a = keyframe0.observations[index0[i]];
      const TrackObservation& b = observations[index1[i]];
      Eigen::Vector3d position;
      if (TriangulatePoint({Ray(keyframe0.world_from_rig, a.camera, a.bearing),
                            Ray(candidate.world_from_rig1, b.camera, b.bearing)},
                           options.triangulation, &position) == TriangulationStatus::kOk)
        candidate.points.emplace_back(static_cast<int>(i), position);
    }
    // The generalised candidate (second) must triangulate clearly more points: when the
    // offsets are small for the depth its scale is ill-conditioned, and a near tie picked it
    // with a map 50 times too small on the demo drive.
    const double margin = best ? options.noncentral_init_margin : 1.0;
    if (!best || candidate.points.size() > margin * best->points.size()) best = &candidate;
  }
  if (!best || static_cast<int>(best->points.size()) < options.min_init_points) return result;
  const Rigid3d world_from_rig1 = best->world_from_rig1;
  const std::vector<std::pair<int, Eigen::Vector3d>>& new_points = best->points;
  metric_scale = !options.central && (best->metric || options.scale_from_offsets);
  scale_source =
      options.central              ? "arbitrary (central mode: the length of the first step is 1)"
      : options.scale_from_offsets ? "metric (the rig's camera offsets, in the bundle adjustments)"
      : best->metric ? "metric (the rig's offsets: generalised relative pose of the first two "
                       "keyframes)"
                     : "arbitrary (two-frame initialisation: the direction of the motion "
                       "only; the length of the first step is 1)";

  Keyframe keyframe1;
  keyframe1.frame = num_frames - 1;
  keyframe1.world_from_rig = world_from_rig1;
  keyframe1.observations = observations;
  for (const auto& [i, position] : new_points) {
    const TrackObservation& a = keyframe0.observations[index0[i]];
    const TrackObservation& b = observations[index1[i]];
    AddPoint(a.track, position, 1, {{0, a.camera, a.bearing}, {1, b.camera, b.bearing}});
  }
  // After the last use of keyframe0: the push_back may reallocate keyframes.
  keyframes.push_back(std::move(keyframe1));
  // Two keyframes barely observe the scale through small offsets (4 cm offsets, a step of
  // 0.75 m and points 10 m away: their adjustment took the unit step to anything from 0.008 to
  // 3,700). A map too small comes back (its offsets, large against its depths, observe the
  // scale well); from a map thousands of times metric the later adjustments did not (its
  // offsets are lost against its depths): a growth beyond max_initial_scale_growth is not taken
  // (LocalBundleAdjustment).
  LocalBundleAdjustment(
      !options.central && options.scale_from_offsets ? options.max_initial_scale_growth : 0.0);
  result.tracked = true;
  result.keyframe = true;
  result.world_from_rig = keyframes.back().world_from_rig;
  result.inliers = static_cast<int>(new_points.size());
  result.status = "initialised";
  return result;
}

std::vector<Reobservation> Tracker::Impl::SearchMapPoints(
    const std::vector<TrackObservation>& observations, const Rigid3d& world_from_rig,
    double radius_scale, const MapPointSearchFn& search) {
  const int num_cameras = static_cast<int>(rig.NumCameras());
  auto key = [num_cameras](int track, int camera) {
    return static_cast<int64_t>(track) * num_cameras + camera;
  };
  // The (track, camera) pairs the frame observes (sorted keys: no allocation per entry), and
  // the observations that may become map points: those whose track has none.
  std::vector<int64_t> observed;
  observed.reserve(observations.size());
  std::vector<char> eligible(observations.size(), 0);
  for (size_t i = 0; i < observations.size(); ++i) {
    observed.push_back(key(observations[i].track, observations[i].camera));
    const auto it = track_to_point.Find(observations[i].track);
    eligible[i] = it < 0 || !points[it].alive;
  }
  std::sort(observed.begin(), observed.end());
  auto is_observed = [&observed](int64_t k) {
    return std::binary_search(observed.begin(), observed.end(), k);
  };
  const Rigid3d rig_from_world = world_from_rig.Inverse();
  const int num_keyframes = static_cast<int>(keyframes.size());
  const int stamp = searches++;
  std::vector<MapPointProjection> candidates;
  for (int k = std::max(0, num_keyframes - options.map_search_keyframes); k < num_keyframes; ++k)
    for (const TrackObservation& observation : keyframes[k].observations) {
      const auto it = track_to_point.Find(observation.track);
      if (it < 0) continue;
      const Point& point = points[it];
      if (!point.alive || point_stamp[it] == stamp) continue;
      point_stamp[it] = stamp;
      const Eigen::Vector3d in_rig = rig_from_world * point.position;
      for (int c = 0; c < num_cameras; ++c) {
        if (is_observed(key(point.track, c))) continue;
        // The direction the map's model expects: from the central centre in central mode.
        const Eigen::Vector3d bearing =
            rig.cameras[c].cam_from_rig.rotation * (in_rig - CenterInRig(c));
        candidates.push_back({point.track, c, bearing, radius_scale});
      }
    }
  if (candidates.empty()) return {};
  std::vector<Reobservation> found = search(candidates, eligible);
  // The front end's promise, checked: each observation once, each (track, camera) once, only
  // eligible observations, only candidates.
  std::vector<int64_t> candidate_keys;
  candidate_keys.reserve(candidates.size());
  for (const MapPointProjection& candidate : candidates)
    candidate_keys.push_back(key(candidate.track, candidate.camera));
  std::sort(candidate_keys.begin(), candidate_keys.end());
  std::vector<char> used(observations.size(), 0);
  std::unordered_set<int64_t> taken;  // the pairs of the results so far
  std::vector<Reobservation> result;
  for (const Reobservation& r : found) {
    if (r.observation >= static_cast<int>(observations.size())) continue;
    const bool existing = r.observation >= 0;
    if (existing ? r.camera != observations[r.observation].camera
                 : r.camera < 0 || r.camera >= num_cameras)
      continue;
    const int64_t k = key(r.track, existing ? observations[r.observation].camera : r.camera);
    if (!std::binary_search(candidate_keys.begin(), candidate_keys.end(), k) || is_observed(k) ||
        taken.count(k))
      continue;
    if (existing && (!eligible[r.observation] || used[r.observation])) continue;
    if (existing) used[r.observation] = 1;
    taken.insert(k);
    result.push_back(r);
  }
  return result;
}

Tracker::Impl::Resection Tracker::Impl::Resect(const std::vector<TrackObservation>& observations,
                                               const Rigid3d* prior_world_from_rig,
                                               int accept_inliers) {
  const auto start = std::chrono::steady_clock::now();
  Resection r;
  for (size_t j = 0; j < observations.size(); ++j) {
    const auto it = track_to_point.Find(observations[j].track);
    if (it < 0 || !points[it].alive) continue;
    r.bearings.push_back(options.central ? RigBearing(observations[j]) : observations[j].bearing);
    r.cameras.push_back(observations[j].camera);
    r.positions.push_back(points[it].position);
    r.observation_index.push_back(static_cast<int>(j));
  }
  PosePrior prior;
  if (prior_world_from_rig != nullptr) {
    prior.pose = *prior_world_from_rig;
    prior.accept_inliers = std::max(accept_inliers, options.min_resection_inliers);
  }
  if (options.central) {
    CentralAbsolutePoseOptions absolute;
    absolute.ransac = ResectionRansac();
    absolute.consensus_angle_factor = options.ResectionConsensusAngleFactor();
    // The central frame sits at central_center in the rig frame.
    prior.pose.translation += prior.pose.rotation * central_center;
    Rigid3d world_from_central;
    r.ransac = EstimateCentralAbsolutePose(r.bearings, r.positions, absolute, &world_from_central,
                                           prior_world_from_rig != nullptr ? &prior : nullptr);
    r.world_from_rig = RigFromCentral(world_from_central);
  } else {
    NoncentralAbsolutePoseOptions absolute;
    absolute.ransac = ResectionRansac();
    absolute.hypotheses = options.noncentral_resection_hypotheses;
    absolute.consensus_angle_factor = options.ResectionConsensusAngleFactor();
    r.ransac = EstimateNoncentralAbsolutePose(rig, r.bearings, r.cameras, r.positions, absolute,
                                              &r.world_from_rig,
                                              prior_world_from_rig != nullptr ? &prior : nullptr);
  }
  const int inliers = r.ransac.num_inliers;
  const bool consistent =
      options.min_consistent_inliers > 0 && inliers >= options.min_consistent_inliers &&
      inliers >= options.consistent_inlier_share * static_cast<double>(r.bearings.size());
  r.ok = r.ransac.success && (inliers >= options.min_resection_inliers || consistent);
  AddSeconds(start, &timings.resect);
  return r;
}

int Tracker::Impl::Reobserve(std::vector<TrackObservation>* observations,
                             const Rigid3d& world_from_rig, double radius_scale,
                             const MapPointSearchFn& search) {
  const auto start = std::chrono::steady_clock::now();
  int count = 0;
  for (const Reobservation& r :
       SearchMapPoints(*observations, world_from_rig, radius_scale, search)) {
    if (r.observation >= 0) {
      (*observations)[r.observation].track = r.track;
      (*observations)[r.observation].bearing = r.bearing.normalized();
    } else
      observations->push_back({r.track, r.camera, r.bearing.normalized()});
    ++count;
  }
  AddSeconds(start, &timings.map_search);
  return count;
}

FrameResult Tracker::Impl::Track(const std::vector<TrackObservation>& input_observations,
                                 const MapPointSearchFn& search) {
  FrameResult result;
  // The frame's observations, re-labelled (and completed) by the map-point search.
  std::vector<TrackObservation> observations = input_observations;
  // The motion model's prediction first: taken without the RANSAC when it explains at least
  // resection_prior_share of the observations of map points.
  Resection resection;
  Rigid3d motion_prior;
  if (options.resection_prior_share < 1.0 && !last_tracked.empty() &&
      Predict(num_frames - 1, &motion_prior)) {
    int with_points = 0;
    for (const TrackObservation& o : observations) {
      const auto it = track_to_point.Find(o.track);
      with_points += it >= 0 && points[it].alive;
    }
    resection = Resect(observations, &motion_prior,
                       static_cast<int>(std::ceil(options.resection_prior_share * with_points)));
  } else {
    resection = Resect(observations);
  }
  bool searched = false;
  if (!resection.ok && search && !last_tracked.empty()) {
    // Too few chained tracks: search the map points around the constant-velocity prediction
    // (a wider radius) and resect again with what is found.
    Rigid3d predicted;
    if (Predict(num_frames - 1, &predicted)) {
      searched = true;
      result.reobserved =
          Reobserve(&observations, predicted, options.predicted_search_radius_scale, search);
      if (result.reobserved > 0) resection = Resect(observations);
    }
  }
  RelativeMotion relative;
  bool relative_alone = false;
  if (!resection.ok && retrying && options.relative_pose_fallback &&
      PoseFromRelativeMotion(observations, &relative)) {
    if (search)
      result.reobserved += Reobserve(&observations, relative.world_from_rig,
                                     options.predicted_search_radius_scale, search);
    Resection again = Resect(observations, &relative.world_from_rig);
    if (again.ok) {
      resection = std::move(again);
      result.status = "resected after its relative motion; ";
    } else if (relative.inliers >= options.min_relative_inliers_alone &&
               relative.scale_points >= options.min_scale_points_alone) {
      resection = EvaluatePose(observations, relative.world_from_rig);
      relative_alone = true;
      result.status = "posed by its relative motion; ";
    }
  }
  if (!resection.ok) {
    result.status = "resection failed: " + std::to_string(resection.ransac.num_inliers) +
                    " inliers of " + std::to_string(resection.bearings.size());
    if (ThinStereoMap()) {
      FrameResult initialised_again = InitialiseOverStereoMap(input_observations);
      if (initialised_again.tracked) return initialised_again;
    }
    return result;
  }
  // A pose far from the motion model is a wrong resection (wrong matches that agree), not a
  // jump of the rig: rejected rather than put in the map.
  Rigid3d predicted;
  if (!last_tracked.empty()) {
    if (Predict(num_frames - 1, &predicted)) {
      prediction_rotation_error =
          resection.world_from_rig.rotation.angularDistance(predicted.rotation);
      const Eigen::Vector3d step =
          resection.world_from_rig.translation - last_tracked.back().world_from_rig.translation;
      const Eigen::Vector3d error = resection.world_from_rig.translation - predicted.translation;
      const double length = step.norm();
      prediction_translation_error =
          length > 0.0 ? (error - error.dot(step / length) * (step / length)).norm() / length
                       : -1.0;
    }
    const double last_step = last_tracked.size() == 2
                                 ? (last_tracked[1].world_from_rig.translation -
                                    last_tracked[0].world_from_rig.translation)
                                       .norm()
                                 : 0.0;
    const double mean_step = travelled_steps > 0 ? travelled / travelled_steps : 0.0;
    const int frames_since = num_frames - 1 - last_tracked.back().frame;
    const double allowed =
        options.max_jump_ratio * std::max(last_step, mean_step) * std::max(1, frames_since);
    const double jump = (resection.world_from_rig.translation - predicted.translation).norm();
    if (mean_step > 0.0 && jump > allowed) {
      result.status = "rejected: resected pose " + std::to_string(jump / mean_step) +
                      " mean steps from the prediction";
      return result;
    }
  }
  // Map-point re-observation around the projections by the resected pose; then, optionally,
  // the pose again from every observation of a map point (kept when it has at least as many
  // inliers: the re-observations that agree are then among its inliers).
  if (search && !searched) {
    const int found = Reobserve(&observations, resection.world_from_rig, 1.0, search);
    result.reobserved += found;
    if (found > 0 && options.resect_after_search) {
      // The pose just resected first: kept without the RANSAC when it has at least as many
      // inliers among the observations the search completed.
      Resection again =
          options.resection_prior_after_search
              ? Resect(observations, &resection.world_from_rig, resection.ransac.num_inliers)
              : Resect(observations);
      if (again.ok && again.ransac.num_inliers >= resection.ransac.num_inliers)
        resection = std::move(again);
    }
  }
  const Rigid3d world_from_rig = resection.world_from_rig;
  const std::vector<Eigen::Vector3d>& bearings = resection.bearings;
  const std::vector<Eigen::Vector3d>& positions = resection.positions;
  const std::vector<int>& observation_index = resection.observation_index;
  const RansacResult& ransac = resection.ransac;
  result.tracked = true;
  result.world_from_rig = world_from_rig;
  result.inliers = ransac.num_inliers;
  last_frame = num_frames - 1;
  last_frame_observations = observations;

  // Keyframe decision against the last keyframe.
  const int last = static_cast<int>(keyframes.size()) - 1;
  KeyframeCandidate candidate;
  candidate.last_keyframe_world_from_rig = keyframes[last].world_from_rig;
  candidate.world_from_rig = world_from_rig;
  candidate.inliers = ransac.num_inliers;
  std::vector<double> depths;
  std::vector<char> tracked_now(points.size(), 0);
  for (size_t k = 0; k < bearings.size(); ++k) {
    if (!ransac.inlier_mask[k]) continue;
    tracked_now[track_to_point.At(observations[observation_index[k]].track)] = 1;
    depths.push_back((positions[k] - world_from_rig.translation).norm());
  }
  // The re-observations that agree with the pose (the resection's inliers already include
  // those of a search around the prediction) join their points at a keyframe, and count as
  // tracked: they were found where the pose projects them.
  std::vector<int> reobserved;
  std::vector<char> in_resection(observations.size(), 0);
  for (int j : observation_index) in_resection[j] = 1;
  for (size_t j = 0; j < observations.size(); ++j) {
    if (in_resection[j]) continue;
    const auto it = track_to_point.Find(observations[j].track);
    if (it < 0 || !points[it].alive) continue;
    if (ObservationAngleError(world_from_rig, observations[j], points[it].position) >
        options.reobservation_max_angle_error)
      continue;
    reobserved.push_back(static_cast<int>(j));
    if (options.reobserved_count_as_tracked) tracked_now[it] = 1;
  }
  // The frame's tracks, sorted, when the keyframe rule counts the last keyframe's followed ones.
  std::vector<int> followed;
  const bool count_followed = options.keyframes.min_followed_track_share > 0.0;
  if (count_followed) {
    followed.reserve(observations.size());
    for (const TrackObservation& o : observations) followed.push_back(o.track);
    std::sort(followed.begin(), followed.end());
  }
  for (const TrackObservation& observation : keyframes[last].observations) {
    if (count_followed) {
      ++candidate.last_keyframe_tracks;
      candidate.followed_tracks +=
          std::binary_search(followed.begin(), followed.end(), observation.track);
    }
    const auto it = track_to_point.Find(observation.track);
    if (it < 0 || !points[it].alive) continue;
    ++candidate.last_keyframe_points;
    candidate.tracked_points += tracked_now[it];
  }
  if (!depths.empty()) {
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    candidate.median_depth = depths[depths.size() / 2];
  }
  KeyframeDecisionReason decision = DecideKeyframe(candidate, options.keyframes);
  if (relative_alone) {
    // Its matches with the reference become points only at a keyframe.
    decision.decision = KeyframeDecision::kKeyframe;
    decision.reason = "keyframe of a thin map";
  }
  result.status += decision.reason;
  if (decision.decision != KeyframeDecision::kKeyframe) {
    if (options.keep_frame_observations) {
      std::vector<KeptObservation>& kept = kept_observations[num_frames - 1];
      kept.clear();
      const auto keep = [&](int j) {
        const TrackObservation& o = observations[j];
        kept.push_back({o.track, o.camera, o.bearing.cast<float>()});
      };
      for (size_t k = 0; k < bearings.size(); ++k)
        if (ransac.inlier_mask[k]) keep(observation_index[k]);
      for (int j : reobserved) keep(j);
    }
    if (options.frame_ray_step > 0 && ++tracked_since_keyframe % options.frame_ray_step == 0 &&
        MovedSinceLastRays(world_from_rig)) {
      std::vector<int> of_map_points = reobserved;
      for (size_t k = 0; k < bearings.size(); ++k)
        if (ransac.inlier_mask[k]) of_map_points.push_back(observation_index[k]);
      RecordFrameRays(world_from_rig, observations, of_map_points);
    }
    return result;
  }
  tracked_since_keyframe = 0;

  Keyframe keyframe;
  keyframe.frame = num_frames - 1;
  keyframe.world_from_rig = world_from_rig;
  keyframe.observations = observations;
  keyframes.push_back(std::move(keyframe));
  const int index = static_cast<int>(keyframes.size()) - 1;
  for (size_t k = 0; k < bearings.size(); ++k) {
    if (!ransac.inlier_mask[k]) continue;
    const TrackObservation& observation = observations[observation_index[k]];
    points[track_to_point.At(observation.track)].observations.push_back(
        {index, observation.camera, observation.bearing});
  }
  for (int j : reobserved) {
    const TrackObservation& observation = observations[j];
    points[track_to_point.At(observation.track)].observations.push_back(
        {index, observation.camera, observation.bearing});
  }
  TriangulateNewPoints(index);
  LocalBundleAdjustment();
  result.keyframe = true;
  result.world_from_rig = keyframes.back().world_from_rig;
  return result;
}

Tracker::Impl::Resection Tracker::Impl::EvaluatePose(
    const std::vector<TrackObservation>& observations, const Rigid3d& world_from_rig) const {
  Resection r;
  r.world_from_rig = world_from_rig;
  const double max_cos = std::cos(ResectionRansac().max_angle_error);
  for (size_t j = 0; j < observations.size(); ++j) {
    const auto it = track_to_point.Find(observations[j].track);
    if (it < 0 || !points[it].alive) continue;
    const Eigen::Vector3d& position = points[it].position;
    r.bearings.push_back(options.central ? RigBearing(observations[j]) : observations[j].bearing);
    r.cameras.push_back(observations[j].camera);
    r.positions.push_back(position);
    r.observation_index.push_back(static_cast<int>(j));
    const WorldRay ray = Ray(world_from_rig, observations[j].camera, observations[j].bearing);
    const Eigen::Vector3d to_point = position - ray.center;
    const bool inlier = ray.direction.normalized().dot(to_point) > max_cos * to_point.norm();
    r.ransac.inlier_mask.push_back(inlier ? 1 : 0);
    r.ransac.num_inliers += inlier;
  }
  r.ransac.success = true;
  r.ok = true;
  return r;
}

bool Tracker::Impl::PoseFromRelativeMotion(const std::vector<TrackObservation>& observations,
                                           RelativeMotion* motion) const {
  // The references: the last tracked frame and the last keyframes.
  struct Reference {
    const std::vector<TrackObservation>* observations;
    Rigid3d world_from_rig;
  };
  std::vector<Reference> references;
  if (!last_tracked.empty() && last_tracked.back().frame == last_frame)
    references.push_back({&last_frame_observations, last_tracked.back().world_from_rig});
  const int num_keyframes = static_cast<int>(keyframes.size());
  for (int k = num_keyframes - 1; k >= std::max(0, num_keyframes - 3); --k)
    references.push_back({&keyframes[k].observations, keyframes[k].world_from_rig});
  // The tracks of the frame: the first observation of each.
  std::unordered_map<int, int> frame_track;
  for (size_t j = 0; j < observations.size(); ++j)
    frame_track.emplace(observations[j].track, static_cast<int>(j));
  // The reference sharing the most tracks.
  const Reference* best = nullptr;
  std::vector<std::pair<int, int>> pairs;  // (reference observation, frame observation)
  for (const Reference& reference : references) {
    std::vector<std::pair<int, int>> shared;
    std::unordered_set<int> seen;
    for (size_t i = 0; i < reference.observations->size(); ++i) {
      const int track = (*reference.observations)[i].track;
      const auto it = frame_track.find(track);
      if (it != frame_track.end() && seen.insert(track).second)
        shared.emplace_back(static_cast<int>(i), it->second);
    }
    if (shared.size() > pairs.size()) {
      pairs = std::move(shared);
      best = &reference;
    }
  }
  if (!best || static_cast<int>(pairs.size()) < options.min_relative_matches) return false;
  std::vector<Eigen::Vector3d> bearings_reference, bearings_frame;
  for (const auto& [i, j] : pairs) {
    bearings_reference.push_back(RigBearing((*best->observations)[i]));
    bearings_frame.push_back(RigBearing(observations[j]));
  }
  CentralRelativePoseOptions relative;
  relative.ransac = options.relative_ransac;
  Rigid3d reference_from_frame;  // central frames, unit translation
  const RansacResult ransac = EstimateCentralRelativePose(bearings_reference, bearings_frame,
                                                          relative, &reference_from_frame);
  if (!ransac.success || ransac.num_inliers < options.min_relative_inliers) return false;
  // The scale: the frame's centre is s t in the reference's central frame; each inlier that is
  // a map point X gives the s that puts X on the frame's ray, and the s most points agree with
  // wins.
  const Rigid3d world_from_central_reference(
      best->world_from_rig.rotation,
      best->world_from_rig.translation + best->world_from_rig.rotation * central_center);
  const Rigid3d central_reference_from_world = world_from_central_reference.Inverse();
  const Eigen::Vector3d t = reference_from_frame.translation.normalized();
  std::vector<Eigen::Vector3d> in_reference, directions;
  std::vector<double> scales;
  for (size_t k = 0; k < pairs.size(); ++k) {
    if (!ransac.inlier_mask[k]) continue;
    const auto it = track_to_point.Find((*best->observations)[pairs[k].first].track);
    if (it < 0 || !points[it].alive) continue;
    const Eigen::Vector3d x = central_reference_from_world * points[it].position;
    const Eigen::Vector3d d = reference_from_frame.rotation * bearings_frame[k];
    const Eigen::Vector3d td = t.cross(d);
    if (td.squaredNorm() < 1e-12) continue;
    const double scale = x.cross(d).dot(td) / td.squaredNorm();
    if (!(scale > 0.0)) continue;
    in_reference.push_back(x);
    directions.push_back(d);
    scales.push_back(scale);
  }
  const double max_cos = std::cos(options.scale_max_angle_error);
  int best_count = 0;
  double best_scale = 0.0;
  for (double scale : scales) {
    int count = 0;
    for (size_t k = 0; k < scales.size(); ++k) {
      const Eigen::Vector3d to_point = in_reference[k] - scale * t;
      if (to_point.dot(directions[k]) > max_cos * to_point.norm()) ++count;
    }
    if (count > best_count) {
      best_count = count;
      best_scale = scale;
    }
  }
  spdlog::debug(
      "relative motion: {} shared tracks, {} inliers, {} of their {} map points agree on the scale",
      pairs.size(), ransac.num_inliers, best_count, scales.size());
  if (best_count < options.min_scale_points) return false;
  const Rigid3d world_from_central_frame =
      world_from_central_reference * Rigid3d(reference_from_frame.rotation, best_scale * t);
  motion->world_from_rig = RigFromCentral(world_from_central_frame);
  motion->inliers = ransac.num_inliers;
  motion->scale_points = best_count;
  return true;
}

void Tracker::Impl::TriangulateNewPoints(int keyframe) {
  const auto start = std::chrono::steady_clock::now();
  const int window_begin = TriangulationWindowBegin(keyframe);
  // The observations of the tracks without a point, in the window's keyframes (a track may
  // be seen by two cameras of one keyframe).
  std::unordered_map<int, std::vector<PointObservation>> by_track;
  for (const TrackObservation& observation : keyframes[keyframe].observations)
    if (!track_to_point.Contains(observation.track))
      by_track[observation.track].push_back({keyframe, observation.camera, observation.bearing});
  for (int k = keyframe - 1; k >= window_begin; --k)
    for (const TrackObservation& older : keyframes[k].observations) {
      const auto it = by_track.find(older.track);
      if (it != by_track.end()) it->second.push_back({k, older.camera, older.bearing});
    }
  std::unordered_map<int, int> new_tracks;
  for (const TrackObservation& observation : keyframes[keyframe].observations) {
    const auto it = by_track.find(observation.track);
    if (it == by_track.end() || track_to_point.Contains(observation.track)) continue;
    std::vector<PointObservation> track_observations = std::move(it->second);
    by_track.erase(it);
    const bool two_keyframes =
        std::any_of(track_observations.begin(), track_observations.end(),
                    [&](const PointObservation& o) { return o.keyframe != keyframe; });
    if (!two_keyframes) continue;
    std::vector<WorldRay> rays;
    for (const PointObservation& o : track_observations)
      rays.push_back(Ray(keyframes[o.keyframe].world_from_rig, o.camera, o.bearing));
    Eigen::Vector3d position;
    if (TriangulatePoint(rays, options.triangulation, &position) == TriangulationStatus::kOk)
      new_tracks[observation.track] =
          AddPoint(observation.track, position, keyframe, std::move(track_observations));
  }
  AddRecentFrameRays(new_tracks);
  if (options.frame_points) MakeFramePoints(keyframe);
  // The recorded frames before the next keyframe's window are of no further use.
  const int next_window_begin = TriangulationWindowBegin(keyframe + 1);
  while (!recent_frames.empty() &&
         frame_stamps[recent_frames.front().stamp].keyframe < next_window_begin)
    recent_frames.pop_front();
  AddSeconds(start, &timings.triangulate);
}

void Tracker::Impl::MakeFramePoints(int keyframe) {
  if (keyframe < 1) return;
  // The tracks that ended since the keyframe before: seen by it or by a recorded frame after
  // it, not by this keyframe, without a point. (One that ended earlier was looked at then.)
  std::unordered_set<int> seen_by_keyframe;
  for (const TrackObservation& o : keyframes[keyframe].observations)
    seen_by_keyframe.insert(o.track);
  std::unordered_map<int, std::vector<std::pair<int, TrackObservation>>> by_track;
  auto consider = [&](const TrackObservation& o) {
    if (!seen_by_keyframe.count(o.track) && !track_to_point.Contains(o.track) &&
        !frame_point_tracks.count(o.track))
      by_track.try_emplace(o.track);
  };
  for (const TrackObservation& o : keyframes[keyframe - 1].observations) consider(o);
  for (auto recent = recent_frames.rbegin(); recent != recent_frames.rend(); ++recent) {
    if (frame_stamps[recent->stamp].keyframe != keyframe - 1) break;
    for (const TrackObservation& o : recent->observations) consider(o);
  }
  if (by_track.empty()) return;
  // All their observations in the recorded frames, oldest first.
  for (const RecentFrame& recent : recent_frames)
    for (const TrackObservation& o : recent.observations) {
      const auto it = by_track.find(o.track);
      if (it != by_track.end()) it->second.emplace_back(recent.stamp, o);
    }
  std::vector<int> tracks;  // in track order: the points' order does not depend on hashing
  tracks.reserve(by_track.size());
  for (const auto& entry : by_track) tracks.push_back(entry.first);
  std::sort(tracks.begin(), tracks.end());
  for (const int track : tracks) {
    std::vector<std::pair<int, TrackObservation>>& observations = by_track[track];
    if (observations.size() < 2) continue;
    FramePoint point{-1, std::move(observations)};
    for (const auto& [stamp, o] : point.observations)
      point.keyframe = std::max(point.keyframe, frame_stamps[stamp].keyframe);
    Eigen::Vector3d position;
    if (TriangulatePoint(FramePointRays(point), options.triangulation, &position) !=
        TriangulationStatus::kOk)
      continue;
    frame_point_tracks.insert(track);
    if (static_cast<int>(frame_points_by_keyframe.size()) <= point.keyframe)
      frame_points_by_keyframe.resize(point.keyframe + 1);
    frame_points_by_keyframe[point.keyframe].push_back(static_cast<int>(frame_points.size()));
    frame_points.push_back(std::move(point));
  }
}

std::vector<WorldRay> Tracker::Impl::FramePointRays(const FramePoint& point) const {
  std::vector<WorldRay> rays;
  for (const auto& [stamp, o] : point.observations)
    rays.push_back(Ray(FrameStampPose(frame_stamps[stamp]), o.camera, o.bearing));
  return rays;
}

void Tracker::Impl::LocalBundleAdjustment(double max_scale_growth) {
  const int num_keyframes = static_cast<int>(keyframes.size());
  const int gauge_keyframes = GaugeKeyframes();
  const int free_begin = std::max(gauge_keyframes, num_keyframes - options.num_free_keyframes);
  const int fixed_begin = std::max(0, free_begin - options.num_fixed_keyframes);
  BundleAdjustmentProblem problem;
  std::vector<int> problem_keyframe(num_keyframes, -1), keyframe_of;
  for (int k = fixed_begin; k < num_keyframes; ++k) {
    problem_keyframe[k] = static_cast<int>(problem.keyframes.size());
    problem.keyframes.push_back({keyframes[k].world_from_rig, k < free_begin});
    keyframe_of.push_back(k);
  }
  std::vector<int> point_of;
  std::vector<std::pair<int, int>> observation_of;  // (point, index in its observations)
  for (size_t p = 0; p < points.size(); ++p) {
    Point& point = points[p];
    if (!point.alive) continue;
    const bool seen_by_free =
        std::any_of(point.observations.begin(), point.observations.end(),
                    [&](const PointObservation& o) { return o.keyframe >= free_begin; });
    if (!seen_by_free) continue;
    const int problem_point = static_cast<int>(problem.points_in_world.size());
    problem.points_in_world.push_back(point.position);
    // The points handed over to the surface never move again.
    problem.point_fixed.push_back(point.handed_over_by >= 0 ? 1 : 0);
    point_of.push_back(static_cast<int>(p));
    for (size_t i = 0; i < point.observations.size(); ++i) {
      const PointObservation& o = point.observations[i];
      if (problem_keyframe[o.keyframe] < 0) continue;
      problem.observations.push_back(
          {problem_keyframe[o.keyframe], o.camera, problem_point, o.bearing});
      observation_of.emplace_back(static_cast<int>(p), static_cast<int>(i));
    }
  }
  if (problem.observations.empty()) return;
  BundleAdjustmentOptions ba_options = options.bundle_adjustment;
  ba_options.mode = options.central ? BundleAdjustmentOptions::Mode::kCentral
                                    : BundleAdjustmentOptions::Mode::kNonCentral;
  const auto start = std::chrono::steady_clock::now();
  const bool check_scale = max_scale_growth > 0.0 && fixed_begin == 0 &&
                           problem.keyframes.size() >= 2 && !problem.keyframes[1].fixed;
  BundleAdjustmentProblem unsolved;
  if (check_scale) unsolved = problem;
  BundleAdjustmentSummary summary = LocalBundleAdjust(rig, ba_options, &problem);
  if (check_scale && summary.success) {
    const auto step = [](const BundleAdjustmentProblem& p) {
      return (p.keyframes[1].world_from_rig.translation - p.keyframes[0].world_from_rig.translation)
          .norm();
    };
    const double growth = step(problem) / step(unsolved);
    if (!(growth <= max_scale_growth)) {
      spdlog::debug(
          "sfm: the adjustment of the first keyframes made their distance {} times "
          "larger; solved again with the scale held",
          growth);
      problem = std::move(unsolved);
      problem.keyframes[1].fixed = true;
      summary = LocalBundleAdjust(rig, ba_options, &problem);
    }
  }
  AddSeconds(start, &timings.bundle_adjustment);
  if (!summary.success) return;
  for (size_t k = 0; k < problem.keyframes.size(); ++k)
    keyframes[keyframe_of[k]].world_from_rig = problem.keyframes[k].world_from_rig;
  for (size_t i = 0; i < point_of.size(); ++i)
    points[point_of[i]].position = problem.points_in_world[i];
  // Drop the outlier observations (mark, then erase), and the points left with fewer than two.
  std::vector<std::vector<int>> removed(points.size());
  for (int r : summary.removed_observations)
    removed[observation_of[r].first].push_back(observation_of[r].second);
  for (size_t p = 0; p < points.size(); ++p) {
    if (removed[p].empty()) continue;
    std::sort(removed[p].rbegin(), removed[p].rend());
    for (int i : removed[p]) points[p].observations.erase(points[p].observations.begin() + i);
    if (points[p].observations.size() < 2) {
      points[p].alive = false;
      track_to_point.Erase(points[p].track);
    }
  }
  FinalizeUpTo(num_keyframes - options.num_free_keyframes);
}

FinalizedKeyframe Tracker::Impl::MakeFinalized(int k, const std::vector<int>& handed_points,
                                               bool all_rays) const {
  const Keyframe& keyframe = keyframes[k];
  FinalizedKeyframe event;
  event.keyframe = k;
  event.frame = keyframe.frame;
  event.world_from_rig = keyframe.world_from_rig;
  event.center = keyframe.world_from_rig * central_center;
  for (int p : handed_points) {
    FinalizedPoint finalized_point;
    finalized_point.point = p;
    finalized_point.position = points[p].position;
    for (const PointObservation& o : points[p].observations)
      // Rays of keyframes up to k only: the later ones can still move.
      if (o.keyframe <= k || all_rays)
        finalized_point.rays.push_back(
            {o.keyframe, keyframes[o.keyframe].world_from_rig * CenterInRig(o.camera), o.camera,
             o.bearing});
    // A frame ray within frame_ray_min_angle of a ray kept before it (the keyframes' first)
    // carves nearly the same cells: left out.
    std::vector<Eigen::Vector3d> directions;
    const double max_cos = std::cos(options.frame_ray_min_angle);
    if (options.frame_ray_min_angle > 0.0)
      for (const FinalizedRay& ray : finalized_point.rays)
        directions.push_back((ray.center - finalized_point.position).normalized());
    for (const FrameObservation& o : points[p].frame_observations) {
      const FrameStamp& stamp = frame_stamps[o.stamp];
      if (stamp.keyframe > k && !all_rays) continue;
      const Eigen::Vector3d center = FrameStampPose(stamp) * CenterInRig(o.camera);
      if (options.frame_ray_min_angle > 0.0) {
        const Eigen::Vector3d direction = (center - finalized_point.position).normalized();
        if (std::any_of(directions.begin(), directions.end(),
                        [&](const Eigen::Vector3d& d) { return d.dot(direction) > max_cos; }))
          continue;
        directions.push_back(direction);
      }
      finalized_point.frame_rays.push_back({stamp.keyframe, stamp.frame, o.camera, center});
    }
    event.points.push_back(std::move(finalized_point));
  }
  // The frame points of the frames after k, triangulated from their frames' poses now (they
  // follow the keyframes' corrections); the checks are those they passed when made, but a
  // correction may have bent their rays apart: then they are left out.
  const std::vector<int> none;
  for (const int f :
       k < static_cast<int>(frame_points_by_keyframe.size()) ? frame_points_by_keyframe[k] : none) {
    const FramePoint& frame_point = frame_points[f];
    FinalizedPoint finalized_point;
    finalized_point.point = kFramePointIdBase + f;
    finalized_point.frame_point = true;
    // The rays' centres are the frame rays' (each frame's pose computed once).
    const std::vector<WorldRay> rays = FramePointRays(frame_point);
    if (TriangulatePoint(rays, options.triangulation, &finalized_point.position) !=
        TriangulationStatus::kOk)
      continue;
    for (size_t i = 0; i < rays.size(); ++i) {
      const auto& [stamp, o] = frame_point.observations[i];
      finalized_point.frame_rays.push_back(
          {frame_stamps[stamp].keyframe, frame_stamps[stamp].frame, o.camera, rays[i].center});
    }
    event.points.push_back(std::move(finalized_point));
  }
  return event;
}

void Tracker::Impl::FinalizeUpTo(int end) {
  for (int k = 0; k < end; ++k) {
    Keyframe& keyframe = keyframes[k];
    if (keyframe.finalized) continue;
    keyframe.finalized = true;
    // Hand over the points created up to k that no newer keyframe observes, and those whose
    // delay is over; the others wait for a later keyframe.
    std::vector<int> handed, still_pending;
    for (int p : pending) {
      Point& point = points[p];
      if (!point.alive) continue;
      const bool observed_later =
          std::any_of(point.observations.begin(), point.observations.end(),
                      [k](const PointObservation& o) { return o.keyframe > k; });
      if (point.created_by <= k &&
          (!observed_later || k >= point.created_by + options.max_handover_delay)) {
        point.handed_over_by = k;
        handed.push_back(p);
      } else {
        still_pending.push_back(p);
      }
    }
    pending = std::move(still_pending);
    finalized.push_back(MakeFinalized(k, handed));
  }
}

void Tracker::Impl::RecordFrameRays(const Rigid3d& world_from_rig,
                                    const std::vector<TrackObservation>& observations,
                                    const std::vector<int>& of_map_points) {
  const int stamp = static_cast<int>(frame_stamps.size());
  const int keyframe = static_cast<int>(keyframes.size()) - 1;
  frame_stamps.push_back({num_frames - 1, keyframe,
                          keyframes[keyframe].world_from_rig.Inverse() * world_from_rig,
                          KeyframeStep(keyframe)});
  for (int j : of_map_points)
    AddFrameObservation(&points[track_to_point.At(observations[j].track)], stamp,
                        observations[j].camera);
  RecentFrame recent;
  recent.stamp = stamp;
  for (const TrackObservation& observation : observations)
    if (!track_to_point.Contains(observation.track)) recent.observations.push_back(observation);
  recent_frames.push_back(std::move(recent));
}

void Tracker::Impl::AddRecentFrameRays(const std::unordered_map<int, int>& new_tracks) {
  if (new_tracks.empty()) return;
  for (const RecentFrame& recent : recent_frames) {
    const Rigid3d world_from_rig = FrameStampPose(frame_stamps[recent.stamp]);
    for (const TrackObservation& observation : recent.observations) {
      const auto it = new_tracks.find(observation.track);
      if (it == new_tracks.end()) continue;
      Point& point = points[it->second];
      if (ObservationAngleError(world_from_rig, observation, point.position) >
          options.reobservation_max_angle_error)
        continue;
      AddFrameObservation(&point, recent.stamp, observation.camera);
    }
  }
}

Tracker::Tracker(const Rig& rig, const TrackerOptions& options) : impl_(new Impl) {
  ThrowIfInvalid(options.Check(), "TrackerOptions");
  if (rig.cameras.empty()) throw std::invalid_argument("Tracker: the rig has no camera");
  impl_->rig = rig;
  impl_->options = options;
  for (const Camera& camera : rig.cameras) impl_->central_center += camera.cam_from_rig.Center();
  impl_->central_center /= static_cast<double>(rig.cameras.size());
}

Tracker::~Tracker() = default;

FrameResult Tracker::AddFrame(const std::vector<TrackObservation>& observations,
                              const MapPointSearchFn& search) {
  Impl& s = *impl_;
  ++s.num_frames;
  s.prediction_rotation_error = -1.0;  // until the frame is resected against a prediction
  s.prediction_translation_error = -1.0;
  const int frame = s.num_frames - 1;
  // A new start when the first keyframe cannot be initialised from (see max_init_frames).
  // A stereo map of one keyframe is given up only when no frame has been tracked from it for as
  // long (a rig standing still keeps its map and its poses).
  const bool restart =
      !s.keyframes.empty() &&
      ((!s.initialised &&
        (frame - s.keyframes[0].frame > s.options.max_init_frames ||
         static_cast<int>(s.keyframes[0].observations.size()) < s.options.min_init_points)) ||
       (s.ThinStereoMap() && !s.last_tracked.empty() &&
        frame - s.last_tracked.back().frame > s.options.max_init_frames));
  if (s.keyframes.empty() || restart) return s.StartMap(observations);
  return s.Process(observations, search);
}

bool Tracker::CanRetryFrame() const {
  const Impl& s = *impl_;
  const int frame = s.num_frames - 1;
  return !s.keyframes.empty() && s.keyframes.back().frame != frame &&
         (s.last_tracked.empty() || s.last_tracked.back().frame != frame);
}

FrameResult Tracker::RetryFrame(const std::vector<TrackObservation>& observations,
                                const MapPointSearchFn& search) {
  if (!CanRetryFrame()) {
    FrameResult result;
    result.status = "no frame to retry";
    return result;
  }
  struct RetryScope {
    bool& retrying;
    ~RetryScope() { retrying = false; }
  } scope{impl_->retrying};
  impl_->retrying = true;
  return impl_->Process(observations, search);
}

FrameResult Tracker::Impl::StartMap(const std::vector<TrackObservation>& observations) {
  const int frame = num_frames - 1;
  if (!keyframes.empty()) {
    // The first keyframe given up, and the frames waiting for its map.
    FrameResult dropped;
    dropped.status = "initialisation restarted from frame " + std::to_string(frame);
    revised.push_back({keyframes[0].frame, dropped});
  }
  keyframes.clear();
  keyframes_at_global_adjustment = 0;
  ClearPoints();
  init_frames.clear();
  last_tracked.clear();
  travelled = 0.0;
  travelled_steps = 0;
  initialised = false;
  map_from_stereo = false;
  metric_scale = false;
  scale_source.clear();
  Keyframe keyframe;
  keyframe.frame = frame;
  keyframe.observations = observations;
  keyframes.push_back(std::move(keyframe));
  FrameResult result;
  result.keyframe = true;
  // A frame with too few observations (a black frame) cannot start a map: the next frame
  // starts again (AddFrame).
  result.tracked = static_cast<int>(observations.size()) >= options.min_init_points;
  result.status = result.tracked ? "first keyframe" : "too few observations to start a map";
  if (!options.central && options.stereo_initialisation) {
    const int stereo_points = TriangulateStereo();
    if (stereo_points >= options.min_stereo_points) {
      initialised = true;
      map_from_stereo = true;
      metric_scale = true;
      scale_source = "metric (the rig's stereo baseline: " + std::to_string(stereo_points) +
                     " points of the first keyframe)";
      result.inliers = stereo_points;
      result.status = "initialised from the rig's stereo baseline";
    } else {
      ClearPoints();
    }
  }
  if (result.tracked) RecordTracked(frame, result.world_from_rig);
  return result;
}

int Tracker::Impl::TriangulateStereo() {
  // The tracks that two or more cameras of the first keyframe observe.
  std::unordered_map<int, std::vector<int>> by_track;
  const Keyframe& keyframe0 = keyframes[0];
  for (size_t i = 0; i < keyframe0.observations.size(); ++i)
    by_track[keyframe0.observations[i].track].push_back(static_cast<int>(i));
  TriangulationOptions triangulation = options.triangulation;
  triangulation.min_ray_angle = options.stereo_min_ray_angle;
  int count = 0;
  for (const auto& [track, indices] : by_track) {
    if (indices.size() < 2) continue;
    std::vector<WorldRay> rays;
    std::vector<PointObservation> point_observations;
    for (int i : indices) {
      const TrackObservation& o = keyframe0.observations[i];
      rays.push_back(Ray(keyframe0.world_from_rig, o.camera, o.bearing));
      point_observations.push_back({0, o.camera, o.bearing});
    }
    Eigen::Vector3d position;
    if (TriangulatePoint(rays, triangulation, &position) != TriangulationStatus::kOk) continue;
    AddPoint(track, position, 0, std::move(point_observations));
    ++count;
  }
  return count;
}

FrameResult Tracker::Impl::InitialiseOverStereoMap(
    const std::vector<TrackObservation>& observations) {
  // The stereo map, kept to be restored, and its positions by track (the scale's reference).
  std::vector<Point> stereo_points = points;
  TrackToPoint stereo_track_to_point = track_to_point;
  std::vector<int> stereo_pending = pending;
  std::vector<int> stereo_stamp = point_stamp;
  std::vector<FrameStamp> stereo_frame_stamps = frame_stamps;
  std::deque<RecentFrame> stereo_recent_frames = recent_frames;
  std::vector<FramePoint> stereo_frame_points = frame_points;
  std::vector<std::vector<int>> stereo_frame_points_by_keyframe = frame_points_by_keyframe;
  std::unordered_set<int> stereo_frame_point_tracks = frame_point_tracks;
  const std::string stereo_scale_source = scale_source;
  ClearPoints();
  map_from_stereo = false;
  FrameResult result = Initialise(observations);
  if (!result.tracked) {
    points = std::move(stereo_points);
    track_to_point = std::move(stereo_track_to_point);
    pending = std::move(stereo_pending);
    point_stamp = std::move(stereo_stamp);
    frame_stamps = std::move(stereo_frame_stamps);
    recent_frames = std::move(stereo_recent_frames);
    frame_points = std::move(stereo_frame_points);
    frame_points_by_keyframe = std::move(stereo_frame_points_by_keyframe);
    frame_point_tracks = std::move(stereo_frame_point_tracks);
    map_from_stereo = true;
    metric_scale = true;
    scale_source = stereo_scale_source;
    return result;
  }
  // The scale: each new point that is also a stereo point gives the ratio of its two distances
  // from the first keyframe's camera that saw it; the median, if enough ratios agree with it.
  const Keyframe& keyframe0 = keyframes[0];
  std::vector<double> ratios;
  for (const Point& point : points) {
    const auto it = stereo_track_to_point.Find(point.track);
    if (it < 0 || point.observations.empty()) continue;
    const PointObservation& first = point.observations.front();
    const Eigen::Vector3d center =
        Ray(keyframe0.world_from_rig, first.camera, first.bearing).center;
    const double temporal = (point.position - center).norm();
    const double stereo = (stereo_points[it].position - center).norm();
    if (temporal > 0.0 && std::isfinite(stereo)) ratios.push_back(stereo / temporal);
  }
  double scale = 0.0;
  int agreeing = 0;
  if (!ratios.empty()) {
    std::vector<double> sorted = ratios;
    std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
    scale = sorted[sorted.size() / 2];
    for (double ratio : ratios) agreeing += std::abs(ratio / scale - 1.0) < 0.2;
    std::sort(sorted.begin(), sorted.end());
    spdlog::debug("stereo scale: {} shared points, ratios q10 {} q50 {} q90 {}, {} agree",
                  sorted.size(), sorted[sorted.size() / 10], scale, sorted[9 * sorted.size() / 10],
                  agreeing);
  }
  if (agreeing < options.min_stereo_scale_points) {
    result.status = "initialised from two frames (the stereo map too thin to track; " +
                    std::to_string(agreeing) + " stereo points agree on a scale)";
    return result;
  }
  // Scaled about the first keyframe; the stereo rays of the first keyframe join the points,
  // so that the adjustments keep the scale (one keyframe fixes the gauge, as for a stereo map).
  const Eigen::Vector3d origin = keyframe0.world_from_rig.translation;
  for (Point& point : points) point.position = origin + scale * (point.position - origin);
  Rigid3d& world_from_rig1 = keyframes[1].world_from_rig;
  world_from_rig1.translation = origin + scale * (world_from_rig1.translation - origin);
  for (Point& point : points) {
    for (const TrackObservation& observation : keyframe0.observations) {
      if (observation.track != point.track) continue;
      bool present = false;
      for (const PointObservation& o : point.observations)
        present |= o.keyframe == 0 && o.camera == observation.camera;
      if (!present) point.observations.push_back({0, observation.camera, observation.bearing});
    }
  }
  map_from_stereo = true;
  metric_scale = true;
  LocalBundleAdjustment();
  scale_source = "metric (two-frame initialisation scaled by " + std::to_string(agreeing) +
                 " of the rig's stereo points)";
  result.world_from_rig = keyframes.back().world_from_rig;
  result.status = "initialised from two frames (the stereo map too thin to track), scaled by " +
                  std::to_string(agreeing) + " stereo points";
  return result;
}

FrameResult Tracker::Impl::Process(const std::vector<TrackObservation>& observations,
                                   const MapPointSearchFn& search) {
  const int frame = num_frames - 1;
  // A thin stereo map is still an initialisation: its failed frames wait for the map too.
  const bool initialising = !initialised || ThinStereoMap();
  const FrameResult result = keyframes.size() == 1 && !initialised ? Initialise(observations)
                                                                   : Track(observations, search);
  if (result.tracked) RecordTracked(frame, result.world_from_rig);
  if (initialising && !result.tracked) {
    // Kept for its resection once the map exists (the last attempt at a frame wins).
    if (!init_frames.empty() && init_frames.back().first == frame) init_frames.pop_back();
    init_frames.emplace_back(frame, observations);
  }
  if (initialising && result.tracked) {
    initialised = true;
    // The frames read while initialising, resected in the new map (their own matches: the
    // threshold of a frame the front end tracked, also when a retry initialised).
    const bool was_retrying = retrying;
    retrying = false;
    for (const auto& [earlier, earlier_observations] : init_frames) {
      if (earlier == frame) continue;
      const Resection resection = Resect(earlier_observations);
      if (!resection.ok) continue;
      FrameResult late;
      late.tracked = true;
      late.world_from_rig = resection.world_from_rig;
      late.inliers = resection.ransac.num_inliers;
      late.status = "resected once the map existed";
      revised.push_back({earlier, late});
    }
    retrying = was_retrying;
    init_frames.clear();
  }
  return result;
}

bool Tracker::Initialised() const { return impl_->initialised; }

std::string Tracker::ScaleSource() const { return impl_->scale_source; }

double Tracker::MedianPointDepth() const {
  const Impl& m = *impl_;
  std::vector<double> depths;
  for (const Impl::Point& point : m.points) {
    if (!point.alive || point.observations.empty()) continue;
    const Impl::PointObservation& first = point.observations.front();
    depths.push_back(
        (point.position -
         m.Ray(m.keyframes[first.keyframe].world_from_rig, first.camera, first.bearing).center)
            .norm());
  }
  if (depths.empty()) return 0.0;
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
  return depths[depths.size() / 2];
}

bool Tracker::MetricScale() const { return impl_->metric_scale; }

std::vector<Tracker::RevisedFrame> Tracker::TakeRevisedFrames() {
  std::vector<RevisedFrame> taken = std::move(impl_->revised);
  impl_->revised.clear();
  return taken;
}

bool Tracker::PredictPose(Rigid3d* world_from_rig) const {
  if (!impl_->initialised) return false;
  return impl_->Predict(impl_->num_frames, world_from_rig) &&
         impl_->last_tracked.back().frame == impl_->num_frames - 1;
}

bool Tracker::PredictMotion(Rigid3d* previous_world_from_rig, Rigid3d* predicted_world_from_rig,
                            double* last_rotation_error, double* last_translation_error) const {
  if (!PredictPose(predicted_world_from_rig)) return false;
  *previous_world_from_rig = impl_->last_tracked.back().world_from_rig;
  if (last_rotation_error) *last_rotation_error = impl_->prediction_rotation_error;
  if (last_translation_error) *last_translation_error = impl_->prediction_translation_error;
  return true;
}

bool Tracker::TrackPosition(int track, Eigen::Vector3d* position) const {
  const auto it = impl_->track_to_point.Find(track);
  if (it < 0 || !impl_->points[it].alive) return false;
  *position = impl_->points[it].position;
  return true;
}

Tracker::Timings Tracker::StageTimings() const { return impl_->timings; }

FramePoseRefinement Tracker::RefineFramePose(int frame, const Rigid3d& world_from_rig,
                                             const FramePoseRefinementOptions& options) const {
  ThrowIfInvalid(options.Check(), "FramePoseRefinementOptions");
  const Impl& m = *impl_;
  FramePoseRefinement refinement;
  refinement.world_from_rig = world_from_rig;
  const auto kept = m.kept_observations.find(frame);
  if (kept == m.kept_observations.end()) return refinement;
  BundleAdjustmentProblem problem;
  problem.keyframes.push_back({world_from_rig, false});
  std::unordered_map<int, int> problem_point;  // map point → index in the problem
  for (const Impl::KeptObservation& o : kept->second) {
    const auto it = m.track_to_point.Find(o.track);
    if (it < 0 || !m.points[it].alive) continue;
    const auto [point, added] =
        problem_point.emplace(it, static_cast<int>(problem.points_in_world.size()));
    if (added) problem.points_in_world.push_back(m.points[it].position);
    problem.observations.push_back({0, o.camera, point->second, o.bearing.cast<double>()});
  }
  refinement.observations = static_cast<int>(problem.observations.size());
  if (refinement.observations < options.min_inliers) return refinement;
  problem.point_fixed.assign(problem.points_in_world.size(), 1);
  BundleAdjustmentOptions ba_options = m.options.bundle_adjustment;
  ba_options.mode = m.options.central ? BundleAdjustmentOptions::Mode::kCentral
                                      : BundleAdjustmentOptions::Mode::kNonCentral;
  ba_options.estimate_offset_scale = false;
  ba_options.linear_solver = BundleAdjustmentOptions::LinearSolver::kDenseSchur;
  ba_options.max_iterations = options.max_iterations;
  ba_options.num_threads = 1;
  const BundleAdjustmentSummary summary = LocalBundleAdjust(m.rig, ba_options, &problem);
  if (!summary.success) return refinement;
  refinement.inliers = static_cast<int>(problem.observations.size());
  const Rigid3d& refined = problem.keyframes[0].world_from_rig;
  double before = 0.0, after = 0.0;
  for (const BundleAdjustmentObservation& o : problem.observations) {
    const Eigen::Vector3d& position = problem.points_in_world[o.point];
    const double angle_before =
        ObservationAngle(m.rig, ba_options.mode, world_from_rig, position, o.camera, o.bearing);
    const double angle_after =
        ObservationAngle(m.rig, ba_options.mode, refined, position, o.camera, o.bearing);
    before += angle_before * angle_before;
    after += angle_after * angle_after;
  }
  if (refinement.inliers > 0) {
    refinement.rms_angle_before = std::sqrt(before / refinement.inliers);
    refinement.rms_angle_after = std::sqrt(after / refinement.inliers);
  }
  if (refinement.inliers < options.min_inliers ||
      refinement.inliers < options.min_inlier_share * refinement.observations ||
      refinement.rms_angle_after > refinement.rms_angle_before)
    return refinement;
  refinement.refined = true;
  refinement.world_from_rig = refined;
  return refinement;
}

void Tracker::Finish() { impl_->FinalizeUpTo(static_cast<int>(impl_->keyframes.size())); }

std::vector<FinalizedKeyframe> Tracker::TakeFinalized() {
  std::vector<FinalizedKeyframe> result = std::move(impl_->finalized);
  impl_->finalized.clear();
  return result;
}

int Tracker::NumKeyframes() const { return static_cast<int>(impl_->keyframes.size()); }

int Tracker::NumPoints() const {
  return static_cast<int>(std::count_if(impl_->points.begin(), impl_->points.end(),
                                        [](const Impl::Point& p) { return p.alive; }));
}

Rigid3d Tracker::KeyframePose(int keyframe) const {
  return impl_->keyframes.at(static_cast<size_t>(keyframe)).world_from_rig;
}

std::vector<Rigid3d> Tracker::KeyframePoses() const {
  std::vector<Rigid3d> poses;
  for (const auto& keyframe : impl_->keyframes) poses.push_back(keyframe.world_from_rig);
  return poses;
}

std::vector<int> Tracker::KeyframeFrames() const {
  std::vector<int> frames;
  for (const auto& keyframe : impl_->keyframes) frames.push_back(keyframe.frame);
  return frames;
}

// ---- Map access and correction (loop closure) ----

std::vector<std::pair<int, Eigen::Vector3d>> Tracker::KeyframeTrackPoints(int keyframe) const {
  std::vector<std::pair<int, Eigen::Vector3d>> result;
  for (const TrackObservation& observation : impl_->keyframes.at(keyframe).observations) {
    const auto it = impl_->track_to_point.Find(observation.track);
    if (it < 0 || !impl_->points[it].alive) continue;
    result.emplace_back(observation.track, impl_->points[it].position);
  }
  return result;
}

void Tracker::ApplyCorrection(const std::vector<Sim3d>& new_from_old) {
  assert(new_from_old.size() == impl_->keyframes.size());
  for (size_t k = 0; k < impl_->keyframes.size(); ++k)
    impl_->keyframes[k].world_from_rig =
        TransformPose(new_from_old[k], impl_->keyframes[k].world_from_rig);
  for (Impl::Point& point : impl_->points)
    if (point.created_by >= 0) point.position = new_from_old[point.created_by] * point.position;
  // The last tracked frames move with the newest keyframe: otherwise the motion model predicts
  // the next frame in the uncorrected map and every resected pose is rejected as a jump.
  if (!new_from_old.empty())
    for (Impl::TrackedPose& tracked : impl_->last_tracked)
      tracked.world_from_rig = TransformPose(new_from_old.back(), tracked.world_from_rig);
}

void Tracker::MergeTracks(const std::vector<std::pair<int, int>>& drop_keep) {
  Impl& m = *impl_;
  for (const auto& [drop, keep] : drop_keep) {
    const auto d = m.track_to_point.Find(drop), k = m.track_to_point.Find(keep);
    if (d < 0 || k < 0 || d == k) continue;
    Impl::Point& from = m.points[d];
    Impl::Point& to = m.points[k];
    if (!from.alive || !to.alive) continue;
    for (const Impl::PointObservation& o : from.observations) {
      const bool seen = std::any_of(to.observations.begin(), to.observations.end(),
                                    [&](const Impl::PointObservation& t) {
                                      return t.keyframe == o.keyframe && t.camera == o.camera;
                                    });
      if (!seen) to.observations.push_back(o);
    }
    to.frame_observations.insert(to.frame_observations.end(), from.frame_observations.begin(),
                                 from.frame_observations.end());
    from.alive = false;
    m.track_to_point.Set(drop, k);
  }
}

// The live points that are one place seen by two tracks (a corner whose track broke and was
// detected again, a point of another camera) fused before a global adjustment: two points
// closer than kSearchRadiusInMergeAngles * `merge_angle` times their depth (a point of a short
// track is uncertain along its rays far more than across them), never observed by one camera of one
// keyframe, whose observations all fit their observation-weighted mean within `merge_angle`. The
// dropped point gives its observations to the kept one, dies, and its tracks follow. Returns the
// number of points fused.
constexpr double kSearchRadiusInMergeAngles = 20.0;

template <typename PointT>
int MergeNearbyPoints(const Rig& rig, BundleAdjustmentOptions::Mode mode,
                      const std::vector<Rigid3d>& world_from_rig, double merge_angle,
                      std::vector<PointT>* points, TrackToPoint* track_to_point) {
  std::vector<int> live;
  std::vector<double> radius(points->size(), 0.0);
  for (size_t p = 0; p < points->size(); ++p) {
    const PointT& point = (*points)[p];
    if (!point.alive || point.observations.empty()) continue;
    double depth = std::numeric_limits<double>::max();
    for (const auto& o : point.observations)
      depth = std::min(depth, (point.position - world_from_rig[o.keyframe].translation).norm());
    radius[p] = kSearchRadiusInMergeAngles * merge_angle * depth;
    live.push_back(static_cast<int>(p));
  }
  if (live.size() < 2) return 0;
  std::vector<double> radii;
  for (int p : live) radii.push_back(radius[p]);
  std::nth_element(radii.begin(), radii.begin() + radii.size() / 2, radii.end());
  const double cell = std::max(radii[radii.size() / 2], 1e-9);
  const auto key = [cell](const Eigen::Vector3d& x, int dx, int dy, int dz) {
    const int64_t i = static_cast<int64_t>(std::floor(x.x() / cell)) + dx;
    const int64_t j = static_cast<int64_t>(std::floor(x.y() / cell)) + dy;
    const int64_t k = static_cast<int64_t>(std::floor(x.z() / cell)) + dz;
    return (i * 73856093) ^ (j * 19349663) ^ (k * 83492791);
  };
  std::unordered_map<int64_t, std::vector<int>> grid;
  for (int p : live) grid[key((*points)[p].position, 0, 0, 0)].push_back(p);

  std::vector<int> merged_into(points->size(), -1);
  int merged = 0;
  for (int a : live) {
    PointT& kept = (*points)[a];
    if (!kept.alive) continue;
    const int reach = std::min(3, static_cast<int>(std::ceil(radius[a] / cell)));
    for (int dx = -reach; dx <= reach; ++dx)
      for (int dy = -reach; dy <= reach; ++dy)
        for (int dz = -reach; dz <= reach; ++dz) {
          const auto it = grid.find(key(kept.position, dx, dy, dz));
          if (it == grid.end()) continue;
          for (int b : it->second) {
            if (b == a || !(*points)[b].alive) continue;
            PointT& other = (*points)[b];
            if ((other.position - kept.position).norm() > std::min(radius[a], radius[b])) continue;
            bool shared = false;
            for (const auto& o : other.observations)
              for (const auto& k : kept.observations)
                shared = shared || (o.keyframe == k.keyframe && o.camera == k.camera);
            if (shared) continue;
            const double wa = static_cast<double>(kept.observations.size());
            const double wb = static_cast<double>(other.observations.size());
            const Eigen::Vector3d position = (wa * kept.position + wb * other.position) / (wa + wb);
            bool fits = true;
            for (const auto* observations : {&kept.observations, &other.observations})
              for (const auto& o : *observations)
                fits = fits && ObservationAngle(rig, mode, world_from_rig[o.keyframe], position,
                                                o.camera, o.bearing) < merge_angle;
            if (!fits) continue;
            kept.position = position;
            kept.observations.insert(kept.observations.end(), other.observations.begin(),
                                     other.observations.end());
            kept.frame_observations.insert(kept.frame_observations.end(),
                                           other.frame_observations.begin(),
                                           other.frame_observations.end());
            other.alive = false;
            merged_into[b] = a;
            ++merged;
          }
        }
  }
  if (merged == 0) return 0;
  track_to_point->ForEach([&](int, int& point) {
    int target = point;
    while (target >= 0 && merged_into[target] >= 0) target = merged_into[target];
    point = target;
  });
  return merged;
}

BundleAdjustmentSummary Tracker::GlobalBundleAdjust(bool true_offsets, double merge_angle,
                                                    int* points_merged, int first_free_keyframe,
                                                    double function_tolerance,
                                                    std::vector<AdjustedFrame>* frames,
                                                    int min_frame_observations) {
  if (!(function_tolerance >= 0.0 && function_tolerance < 1.0)) {
    throw std::invalid_argument(
        "Tracker::GlobalBundleAdjust: function_tolerance: expected 0 or a value in (0, 1)");
  }
  Impl& m = *impl_;
  BundleAdjustmentOptions options = m.options.bundle_adjustment;
  options.mode = m.options.central ? BundleAdjustmentOptions::Mode::kCentral
                                   : BundleAdjustmentOptions::Mode::kNonCentral;
  if (m.options.central && true_offsets) {
    options.mode = BundleAdjustmentOptions::Mode::kNonCentral;
    options.estimate_offset_scale = true;
  }
  int merged = 0;
  if (merge_angle > 0.0) {
    std::vector<Rigid3d> world_from_rig;
    for (const Impl::Keyframe& keyframe : m.keyframes)
      world_from_rig.push_back(keyframe.world_from_rig);
    // The offsets' scale is not known before the adjustment: the fit is judged centrally then.
    const BundleAdjustmentOptions::Mode merge_mode =
        m.options.central ? BundleAdjustmentOptions::Mode::kCentral : options.mode;
    merged = MergeNearbyPoints(m.rig, merge_mode, world_from_rig, merge_angle, &m.points,
                               &m.track_to_point);
  }
  if (points_merged) *points_merged = merged;
  BundleAdjustmentProblem problem;
  const int first_free = std::max(first_free_keyframe, m.GaugeKeyframes());
  for (size_t k = 0; k < m.keyframes.size(); ++k)
    problem.keyframes.push_back({m.keyframes[k].world_from_rig, static_cast<int>(k) < first_free});
  std::vector<int> point_of;
  for (size_t p = 0; p < m.points.size(); ++p) {
    const Impl::Point& point = m.points[p];
    if (!point.alive) continue;
    // A tail adjustment leaves out the points that only fixed keyframes observe.
    if (first_free_keyframe > 0 &&
        std::none_of(point.observations.begin(), point.observations.end(),
                     [&](const Impl::PointObservation& o) { return o.keyframe >= first_free; }))
      continue;
    const int index = static_cast<int>(problem.points_in_world.size());
    problem.points_in_world.push_back(point.position);
    point_of.push_back(static_cast<int>(p));
    for (const Impl::PointObservation& o : point.observations)
      problem.observations.push_back({o.keyframe, o.camera, index, o.bearing});
  }
  // The frames: free poses after the keyframes, with their kept observations of the points
  // adjusted.
  const size_t num_keyframes = m.keyframes.size();
  std::vector<int> frame_pose_index;  // per frame: its pose in the problem, -1: left out
  if (frames != nullptr) {
    std::vector<int> problem_point(m.points.size(), -1);
    for (size_t i = 0; i < point_of.size(); ++i) problem_point[point_of[i]] = static_cast<int>(i);
    std::vector<BundleAdjustmentObservation> seen;
    for (AdjustedFrame& frame : *frames) {
      frame.adjusted = false;
      frame_pose_index.push_back(-1);
      const auto kept = m.kept_observations.find(frame.frame);
      if (kept == m.kept_observations.end()) continue;
      const int pose = static_cast<int>(problem.keyframes.size());
      seen.clear();
      for (const Impl::KeptObservation& o : kept->second) {
        const int p = m.track_to_point.Find(o.track);
        if (p < 0 || !m.points[p].alive || problem_point[p] < 0) continue;
        seen.push_back({pose, o.camera, problem_point[p], o.bearing.cast<double>()});
      }
      if (static_cast<int>(seen.size()) < min_frame_observations) continue;
      problem.keyframes.push_back({frame.world_from_rig, false});
      problem.observations.insert(problem.observations.end(), seen.begin(), seen.end());
      frame_pose_index.back() = pose;
    }
  }
  options.linear_solver = BundleAdjustmentOptions::LinearSolver::kSparseSchur;
  options.num_threads = m.options.global_bundle_adjustment_threads;
  options.function_tolerance = function_tolerance > 0.0
                                   ? function_tolerance
                                   : m.options.global_bundle_adjustment_function_tolerance;
  if (problem.observations.empty()) return {};
  const BundleAdjustmentSummary summary = LocalBundleAdjust(m.rig, options, &problem);
  if (!summary.success) return summary;
  // The last tracked frames follow the newest keyframe (see ApplyCorrection).
  const Rigid3d world_new_from_old = problem.keyframes[num_keyframes - 1].world_from_rig *
                                     m.keyframes.back().world_from_rig.Inverse();
  for (size_t i = 0; i < frame_pose_index.size(); ++i) {
    if (frame_pose_index[i] < 0) continue;
    (*frames)[i].world_from_rig = problem.keyframes[frame_pose_index[i]].world_from_rig;
    (*frames)[i].adjusted = true;
  }
  for (Impl::TrackedPose& tracked : m.last_tracked)
    tracked.world_from_rig = world_new_from_old * tracked.world_from_rig;
  for (size_t k = 0; k < m.keyframes.size(); ++k)
    m.keyframes[k].world_from_rig = problem.keyframes[k].world_from_rig;
  for (size_t i = 0; i < point_of.size(); ++i)
    m.points[point_of[i]].position = problem.points_in_world[i];
  m.keyframes_at_global_adjustment = static_cast<int>(m.keyframes.size());
  return summary;
}

int Tracker::KeyframesAtLastGlobalAdjustment() const {
  return impl_->keyframes_at_global_adjustment;
}

std::vector<FinalizedKeyframe> Tracker::FinalizedSnapshot(bool all_rays) const {
  const Impl& m = *impl_;
  std::vector<FinalizedKeyframe> result;
  std::vector<std::vector<int>> created(m.keyframes.size());
  for (size_t p = 0; p < m.points.size(); ++p)
    if (m.points[p].alive && m.points[p].handed_over_by >= 0)
      created[m.points[p].handed_over_by].push_back(static_cast<int>(p));
  for (size_t k = 0; k < m.keyframes.size(); ++k)
    if (m.keyframes[k].finalized)
      result.push_back(m.MakeFinalized(static_cast<int>(k), created[k], all_rays));
  return result;
}

TrackStats ComputeTrackStats(const std::vector<FinalizedKeyframe>& keyframes, double min_aperture) {
  TrackStats stats;
  std::vector<int> lengths;
  size_t rays = 0, frame_rays = 0;
  int multi_camera = 0, aperture_ok = 0;
  const double max_cos = std::cos(min_aperture);
  for (const FinalizedKeyframe& keyframe : keyframes)
    for (const FinalizedPoint& point : keyframe.points) {
      if (point.frame_point) {
        ++stats.frame_points;
        continue;
      }
      std::vector<int> seen_keyframes;
      std::vector<Eigen::Vector3d> directions;
      bool two_cameras = false;
      for (const FinalizedRay& ray : point.rays) {
        seen_keyframes.push_back(ray.keyframe);
        directions.push_back((ray.center - point.position).normalized());
        two_cameras = two_cameras || ray.camera != point.rays.front().camera;
      }
      std::sort(seen_keyframes.begin(), seen_keyframes.end());
      lengths.push_back(static_cast<int>(std::unique(seen_keyframes.begin(), seen_keyframes.end()) -
                                         seen_keyframes.begin()));
      rays += point.rays.size();
      frame_rays += point.frame_rays.size();
      multi_camera += two_cameras ? 1 : 0;
      bool wide = false;
      for (size_t i = 0; i < directions.size() && !wide; ++i)
        for (size_t j = i + 1; j < directions.size() && !wide; ++j)
          wide = directions[i].dot(directions[j]) < max_cos;
      aperture_ok += wide ? 1 : 0;
    }
  stats.points = static_cast<int>(lengths.size());
  if (lengths.empty()) return stats;
  const double n = static_cast<double>(lengths.size());
  double sum = 0.0;
  for (int length : lengths) sum += length;
  stats.mean_keyframes = sum / n;
  std::sort(lengths.begin(), lengths.end());
  const size_t half = lengths.size() / 2;
  stats.median_keyframes =
      lengths.size() % 2 ? lengths[half] : 0.5 * (lengths[half - 1] + lengths[half]);
  stats.mean_rays = static_cast<double>(rays) / n;
  stats.mean_frame_rays = static_cast<double>(frame_rays) / n;
  stats.multi_camera_share = multi_camera / n;
  stats.aperture_ok_share = aperture_ok / n;
  return stats;
}

}  // namespace omni
