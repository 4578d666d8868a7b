#include "sfm/tracker.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <unordered_map>

#include "sfm/absolute_pose_central.h"
#include "sfm/absolute_pose_noncentral.h"
#include "sfm/relative_pose_central.h"
#include "sfm/relative_pose_noncentral.h"

namespace omni {

std::string TrackerOptions::Check() const {
  for (const auto& [name, check] :
       {std::pair<const char*, std::string>{"relative_ransac", relative_ransac.Check()},
        {"resection_ransac", resection_ransac.Check()},
        {"triangulation", triangulation.Check()},
        {"keyframes", keyframes.Check()},
        {"bundle_adjustment", bundle_adjustment.Check()}})
    if (!check.empty()) return std::string(name) + "." + check;
  if (num_free_keyframes < 1) return "num_free_keyframes: expected at least 1";
  if (num_fixed_keyframes < 1) return "num_fixed_keyframes: expected at least 1";
  if (min_init_points < 5) return "min_init_points: expected at least 5";
  if (min_resection_inliers < 4) return "min_resection_inliers: expected at least 4";
  if (!(max_jump_ratio > 1.0)) return "max_jump_ratio: expected more than 1";
  return {};
}

struct Tracker::Impl {
  struct PointObservation {
    int keyframe;
    int camera;
    Eigen::Vector3d bearing;
  };
  struct Point {
    Eigen::Vector3d position;
    std::vector<PointObservation> observations;
    int created_by = -1;
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
  std::vector<Point> points;
  std::unordered_map<int, int> track_to_point;
  std::vector<FinalizedKeyframe> finalized;
  // Motion model: the last two tracked frames (frame index, world_from_rig), and the distance
  // travelled over the tracked steps so far.
  struct TrackedPose {
    int frame;
    Rigid3d world_from_rig;
  };
  std::vector<TrackedPose> last_tracked;  // at most two, oldest first
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
  // Constant velocity: the motion between the last two tracked frames (when consecutive)
  // applied once per frame from the last tracked one to `frame`; without a velocity, the last
  // tracked pose and false.
  bool Predict(int frame, Rigid3d* world_from_rig) const {
    if (last_tracked.empty()) return false;
    const TrackedPose& last = last_tracked.back();
    *world_from_rig = last.world_from_rig;
    if (last_tracked.size() < 2 || last_tracked[0].frame != last.frame - 1) return false;
    const Rigid3d step = last_tracked[0].world_from_rig.Inverse() * last.world_from_rig;
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
    track_to_point[track] = static_cast<int>(points.size()) - 1;
    return static_cast<int>(points.size()) - 1;
  }

  FrameResult Initialise(const std::vector<TrackObservation>& observations);
  FrameResult Track(const std::vector<TrackObservation>& observations);
  void TriangulateNewPoints(int keyframe);
  void LocalBundleAdjustment();
  void FinalizeUpTo(int end);
  // The "keyframe finalised" event of keyframe k: its pose and the points it created.
  FinalizedKeyframe MakeFinalized(int k, const std::vector<int>& created_points) const;
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
    if (ransac.success) candidates.push_back({rig0_from_rig1, {}});
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
    if (!best || candidate.points.size() > best->points.size()) best = &candidate;
  }
  if (!best || static_cast<int>(best->points.size()) < options.min_init_points) return result;
  const Rigid3d world_from_rig1 = best->world_from_rig1;
  const std::vector<std::pair<int, Eigen::Vector3d>>& new_points = best->points;

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
  LocalBundleAdjustment();
  result.tracked = true;
  result.keyframe = true;
  result.world_from_rig = keyframes.back().world_from_rig;
  result.inliers = static_cast<int>(new_points.size());
  result.status = "initialised";
  return result;
}

FrameResult Tracker::Impl::Track(const std::vector<TrackObservation>& observations) {
  FrameResult result;
  const auto resect_start = std::chrono::steady_clock::now();
  std::vector<Eigen::Vector3d> bearings, positions;
  std::vector<int> cameras, observation_index;
  for (size_t j = 0; j < observations.size(); ++j) {
    const auto it = track_to_point.find(observations[j].track);
    if (it == track_to_point.end() || !points[it->second].alive) continue;
    bearings.push_back(options.central ? RigBearing(observations[j]) : observations[j].bearing);
    cameras.push_back(observations[j].camera);
    positions.push_back(points[it->second].position);
    observation_index.push_back(static_cast<int>(j));
  }
  Rigid3d world_from_rig;
  RansacResult ransac;
  if (options.central) {
    CentralAbsolutePoseOptions absolute;
    absolute.ransac = options.resection_ransac;
    Rigid3d world_from_central;
    ransac = EstimateCentralAbsolutePose(bearings, positions, absolute, &world_from_central);
    world_from_rig = RigFromCentral(world_from_central);
  } else {
    NoncentralAbsolutePoseOptions absolute;
    absolute.ransac = options.resection_ransac;
    ransac = EstimateNoncentralAbsolutePose(rig, bearings, cameras, positions, absolute,
                                            &world_from_rig);
  }
  AddSeconds(resect_start, &timings.resect);
  if (!ransac.success || ransac.num_inliers < options.min_resection_inliers) {
    result.status = "resection failed: " + std::to_string(ransac.num_inliers) + " inliers of " +
                    std::to_string(bearings.size());
    return result;
  }
  // A pose far from the motion model is a wrong resection (wrong matches that agree), not a
  // jump of the rig: rejected rather than put in the map.
  Rigid3d predicted;
  if (!last_tracked.empty()) {
    Predict(num_frames - 1, &predicted);
    const double last_step = last_tracked.size() == 2
                                 ? (last_tracked[1].world_from_rig.translation -
                                    last_tracked[0].world_from_rig.translation)
                                       .norm()
                                 : 0.0;
    const double mean_step = travelled_steps > 0 ? travelled / travelled_steps : 0.0;
    const int frames_since = num_frames - 1 - last_tracked.back().frame;
    const double allowed =
        options.max_jump_ratio * std::max(last_step, mean_step) * std::max(1, frames_since);
    const double jump = (world_from_rig.translation - predicted.translation).norm();
    if (mean_step > 0.0 && jump > allowed) {
      result.status = "rejected: resected pose " + std::to_string(jump / mean_step) +
                      " mean steps from the prediction";
      return result;
    }
  }
  result.tracked = true;
  result.world_from_rig = world_from_rig;
  result.inliers = ransac.num_inliers;

  // Keyframe decision against the last keyframe.
  const int last = static_cast<int>(keyframes.size()) - 1;
  KeyframeCandidate candidate;
  candidate.last_keyframe_world_from_rig = keyframes[last].world_from_rig;
  candidate.world_from_rig = world_from_rig;
  std::vector<double> depths;
  std::vector<char> tracked_now(points.size(), 0);
  for (size_t k = 0; k < bearings.size(); ++k) {
    if (!ransac.inlier_mask[k]) continue;
    tracked_now[track_to_point[observations[observation_index[k]].track]] = 1;
    depths.push_back((positions[k] - world_from_rig.translation).norm());
  }
  for (const TrackObservation& observation : keyframes[last].observations) {
    const auto it = track_to_point.find(observation.track);
    if (it == track_to_point.end() || !points[it->second].alive) continue;
    ++candidate.last_keyframe_points;
    candidate.tracked_points += tracked_now[it->second];
  }
  if (!depths.empty()) {
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    candidate.median_depth = depths[depths.size() / 2];
  }
  const KeyframeDecisionReason decision = DecideKeyframe(candidate, options.keyframes);
  result.status = decision.reason;
  if (decision.decision != KeyframeDecision::kKeyframe) return result;

  Keyframe keyframe;
  keyframe.frame = num_frames - 1;
  keyframe.world_from_rig = world_from_rig;
  keyframe.observations = observations;
  keyframes.push_back(std::move(keyframe));
  const int index = static_cast<int>(keyframes.size()) - 1;
  for (size_t k = 0; k < bearings.size(); ++k) {
    if (!ransac.inlier_mask[k]) continue;
    const TrackObservation& observation = observations[observation_index[k]];
    points[track_to_point[observation.track]].observations.push_back(
        {index, observation.camera, observation.bearing});
  }
  TriangulateNewPoints(index);
  LocalBundleAdjustment();
  result.keyframe = true;
  result.world_from_rig = keyframes.back().world_from_rig;
  return result;
}

void Tracker::Impl::TriangulateNewPoints(int keyframe) {
  const auto start = std::chrono::steady_clock::now();
  const int window_begin =
      std::max(0, keyframe - options.num_free_keyframes - options.num_fixed_keyframes);
  for (const TrackObservation& observation : keyframes[keyframe].observations) {
    if (track_to_point.count(observation.track)) continue;
    std::vector<PointObservation> track_observations = {
        {keyframe, observation.camera, observation.bearing}};
    for (int k = keyframe - 1; k >= window_begin; --k)
      for (const TrackObservation& older : keyframes[k].observations)
        if (older.track == observation.track) {
          track_observations.push_back({k, older.camera, older.bearing});
          break;
        }
    if (track_observations.size() < 2) continue;
    std::vector<WorldRay> rays;
    for (const PointObservation& o : track_observations)
      rays.push_back(Ray(keyframes[o.keyframe].world_from_rig, o.camera, o.bearing));
    Eigen::Vector3d position;
    if (TriangulatePoint(rays, options.triangulation, &position) == TriangulationStatus::kOk)
      AddPoint(observation.track, position, keyframe, std::move(track_observations));
  }
  AddSeconds(start, &timings.triangulate);
}

void Tracker::Impl::LocalBundleAdjustment() {
  const int num_keyframes = static_cast<int>(keyframes.size());
  // The first two keyframes stay fixed: they fix the gauge (and the scale in central mode).
  const int free_begin = std::max(2, num_keyframes - options.num_free_keyframes);
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
    // The points of a finalised keyframe were handed over: they never move again.
    problem.point_fixed.push_back(keyframes[point.created_by].finalized ? 1 : 0);
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
  const BundleAdjustmentSummary summary = LocalBundleAdjust(rig, ba_options, &problem);
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
      track_to_point.erase(points[p].track);
    }
  }
  FinalizeUpTo(num_keyframes - options.num_free_keyframes);
}

FinalizedKeyframe Tracker::Impl::MakeFinalized(int k,
                                               const std::vector<int>& created_points) const {
  const Keyframe& keyframe = keyframes[k];
  FinalizedKeyframe event;
  event.keyframe = k;
  event.frame = keyframe.frame;
  event.world_from_rig = keyframe.world_from_rig;
  event.center = keyframe.world_from_rig * central_center;
  for (int p : created_points) {
    FinalizedPoint finalized_point;
    finalized_point.point = p;
    finalized_point.position = points[p].position;
    for (const PointObservation& o : points[p].observations)
      finalized_point.rays.push_back({o.keyframe,
                                      keyframes[o.keyframe].world_from_rig * CenterInRig(o.camera),
                                      o.camera, o.bearing});
    event.points.push_back(std::move(finalized_point));
  }
  return event;
}

void Tracker::Impl::FinalizeUpTo(int end) {
  for (int k = 0; k < end; ++k) {
    Keyframe& keyframe = keyframes[k];
    if (keyframe.finalized) continue;
    keyframe.finalized = true;
    std::vector<int> created;
    for (size_t p = 0; p < points.size(); ++p)
      if (points[p].alive && points[p].created_by == k) created.push_back(static_cast<int>(p));
    finalized.push_back(MakeFinalized(k, created));
  }
}

Tracker::Tracker(const Rig& rig, const TrackerOptions& options) : impl_(new Impl) {
  assert(options.Check().empty());
  assert(!rig.cameras.empty());
  impl_->rig = rig;
  impl_->options = options;
  for (const Camera& camera : rig.cameras) impl_->central_center += camera.cam_from_rig.Center();
  impl_->central_center /= static_cast<double>(rig.cameras.size());
}

Tracker::~Tracker() = default;

FrameResult Tracker::AddFrame(const std::vector<TrackObservation>& observations) {
  ++impl_->num_frames;
  if (impl_->keyframes.empty()) {
    Impl::Keyframe keyframe;
    keyframe.frame = impl_->num_frames - 1;
    keyframe.observations = observations;
    impl_->keyframes.push_back(std::move(keyframe));
    FrameResult result;
    result.tracked = true;
    result.keyframe = true;
    result.status = "first keyframe";
    impl_->RecordTracked(0, result.world_from_rig);
    return result;
  }
  const FrameResult result =
      impl_->keyframes.size() == 1 ? impl_->Initialise(observations) : impl_->Track(observations);
  if (result.tracked) impl_->RecordTracked(impl_->num_frames - 1, result.world_from_rig);
  return result;
}

bool Tracker::PredictPose(Rigid3d* world_from_rig) const {
  if (impl_->keyframes.size() < 2) return false;
  return impl_->Predict(impl_->num_frames, world_from_rig) &&
         impl_->last_tracked.back().frame == impl_->num_frames - 1;
}

bool Tracker::TrackPosition(int track, Eigen::Vector3d* position) const {
  const auto it = impl_->track_to_point.find(track);
  if (it == impl_->track_to_point.end() || !impl_->points[it->second].alive) return false;
  *position = impl_->points[it->second].position;
  return true;
}

Tracker::Timings Tracker::StageTimings() const { return impl_->timings; }

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

// ---- Map access and correction (loop closure, issue 9) ----

std::vector<std::pair<int, Eigen::Vector3d>> Tracker::KeyframeTrackPoints(int keyframe) const {
  std::vector<std::pair<int, Eigen::Vector3d>> result;
  for (const TrackObservation& observation : impl_->keyframes.at(keyframe).observations) {
    const auto it = impl_->track_to_point.find(observation.track);
    if (it == impl_->track_to_point.end() || !impl_->points[it->second].alive) continue;
    result.emplace_back(observation.track, impl_->points[it->second].position);
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
}

void Tracker::MergeTracks(const std::vector<std::pair<int, int>>& drop_keep) {
  Impl& m = *impl_;
  for (const auto& [drop, keep] : drop_keep) {
    const auto d = m.track_to_point.find(drop), k = m.track_to_point.find(keep);
    if (d == m.track_to_point.end() || k == m.track_to_point.end() || d->second == k->second)
      continue;
    Impl::Point& from = m.points[d->second];
    Impl::Point& to = m.points[k->second];
    if (!from.alive || !to.alive) continue;
    for (const Impl::PointObservation& o : from.observations) {
      const bool seen =
          std::any_of(to.observations.begin(), to.observations.end(),
                      [&](const Impl::PointObservation& t) { return t.keyframe == o.keyframe; });
      if (!seen) to.observations.push_back(o);
    }
    from.alive = false;
    d->second = k->second;
  }
}

BundleAdjustmentSummary Tracker::GlobalBundleAdjust() {
  Impl& m = *impl_;
  BundleAdjustmentProblem problem;
  for (size_t k = 0; k < m.keyframes.size(); ++k)
    problem.keyframes.push_back({m.keyframes[k].world_from_rig, k < 2});
  std::vector<int> point_of;
  for (size_t p = 0; p < m.points.size(); ++p) {
    const Impl::Point& point = m.points[p];
    if (!point.alive) continue;
    const int index = static_cast<int>(problem.points_in_world.size());
    problem.points_in_world.push_back(point.position);
    point_of.push_back(static_cast<int>(p));
    for (const Impl::PointObservation& o : point.observations)
      problem.observations.push_back({o.keyframe, o.camera, index, o.bearing});
  }
  BundleAdjustmentOptions options = m.options.bundle_adjustment;
  options.mode = m.options.central ? BundleAdjustmentOptions::Mode::kCentral
                                   : BundleAdjustmentOptions::Mode::kNonCentral;
  options.linear_solver = BundleAdjustmentOptions::LinearSolver::kSparseSchur;
  if (problem.observations.empty()) return {};
  const BundleAdjustmentSummary summary = LocalBundleAdjust(m.rig, options, &problem);
  if (!summary.success) return summary;
  for (size_t k = 0; k < m.keyframes.size(); ++k)
    m.keyframes[k].world_from_rig = problem.keyframes[k].world_from_rig;
  for (size_t i = 0; i < point_of.size(); ++i)
    m.points[point_of[i]].position = problem.points_in_world[i];
  return summary;
}

std::vector<FinalizedKeyframe> Tracker::FinalizedSnapshot() const {
  const Impl& m = *impl_;
  std::vector<FinalizedKeyframe> result;
  std::vector<std::vector<int>> created(m.keyframes.size());
  for (size_t p = 0; p < m.points.size(); ++p)
    if (m.points[p].alive && m.points[p].created_by >= 0)
      created[m.points[p].created_by].push_back(static_cast<int>(p));
  for (size_t k = 0; k < m.keyframes.size(); ++k)
    if (m.keyframes[k].finalized)
      result.push_back(m.MakeFinalized(static_cast<int>(k), created[k]));
  return result;
}

}  // namespace omni
