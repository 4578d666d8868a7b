#include "sfm/tracker.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <memory>
#include <random>
#include <set>

#include "sfm/synthetic.h"
#include "tests/calib/options_error_check.h"

namespace omni {
namespace {

// A drive of num_frames frames, 0.15 m apart along a gentle curve, with points seeded every
// few frames so that the street keeps having points 3–15 m away; tracks are the point ids.
struct SyntheticDrive {
  Rig rig;
  std::vector<Rigid3d> world_from_rig;
  std::vector<std::vector<TrackObservation>> frames;
  double length = 0.0;
  std::vector<Eigen::Vector3d> points;  // the true points, by track id
};

SyntheticDrive MakeDrive(double rig_radius, int num_frames, double noise, double outliers) {
  SyntheticDrive drive;
  drive.rig = MakeSyntheticRingRig(5, true, rig_radius);
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  double heading = 0.0;
  for (int i = 0; i < num_frames; ++i) {
    if (i > 0) {
      heading += 0.01;
      const Eigen::Vector3d step(0.15 * std::cos(heading), 0.15 * std::sin(heading), 0.0);
      position += step;
      drive.length += step.norm();
    }
    drive.world_from_rig.emplace_back(
        Eigen::Quaterniond(Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ())), position);
  }
  drive.frames.resize(num_frames);
  int num_points = 0;
  for (int seed_frame = 0; seed_frame < num_frames; seed_frame += 10) {
    // Rotate the trajectory so the generator seeds its points from seed_frame.
    std::vector<Rigid3d> shifted(drive.world_from_rig.begin() + seed_frame,
                                 drive.world_from_rig.end());
    shifted.insert(shifted.end(), drive.world_from_rig.begin(),
                   drive.world_from_rig.begin() + seed_frame);
    SyntheticSceneOptions options;
    options.num_points = 150;
    options.min_depth = 3.0;
    options.max_depth = 15.0;
    options.half_fov = 0.7;
    options.noise = noise;
    options.outlier_ratio = outliers;
    options.seed = 100 + seed_frame;
    const SyntheticScene scene = MakeSyntheticScene(drive.rig, shifted, options);
    drive.points.insert(drive.points.end(), scene.points_in_world.begin(),
                        scene.points_in_world.end());
    for (const SyntheticObservation& observation : scene.observations) {
      const int frame = (observation.frame + seed_frame) % num_frames;
      drive.frames[frame].push_back(
          {num_points + observation.point, observation.camera, observation.bearing});
    }
    num_points += options.num_points;
  }
  return drive;
}

// RMS distance of the tracker's keyframe centres to the drive's true centres after a similarity
// registration (metres).
double KeyframeRmsAfterSimilarity(const Tracker& tracker, const SyntheticDrive& drive) {
  const std::vector<Rigid3d> poses = tracker.KeyframePoses();
  const std::vector<int> frames = tracker.KeyframeFrames();
  std::vector<Eigen::Vector3d> estimated, truth;
  for (size_t k = 0; k < poses.size(); ++k) {
    estimated.push_back(poses[k].translation);
    truth.push_back(drive.world_from_rig[frames[k]].translation);
  }
  return AlignmentRms(EstimateSim3Umeyama(estimated, truth, true), estimated, truth);
}

struct Case {
  bool central;
  double rig_radius;
};

class TrackerTest : public ::testing::TestWithParam<Case> {};

TEST_P(TrackerTest, TracksSyntheticDriveWithSmallTrajectoryError) {
  const SyntheticDrive drive = MakeDrive(GetParam().rig_radius, 60, 0.0003, 0.03);
  TrackerOptions options;
  options.central = GetParam().central;
  Tracker tracker(drive.rig, options);
  int untracked = 0, first_tracked_after_init = -1;
  std::vector<FinalizedKeyframe> finalized;
  for (size_t f = 0; f < drive.frames.size(); ++f) {
    const FrameResult result = tracker.AddFrame(drive.frames[f]);
    if (tracker.NumKeyframes() >= 2 && first_tracked_after_init < 0)
      first_tracked_after_init = static_cast<int>(f);
    if (first_tracked_after_init >= 0 && !result.tracked) {
      ++untracked;
      ADD_FAILURE() << "frame " << f << " not tracked: " << result.status;
    }
    for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
      finalized.push_back(std::move(keyframe));
  }
  tracker.Finish();
  for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
    finalized.push_back(std::move(keyframe));

  // Initialised within the first 15 frames (2.25 m), then every frame tracked.
  ASSERT_GE(first_tracked_after_init, 1);
  EXPECT_LE(first_tracked_after_init, 15);
  EXPECT_EQ(untracked, 0);
  ASSERT_GE(tracker.NumKeyframes(), 4);
  EXPECT_GT(tracker.NumPoints(), 200);
  // Every keyframe is finalised exactly once, in order.
  ASSERT_EQ(static_cast<int>(finalized.size()), tracker.NumKeyframes());
  for (size_t k = 0; k < finalized.size(); ++k)
    EXPECT_EQ(finalized[k].keyframe, static_cast<int>(k));

  // Keyframe centres against the truth after a similarity registration: below 1 % of the
  // distance driven.
  const double rms = KeyframeRmsAfterSimilarity(tracker, drive);
  EXPECT_LT(rms, 0.01 * drive.length) << "rms " << rms << " m over " << drive.length << " m";
  RecordProperty("keyframes", tracker.NumKeyframes());
  RecordProperty("points", tracker.NumPoints());
  RecordProperty("init_frame", first_tracked_after_init);
  RecordProperty("rms_over_length_ppm", static_cast<int>(1e6 * rms / drive.length));
}

INSTANTIATE_TEST_SUITE_P(Modes, TrackerTest,
                         ::testing::Values(Case{true, 0.0}, Case{true, 0.05}, Case{false, 0.3}));

// Every point handed over, on the drive above, run with the given frame-ray step.
struct HandedOver {
  std::vector<FinalizedKeyframe> keyframes;
  std::vector<Rigid3d> keyframe_poses;
  std::vector<int> keyframe_frames;
};
HandedOver RunForFrameRays(const SyntheticDrive& drive, bool central, int frame_ray_step,
                           double frame_ray_min_angle = 0.0, bool frame_points = false) {
  TrackerOptions options;
  options.central = central;
  options.frame_ray_step = frame_ray_step;
  options.frame_ray_min_angle = frame_ray_min_angle;
  options.frame_points = frame_points;
  Tracker tracker(drive.rig, options);
  HandedOver run;
  for (const std::vector<TrackObservation>& frame : drive.frames) {
    tracker.AddFrame(frame);
    for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
      run.keyframes.push_back(std::move(keyframe));
  }
  tracker.Finish();
  for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
    run.keyframes.push_back(std::move(keyframe));
  run.keyframe_poses = tracker.KeyframePoses();
  run.keyframe_frames = tracker.KeyframeFrames();
  return run;
}

class TrackerFrameRaysTest : public ::testing::TestWithParam<Case> {};

// The rays of the tracked frames between keyframes: each from a frame after its keyframe and
// before the next one, no later than the keyframe that hands the point over, from that frame's
// true optical centre (after the similarity registration of the keyframes), in a camera that
// sees the point; every second frame gives about half of them; recording them changes nothing
// else (the same keyframe poses and keyframe rays).
TEST_P(TrackerFrameRaysTest, PointsCarryTheRaysOfTheFramesBetweenKeyframes) {
  const Case mode = GetParam();
  const SyntheticDrive drive = MakeDrive(mode.rig_radius, 60, 0.0003, 0.03);
  const HandedOver every = RunForFrameRays(drive, mode.central, 1);
  const HandedOver second = RunForFrameRays(drive, mode.central, 2);
  const HandedOver none = RunForFrameRays(drive, mode.central, 0);

  ASSERT_EQ(every.keyframe_poses.size(), none.keyframe_poses.size());
  for (size_t k = 0; k < every.keyframe_poses.size(); ++k)
    EXPECT_LT((every.keyframe_poses[k].translation - none.keyframe_poses[k].translation).norm(),
              1e-9);
  ASSERT_EQ(every.keyframes.size(), none.keyframes.size());
  size_t frame_rays_every = 0, frame_rays_second = 0, frame_rays_none = 0, points = 0;
  for (size_t k = 0; k < none.keyframes.size(); ++k) {
    ASSERT_EQ(every.keyframes[k].points.size(), none.keyframes[k].points.size());
    for (size_t p = 0; p < none.keyframes[k].points.size(); ++p)
      EXPECT_EQ(every.keyframes[k].points[p].rays.size(), none.keyframes[k].points[p].rays.size());
    for (const FinalizedPoint& point : none.keyframes[k].points)
      frame_rays_none += point.frame_rays.size();
  }
  for (const FinalizedKeyframe& keyframe : second.keyframes)
    for (const FinalizedPoint& point : keyframe.points)
      frame_rays_second += point.frame_rays.size();

  std::vector<Eigen::Vector3d> estimated, truth;
  for (size_t k = 0; k < every.keyframe_poses.size(); ++k) {
    estimated.push_back(every.keyframe_poses[k].translation);
    truth.push_back(drive.world_from_rig[every.keyframe_frames[k]].translation);
  }
  const Sim3d truth_from_estimated = EstimateSim3Umeyama(estimated, truth, true);
  const std::set<int> keyframe_frames(every.keyframe_frames.begin(), every.keyframe_frames.end());
  Eigen::Vector3d rig_center = Eigen::Vector3d::Zero();
  for (const Camera& camera : drive.rig.cameras) rig_center += camera.cam_from_rig.Center();
  rig_center /= static_cast<double>(drive.rig.NumCameras());
  double max_center_error = 0.0;
  int outside_view = 0;
  for (const FinalizedKeyframe& keyframe : every.keyframes)
    for (const FinalizedPoint& point : keyframe.points) {
      ++points;
      for (const FinalizedFrameRay& ray : point.frame_rays) {
        ++frame_rays_every;
        ASSERT_GE(ray.keyframe, 0);
        ASSERT_LT(ray.keyframe, static_cast<int>(every.keyframe_frames.size()));
        EXPECT_LE(ray.keyframe, keyframe.keyframe);
        EXPECT_EQ(keyframe_frames.count(ray.frame), 0u) << "frame " << ray.frame;
        EXPECT_GT(ray.frame, every.keyframe_frames[ray.keyframe]);
        if (ray.keyframe + 1 < static_cast<int>(every.keyframe_frames.size())) {
          EXPECT_LT(ray.frame, every.keyframe_frames[ray.keyframe + 1]);
        }
        const Rigid3d& world_from_rig = drive.world_from_rig[ray.frame];
        const Eigen::Vector3d true_center =
            world_from_rig *
            (mode.central ? rig_center : drive.rig.cameras[ray.camera].cam_from_rig.Center());
        max_center_error =
            std::max(max_center_error, (truth_from_estimated * ray.center - true_center).norm());
        // The point is in that camera's view (the synthetic cameras' half field is 0.7 rad).
        const Rigid3d cam_from_world =
            drive.rig.cameras[ray.camera].cam_from_rig * world_from_rig.Inverse();
        const Eigen::Vector3d in_camera = cam_from_world * (truth_from_estimated * point.position);
        outside_view += std::acos(in_camera.normalized().z()) > 0.8;
      }
    }
  EXPECT_EQ(frame_rays_none, 0u);
  // Keyframes are a few frames apart here: most points are seen by some frames between them.
  EXPECT_GT(static_cast<double>(frame_rays_every), 1.0 * static_cast<double>(points));
  EXPECT_GT(frame_rays_second, frame_rays_every / 4);
  EXPECT_LT(frame_rays_second, 3 * frame_rays_every / 4);
  EXPECT_LT(max_center_error, 0.005 * drive.length);
  EXPECT_EQ(outside_view, 0);
  RecordProperty("max_frame_ray_center_error_um", static_cast<int>(1e6 * max_center_error));

  // Thinned to 2 degrees: fewer rays, none within 2 degrees of a ray handed over before it.
  const double min_angle = 2.0 * M_PI / 180.0;
  const HandedOver thinned = RunForFrameRays(drive, mode.central, 1, min_angle);
  size_t frame_rays_thinned = 0, too_close = 0;
  for (const FinalizedKeyframe& keyframe : thinned.keyframes)
    for (const FinalizedPoint& point : keyframe.points) {
      std::vector<Eigen::Vector3d> before;
      for (const FinalizedRay& ray : point.rays)
        before.push_back((ray.center - point.position).normalized());
      for (const FinalizedFrameRay& ray : point.frame_rays) {
        ++frame_rays_thinned;
        const Eigen::Vector3d direction = (ray.center - point.position).normalized();
        for (const Eigen::Vector3d& d : before)
          too_close += std::acos(std::clamp(d.dot(direction), -1.0, 1.0)) < min_angle - 1e-9;
        before.push_back(direction);
      }
    }
  EXPECT_EQ(too_close, 0u);
  EXPECT_GT(frame_rays_thinned, 0u);
  EXPECT_LT(frame_rays_thinned, frame_rays_every);
  RecordProperty("frame_rays_per_point",
                 static_cast<int>(100.0 * static_cast<double>(frame_rays_every) /
                                  static_cast<double>(std::max<size_t>(points, 1))));
}

// Frame points (TrackerOptions::frame_points): the drive above plus points seen by three
// consecutive frames only, tracks that mostly end between two keyframes. They come back as
// frame points: flagged, no keyframe ray, their frames' rays (two or more, from frames before
// the keyframe that hands them over, the newest of them that keyframe's), ids from
// kFramePointIdBase, nine in ten within 3 % of their depth of a true point (after the similarity
// of the keyframes to the truth; a ray angle of 2° at least and 0.3 mrad of noise give about 1 %
// at one sigma). The map does not see them: the keyframe poses and the map's points are those of
// a run without them.
TEST_P(TrackerFrameRaysTest, TracksThatEndBetweenKeyframesBecomeFramePoints) {
  const Case mode = GetParam();
  SyntheticDrive drive = MakeDrive(mode.rig_radius, 60, 0.0003, 0.0);
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 400;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  scene_options.half_fov = 0.7;
  scene_options.noise = 0.0003;
  scene_options.seed = 7;
  const SyntheticScene short_lived =
      MakeSyntheticScene(drive.rig, drive.world_from_rig, scene_options);
  constexpr int kShortTrackBase = 1000000;
  std::map<int, int> first_frame;
  for (const SyntheticObservation& o : short_lived.observations)
    if (!first_frame.count(o.point)) first_frame[o.point] = o.frame + o.point % 7;
  for (const SyntheticObservation& o : short_lived.observations)
    if (o.frame >= first_frame[o.point] && o.frame < first_frame[o.point] + 3)
      drive.frames[o.frame].push_back({kShortTrackBase + o.point, o.camera, o.bearing});

  const HandedOver with = RunForFrameRays(drive, mode.central, 1, 0.0, true);
  const HandedOver without = RunForFrameRays(drive, mode.central, 1, 0.0, false);
  ASSERT_EQ(with.keyframe_poses.size(), without.keyframe_poses.size());
  for (size_t k = 0; k < with.keyframe_poses.size(); ++k)
    EXPECT_EQ(with.keyframe_poses[k].translation, without.keyframe_poses[k].translation) << k;
  std::vector<Eigen::Vector3d> estimated, truth;
  for (size_t k = 0; k < with.keyframe_poses.size(); ++k) {
    estimated.push_back(with.keyframe_poses[k].translation);
    truth.push_back(drive.world_from_rig[with.keyframe_frames[k]].translation);
  }
  const Sim3d truth_from_estimated = EstimateSim3Umeyama(estimated, truth, true);
  ASSERT_EQ(with.keyframes.size(), without.keyframes.size());
  std::set<int> ids;
  int frame_points = 0, near_truth = 0;
  for (size_t k = 0; k < with.keyframes.size(); ++k) {
    std::vector<int> map_points_with, map_points_without;
    for (const FinalizedPoint& point : without.keyframes[k].points) {
      EXPECT_FALSE(point.frame_point);
      map_points_without.push_back(point.point);
    }
    for (const FinalizedPoint& point : with.keyframes[k].points) {
      if (!point.frame_point) {
        map_points_with.push_back(point.point);
        continue;
      }
      ++frame_points;
      EXPECT_TRUE(ids.insert(point.point).second) << "a frame point handed over twice";
      EXPECT_GE(point.point, kFramePointIdBase);
      EXPECT_TRUE(point.rays.empty());
      ASSERT_GE(point.frame_rays.size(), 2u);
      int newest = -1;
      for (const FinalizedFrameRay& ray : point.frame_rays) {
        EXPECT_LE(ray.keyframe, with.keyframes[k].keyframe);
        EXPECT_GT(ray.frame, with.keyframe_frames[ray.keyframe]);
        newest = std::max(newest, ray.keyframe);
      }
      EXPECT_EQ(newest, with.keyframes[k].keyframe) << "handed over with the keyframe before";
      const Eigen::Vector3d position = truth_from_estimated * point.position;
      const Eigen::Vector3d centre =
          drive.world_from_rig[point.frame_rays.front().frame].translation;
      double nearest = std::numeric_limits<double>::infinity();
      for (const Eigen::Vector3d& p : drive.points)
        nearest = std::min(nearest, (p - position).norm());
      for (const Eigen::Vector3d& p : short_lived.points_in_world)
        nearest = std::min(nearest, (p - position).norm());
      near_truth += nearest < 0.03 * (position - centre).norm();
    }
    EXPECT_EQ(map_points_with, map_points_without) << "keyframe " << k;
  }
  EXPECT_GT(frame_points, 80);
  EXPECT_GT(near_truth, 0.9 * frame_points);
  RecordProperty("frame_points", frame_points);
}

// A rig that stands still (the last frame again and again, a red light) gives no frame rays:
// they would repeat the last ones.
TEST(TrackerFrameRays, ARigStandingStillGivesNoMoreRays) {
  SyntheticDrive drive = MakeDrive(0.05, 40, 0.0003, 0.0);
  const size_t moving = drive.frames.size();
  for (int i = 0; i < 40; ++i) {
    drive.frames.push_back(drive.frames[moving - 1]);
    drive.world_from_rig.push_back(drive.world_from_rig[moving - 1]);
  }
  const HandedOver run = RunForFrameRays(drive, true, 1);
  size_t while_moving = 0, standing = 0;
  for (const FinalizedKeyframe& keyframe : run.keyframes)
    for (const FinalizedPoint& point : keyframe.points)
      for (const FinalizedFrameRay& ray : point.frame_rays)
        ++(static_cast<size_t>(ray.frame) < moving ? while_moving : standing);
  EXPECT_GT(while_moving, 0u);
  EXPECT_EQ(standing, 0u);
}

INSTANTIATE_TEST_SUITE_P(Modes, TrackerFrameRaysTest,
                         ::testing::Values(Case{true, 0.05}, Case{false, 0.3}));

// Tracks that end within a few frames while far points stay (side cameras close to the street):
// four points in five lose their track every 4 to 11 frames and are found again as new tracks,
// the others keep theirs as long as the drive sees them. The point rule alone waits for the long
// tracks, so most short ones end between two keyframes and never become points; with the
// followed tracks' share a keyframe comes before they end.
TEST(TrackerKeyframes, AKeyframeComesBeforeMostShortTracksEnd) {
  SyntheticDrive drive = MakeDrive(0.3, 60, 0.0003, 0.0);
  std::map<int, int> first_frame;
  for (int f = 0; f < static_cast<int>(drive.frames.size()); ++f)
    for (const TrackObservation& o : drive.frames[f]) first_frame.emplace(o.track, f);
  constexpr int kTrackIdsPerPiece = 1000000;
  for (int f = 0; f < static_cast<int>(drive.frames.size()); ++f)
    for (TrackObservation& o : drive.frames[f])
      if (o.track % 5 != 0) {  // pieces of 4 to 11 frames, ending at different frames
        const int length = 4 + (o.track / 5) % 8;
        o.track += kTrackIdsPerPiece * ((f - first_frame[o.track] + o.track % length) / length);
      }
  struct Run {
    int keyframes = 0, points = 0, untracked = 0, by_followed_share = 0;
    double rms = 0.0;
  };
  const auto run = [&](double min_followed_track_share) {
    TrackerOptions options;
    options.central = false;
    options.keyframes.min_followed_track_share = min_followed_track_share;
    Tracker tracker(drive.rig, options);
    Run result;
    for (const std::vector<TrackObservation>& frame : drive.frames) {
      const FrameResult frame_result = tracker.AddFrame(frame);
      if (tracker.NumKeyframes() >= 2 && !frame_result.tracked) ++result.untracked;
      if (frame_result.status.find("few tracks followed") != std::string::npos)
        ++result.by_followed_share;
    }
    tracker.Finish();
    result.keyframes = tracker.NumKeyframes();
    result.points = tracker.NumPoints();
    result.rms = KeyframeRmsAfterSimilarity(tracker, drive);
    return result;
  };
  const Run without = run(0.0), with = run(0.25);
  EXPECT_EQ(without.by_followed_share, 0);
  EXPECT_GT(with.by_followed_share, 0);
  EXPECT_EQ(with.untracked, 0);
  EXPECT_GT(with.keyframes, without.keyframes);
  EXPECT_GT(with.points, 5 * without.points / 4)  // measured 622 against 449
      << with.points << " points against " << without.points;
  EXPECT_LT(with.rms, 0.01 * drive.length) << with.rms << " m over " << drive.length << " m";
  RecordProperty("keyframes_without", without.keyframes);
  RecordProperty("keyframes_with", with.keyframes);
  RecordProperty("points_without", without.points);
  RecordProperty("points_with", with.points);
}

// Failures in the middle of a drive: black frames (no observations), a frame whose matches are
// wrong (track ids shuffled), and a frame from 20 frames later (a jump the motion model cannot
// explain). Each is reported and skipped; no wrong pose enters the map; the frames after them
// are tracked again (their tracks are the map's, as after a re-localisation of the front end),
// and the trajectory stays within 1 % of the distance driven.
TEST(TrackerFailures, ReportsSkipsAndRecoversWithoutAWrongPose) {
  const SyntheticDrive drive = MakeDrive(0.05, 70, 0.0003, 0.03);
  TrackerOptions options;
  Tracker tracker(drive.rig, options);
  std::mt19937 random(5);
  const std::set<int> black = {30, 31, 32}, shuffled = {40}, jump = {50};
  std::vector<int> tracked_frames;
  std::vector<Rigid3d> tracked_poses;
  for (int f = 0; f < static_cast<int>(drive.frames.size()); ++f) {
    std::vector<TrackObservation> observations = drive.frames[f];
    if (black.count(f)) observations.clear();
    if (shuffled.count(f)) {
      std::vector<int> tracks;
      for (const TrackObservation& o : observations) tracks.push_back(o.track);
      std::shuffle(tracks.begin(), tracks.end(), random);
      for (size_t i = 0; i < observations.size(); ++i) observations[i].track = tracks[i];
    }
    if (jump.count(f)) observations = drive.frames[f + 18];
    const FrameResult result = tracker.AddFrame(observations);
    const bool failure = black.count(f) || shuffled.count(f) || jump.count(f);
    if (f >= 3) {
      EXPECT_EQ(result.tracked, !failure) << "frame " << f << ": " << result.status;
      if (failure) {
        EXPECT_FALSE(result.status.empty());
      }
      // The jump's matches are right and resect well: the motion model rejects the pose.
      if (jump.count(f)) {
        EXPECT_EQ(result.status.rfind("rejected", 0), 0u) << result.status;
      }
    }
    if (result.tracked) {
      tracked_frames.push_back(f);
      tracked_poses.push_back(result.world_from_rig);
    }
  }
  tracker.Finish();
  // Every tracked frame's pose (as reported, before later adjustments) near the truth.
  std::vector<Eigen::Vector3d> estimated, truth;
  for (size_t i = 0; i < tracked_frames.size(); ++i) {
    estimated.push_back(tracked_poses[i].translation);
    truth.push_back(drive.world_from_rig[tracked_frames[i]].translation);
  }
  const Sim3d truth_from_estimated = EstimateSim3Umeyama(estimated, truth, true);
  double worst = 0.0;
  for (size_t i = 0; i < estimated.size(); ++i)
    worst = std::max(worst, (truth_from_estimated * estimated[i] - truth[i]).norm());
  EXPECT_LT(AlignmentRms(truth_from_estimated, estimated, truth), 0.01 * drive.length);
  EXPECT_LT(worst, 0.03 * drive.length);
}

// The relative-motion fallback of RetryFrame: frame 40 keeps only 12 of its matches with a map
// point (too few to resect it), and 80 matches with the last tracked frame whose tracks have no
// map point yet (fresh track ids in frames 39 and 40). Its pose comes from the relative motion
// to frame 39 with the scale of the 12 map points, and it becomes a keyframe; with those 12
// matches wrong (shuffled among other points), no scale is agreed on and the frame is not
// tracked.
struct RelativeFallbackRun {
  FrameResult first, retry;
  Rigid3d previous, before_previous;  // frames 39 and 38 as tracked
};
RelativeFallbackRun RunRelativeFallback(const SyntheticDrive& drive, bool wrong_map_points) {
  Tracker tracker(drive.rig, TrackerOptions());
  RelativeFallbackRun run;
  constexpr int kFrame = 40, kFresh = 1000000;
  // Points seen in frames 39 and 40: 80 of them get fresh tracks in both frames.
  std::set<int> seen39, shared;
  for (const TrackObservation& o : drive.frames[kFrame - 1]) seen39.insert(o.track);
  for (const TrackObservation& o : drive.frames[kFrame])
    if (seen39.count(o.track) && shared.size() < 80) shared.insert(o.track);
  for (int f = 0; f < kFrame; ++f) {
    std::vector<TrackObservation> observations = drive.frames[f];
    if (f == kFrame - 1)
      for (TrackObservation& o : observations)
        if (shared.count(o.track)) o.track += kFresh;
    const FrameResult result = tracker.AddFrame(observations);
    if (f == kFrame - 2) run.before_previous = result.world_from_rig;
    if (f == kFrame - 1) run.previous = result.world_from_rig;
  }
  std::vector<TrackObservation> observations;
  std::vector<TrackObservation> map_points;
  Eigen::Vector3d position;
  for (const TrackObservation& o : drive.frames[kFrame]) {
    if (shared.count(o.track)) {
      observations.push_back({o.track + kFresh, o.camera, o.bearing});
    } else if (map_points.size() < 12 && tracker.TrackPosition(o.track, &position)) {
      map_points.push_back(o);
    }
  }
  if (wrong_map_points) {
    // Each keeps its bearing but names another map point.
    std::vector<int> tracks;
    for (const TrackObservation& o : map_points) tracks.push_back(o.track);
    std::rotate(tracks.begin(), tracks.begin() + 1, tracks.end());
    for (size_t i = 0; i < map_points.size(); ++i) map_points[i].track = tracks[i];
  }
  observations.insert(observations.end(), map_points.begin(), map_points.end());
  run.first = tracker.AddFrame(observations);
  run.retry = tracker.RetryFrame(observations);
  return run;
}

TEST(TrackerRelativeFallback, PosesAFrameWithTooFewMapPointsFromItsRelativeMotion) {
  // A central rig: the relative pose is the central five-point (on a real drive the step is
  // metres, the camera offsets centimetres; here the step is 15 cm).
  const SyntheticDrive drive = MakeDrive(0.0, 45, 0.0003, 0.0);
  const RelativeFallbackRun run = RunRelativeFallback(drive, false);
  EXPECT_FALSE(run.first.tracked) << run.first.status;
  ASSERT_TRUE(run.retry.tracked) << run.retry.status;
  EXPECT_TRUE(run.retry.keyframe) << run.retry.status;
  EXPECT_NE(run.retry.status.find("relative motion"), std::string::npos) << run.retry.status;
  // The step from frame 39 against the truth, in the map's scale (the step 38 to 39).
  const double scale =
      (run.previous.translation - run.before_previous.translation).norm() /
      (drive.world_from_rig[39].translation - drive.world_from_rig[38].translation).norm();
  const Rigid3d step = run.previous.Inverse() * run.retry.world_from_rig;
  const Rigid3d true_step = drive.world_from_rig[39].Inverse() * drive.world_from_rig[40];
  EXPECT_LT((step.translation / scale - true_step.translation).norm(), 0.02)
      << "of a " << true_step.translation.norm() << " m step";
  EXPECT_LT(RotationAngleBetween(step.rotation, true_step.rotation) * 180.0 / M_PI, 0.2);
}

TEST(TrackerRelativeFallback, RefusesAScaleThatTheMapPointsDoNotAgreeOn) {
  const SyntheticDrive drive = MakeDrive(0.0, 45, 0.0003, 0.0);
  const RelativeFallbackRun run = RunRelativeFallback(drive, true);
  EXPECT_FALSE(run.first.tracked) << run.first.status;
  EXPECT_FALSE(run.retry.tracked) << run.retry.status;
}

// Before the initialisation there is no prediction; afterwards the constant-velocity
// prediction of the next frame is close to its true pose (in the map's scale), and it is
// withdrawn after a frame that was not tracked.
TEST(TrackerFailures, PredictsByConstantVelocity) {
  const SyntheticDrive drive = MakeDrive(0.0, 30, 0.0, 0.0);
  Tracker tracker(drive.rig, TrackerOptions());
  Rigid3d predicted;
  EXPECT_FALSE(tracker.PredictPose(&predicted));
  std::vector<Rigid3d> poses;
  for (int f = 0; f < 20; ++f) poses.push_back(tracker.AddFrame(drive.frames[f]).world_from_rig);
  ASSERT_TRUE(tracker.PredictPose(&predicted));
  // Scale of the map: the estimated step over the true step.
  const double scale =
      (poses[19].translation - poses[18].translation).norm() /
      (drive.world_from_rig[19].translation - drive.world_from_rig[18].translation).norm();
  const Rigid3d true_step = drive.world_from_rig[19].Inverse() * drive.world_from_rig[20];
  const Rigid3d predicted_step = poses[19].Inverse() * predicted;
  EXPECT_NEAR(predicted_step.translation.norm() / scale, true_step.translation.norm(), 0.01);
  EXPECT_LT(RotationAngleBetween(predicted_step.rotation, true_step.rotation), 1e-3);
  Eigen::Vector3d position;
  EXPECT_TRUE(tracker.TrackPosition(drive.frames[19][0].track, &position) ||
              tracker.TrackPosition(drive.frames[19][1].track, &position));
  EXPECT_FALSE(tracker.TrackPosition(-12345, &position));
  tracker.AddFrame({});  // not tracked
  EXPECT_FALSE(tracker.PredictPose(&predicted));
}

}  // namespace
}  // namespace omni

namespace omni {
namespace {

// A front end that loses its tracks as Harris corners do: each frame a point's corner is
// missed with probability miss_rate, and a point seen again after a miss, or in another
// camera, starts a new track id (the per-camera frame-to-frame chaining of the old front end).
// Its map-point search is perfect in appearance (it knows the true point behind a track) but
// geometric in position: a candidate is found only when the true point is seen in that camera
// within max_angle of the predicted bearing, as a detected observation without a map point
// (re-labelled) or, when its corner was missed, as a new observation.
class FragmentingFrontEnd {
 public:
  FragmentingFrontEnd(const SyntheticDrive& drive, double miss_rate, uint32_t seed)
      : drive_(drive), miss_rate_(miss_rate), random_(seed) {}

  std::vector<TrackObservation> Frame(int f) {
    frame_ = f;
    visible_.clear();
    observed_points_.clear();
    std::vector<TrackObservation> observations;
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    for (const TrackObservation& truth : drive_.frames[f]) {
      const int64_t key = Key(truth.track, truth.camera);
      visible_[key] = truth.bearing;
      if (uniform(random_) < miss_rate_) continue;  // the corner is not detected
      auto chain = chains_.find(key);
      if (chain == chains_.end() || chain->second.last_frame != f - 1) {
        const int id = next_id_++;
        point_of_track_[id] = truth.track;
        chain = chains_.insert_or_assign(key, Chain{id, f}).first;
      }
      chain->second.last_frame = f;
      observations.push_back({chain->second.track, truth.camera, truth.bearing});
      observed_points_.push_back(truth.track);
    }
    return observations;
  }

  MapPointSearchFn Searcher(double max_angle) {
    return [this, max_angle](const std::vector<MapPointProjection>& candidates,
                             const std::vector<char>& eligible) {
      std::vector<Reobservation> result;
      std::set<int> used;
      for (const MapPointProjection& candidate : candidates) {
        const int point = point_of_track_.at(candidate.track);
        const int64_t key = Key(point, candidate.camera);
        const auto visible = visible_.find(key);
        if (visible == visible_.end() ||
            AngleBetween(visible->second, candidate.bearing) > max_angle)
          continue;
        // The detected observation of that point in that camera, if any.
        int index = -1;
        for (size_t i = 0; i < observed_points_.size(); ++i)
          if (observed_points_[i] == point && last_observations_camera(i) == candidate.camera)
            index = static_cast<int>(i);
        if (index >= 0 && (!eligible[index] || used.count(index))) continue;
        if (index >= 0) {
          used.insert(index);
          result.push_back({index, candidate.track, candidate.camera, (*last_)[index].bearing});
        } else {
          result.push_back({-1, candidate.track, candidate.camera, visible->second});
        }
        chains_.insert_or_assign(key, Chain{candidate.track, frame_});
      }
      return result;
    };
  }

  // The camera of observation i of the current frame.
  void SetLastObservations(const std::vector<TrackObservation>* observations) {
    last_ = observations;
  }

 private:
  struct Chain {
    int track;
    int last_frame;
  };
  static int64_t Key(int point, int camera) { return static_cast<int64_t>(point) * 16 + camera; }
  int last_observations_camera(size_t i) const { return (*last_)[i].camera; }

  const SyntheticDrive& drive_;
  double miss_rate_;
  std::mt19937 random_;
  int frame_ = -1;
  int next_id_ = 0;
  std::map<int64_t, Chain> chains_;             // (point, camera) -> current track
  std::map<int, int> point_of_track_;           // track id -> true point
  std::map<int64_t, Eigen::Vector3d> visible_;  // this frame's true bearings
  std::vector<int> observed_points_;            // per observation of the frame
  const std::vector<TrackObservation>* last_ = nullptr;
};

struct ReobservationRun {
  TrackStats stats;
  double rms = 0.0;
  double length = 0.0;
  int untracked = 0;
  int duplicates = 0;  // a point with two rays from one camera of one keyframe
  int reobserved = 0;
};

ReobservationRun RunWithFragmentedTracks(bool central, double rig_radius, bool search,
                                         double miss_rate) {
  const SyntheticDrive drive = MakeDrive(rig_radius, 60, 0.0003, 0.0);
  FragmentingFrontEnd front_end(drive, miss_rate, 7);
  TrackerOptions options;
  options.central = central;
  Tracker tracker(drive.rig, options);
  ReobservationRun run;
  run.length = drive.length;
  std::vector<FinalizedKeyframe> finalized;
  for (size_t f = 0; f < drive.frames.size(); ++f) {
    const std::vector<TrackObservation> observations = front_end.Frame(static_cast<int>(f));
    front_end.SetLastObservations(&observations);
    const FrameResult result =
        tracker.AddFrame(observations, search ? front_end.Searcher(0.01) : MapPointSearchFn());
    if (tracker.NumKeyframes() >= 2 && !result.tracked) ++run.untracked;
    run.reobserved += result.reobserved;
    for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
      finalized.push_back(std::move(keyframe));
  }
  tracker.Finish();
  for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
    finalized.push_back(std::move(keyframe));
  run.stats = ComputeTrackStats(finalized);
  for (const FinalizedKeyframe& keyframe : finalized)
    for (const FinalizedPoint& point : keyframe.points) {
      std::set<std::pair<int, int>> seen;
      for (const FinalizedRay& ray : point.rays)
        run.duplicates += seen.insert({ray.keyframe, ray.camera}).second ? 0 : 1;
    }
  run.rms = KeyframeRmsAfterSimilarity(tracker, drive);
  return run;
}

class TrackerReobservationTest : public ::testing::TestWithParam<Case> {};

// With the corners of a quarter of the points missed each frame and tracks cut at every
// camera change, the map-point search makes the tracks long again: more keyframes per point,
// points seen by two cameras, no point twice in one camera of one keyframe, and the
// trajectory still within 1 % of the distance.
TEST_P(TrackerReobservationTest, MapPointSearchLengthensFragmentedTracks) {
  const ReobservationRun without =
      RunWithFragmentedTracks(GetParam().central, GetParam().rig_radius, false, 0.1);
  const ReobservationRun with =
      RunWithFragmentedTracks(GetParam().central, GetParam().rig_radius, true, 0.1);
  RecordProperty("mean_track_keyframes_without_x100",
                 static_cast<int>(100 * without.stats.mean_keyframes));
  RecordProperty("mean_track_keyframes_with_x100",
                 static_cast<int>(100 * with.stats.mean_keyframes));
  RecordProperty("aperture_ok_without_pct",
                 static_cast<int>(100 * without.stats.aperture_ok_share));
  RecordProperty("aperture_ok_with_pct", static_cast<int>(100 * with.stats.aperture_ok_share));
  EXPECT_EQ(without.untracked, 0);
  EXPECT_EQ(with.untracked, 0);
  EXPECT_EQ(without.reobserved, 0);
  EXPECT_GT(with.reobserved, 0);
  EXPECT_EQ(with.duplicates, 0);
  EXPECT_EQ(without.stats.multi_camera_share, 0.0);
  // The neighbour cameras' cones overlap from the rig outwards only when the rig is small.
  if (GetParam().rig_radius < 0.1) {
    EXPECT_GT(with.stats.multi_camera_share, 0.01);
  }
  EXPECT_LT(without.stats.mean_keyframes, 2.8);
  EXPECT_GT(with.stats.mean_keyframes, 3.0);
  EXPECT_GT(with.stats.aperture_ok_share, without.stats.aperture_ok_share + 0.2);
  EXPECT_LT(with.rms, 0.01 * with.length);
}

INSTANTIATE_TEST_SUITE_P(Modes, TrackerReobservationTest,
                         ::testing::Values(Case{true, 0.05}, Case{false, 0.3}));

// Tracker::RefineFramePose on the drive above: every tracked frame between keyframes, its pose
// from the tracker moved by 10 cm and 0.6 degrees, comes back within 1 cm of the truth (after
// the similarity of the keyframes to the truth) by the motion-only adjustment against the final
// map; from 1.5 m and 11 degrees off it comes back too or is refused (never a wrong pose); a
// frame with fewer observations than asked for, a keyframe, or a tracker that kept no
// observations refines nothing.
class TrackerFramePoseRefinementTest : public ::testing::TestWithParam<Case> {};

TEST_P(TrackerFramePoseRefinementTest, BringsAPerturbedFrameBackToItsTruePose) {
  const SyntheticDrive drive = MakeDrive(GetParam().rig_radius, 60, 0.0003, 0.03);
  TrackerOptions options;
  options.central = GetParam().central;
  options.keep_frame_observations = true;
  Tracker tracker(drive.rig, options);
  std::vector<FrameResult> results;
  for (const std::vector<TrackObservation>& frame : drive.frames)
    results.push_back(tracker.AddFrame(frame));
  tracker.Finish();
  ASSERT_TRUE(tracker.GlobalBundleAdjust().success);

  const std::vector<Rigid3d> keyframe_poses = tracker.KeyframePoses();
  const std::vector<int> keyframe_frames = tracker.KeyframeFrames();
  ASSERT_GE(keyframe_poses.size(), 4u);
  std::vector<Eigen::Vector3d> estimated, truth;
  for (size_t k = 0; k < keyframe_poses.size(); ++k) {
    estimated.push_back(keyframe_poses[k].translation);
    truth.push_back(drive.world_from_rig[keyframe_frames[k]].translation);
  }
  const Sim3d truth_from_map = EstimateSim3Umeyama(estimated, truth, true);
  const double metres_per_unit = truth_from_map.scale;
  ASSERT_GT(metres_per_unit, 0.0);
  const auto error_m = [&](const Rigid3d& world_from_rig, int frame) {
    return (truth_from_map * world_from_rig.translation - drive.world_from_rig[frame].translation)
        .norm();
  };

  const std::set<int> keyframes(keyframe_frames.begin(), keyframe_frames.end());
  int refined_frames = 0;
  double worst_error = 0.0;
  for (int f = 0; f < static_cast<int>(results.size()); ++f) {
    if (!results[f].tracked) continue;
    const Rigid3d& tracked = results[f].world_from_rig;
    const Rigid3d moved(
        tracked.rotation * Eigen::Quaterniond(Eigen::AngleAxisd(
                               0.01, Eigen::Vector3d(1.0, 2.0, 3.0).normalized())),
        tracked.translation + (0.1 / metres_per_unit) * Eigen::Vector3d(0.6, -0.8, 0.0));
    const FramePoseRefinement refinement = tracker.RefineFramePose(f, moved);
    if (keyframes.count(f)) {
      EXPECT_FALSE(refinement.refined) << "keyframe " << f;
      continue;
    }
    ASSERT_TRUE(refinement.refined) << "frame " << f << ": " << refinement.inliers << " of "
                                    << refinement.observations << " inliers";
    ++refined_frames;
    EXPECT_GE(refinement.observations, 30) << "frame " << f;
    EXPECT_LT(refinement.rms_angle_after, refinement.rms_angle_before) << "frame " << f;
    EXPECT_GT(error_m(moved, f), 0.09) << "frame " << f;
    worst_error = std::max(worst_error, error_m(refinement.world_from_rig, f));
    EXPECT_LT(RotationAngleBetween(truth_from_map.rotation * refinement.world_from_rig.rotation,
                                   drive.world_from_rig[f].rotation),
              0.002)
        << "frame " << f;

    // From 1.5 m and 11 degrees off: back to the truth, or refused and given back unchanged;
    // never a wrong pose.
    const Rigid3d far(
        tracked.rotation * Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitZ())),
        tracked.translation + (1.5 / metres_per_unit) * Eigen::Vector3d::UnitY());
    const FramePoseRefinement from_far = tracker.RefineFramePose(f, far);
    if (from_far.refined)
      EXPECT_LT(error_m(from_far.world_from_rig, f), 0.01) << "frame " << f;
    else
      EXPECT_EQ(from_far.world_from_rig.translation, far.translation) << "frame " << f;
    // More inliers asked for than the frame has: refused, the pose given back unchanged.
    FramePoseRefinementOptions strict;
    strict.min_inliers = refinement.observations + 1;
    const FramePoseRefinement refused = tracker.RefineFramePose(f, moved, strict);
    EXPECT_FALSE(refused.refined) << "frame " << f;
    EXPECT_EQ(refused.world_from_rig.translation, moved.translation) << "frame " << f;
  }
  EXPECT_GE(refined_frames, 20);
  EXPECT_LT(worst_error, 0.01) << "worst refined frame " << worst_error << " m from the truth";
  RecordProperty("worst_error_mm", static_cast<int>(1e3 * worst_error));

  // Without the observations kept, nothing to refine.
  TrackerOptions without = options;
  without.keep_frame_observations = false;
  Tracker plain(drive.rig, without);
  for (const std::vector<TrackObservation>& frame : drive.frames) plain.AddFrame(frame);
  for (int f = 0; f < static_cast<int>(drive.frames.size()); ++f)
    EXPECT_FALSE(plain.RefineFramePose(f, results[f].world_from_rig).refined) << "frame " << f;
}

INSTANTIATE_TEST_SUITE_P(Modes, TrackerFramePoseRefinementTest,
                         ::testing::Values(Case{true, 0.05}, Case{false, 0.3}));

TEST(TrackerFramePoseRefinement, BadOptionsThrowNamingTheField) {
  const Rig rig = MakeSyntheticRingRig(2, false, 0.0);
  const Tracker tracker(rig, TrackerOptions{});
  FramePoseRefinementOptions options;
  options.min_inlier_share = 0.0;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { tracker.RefineFramePose(0, Rigid3d(), options); },
                                          "FramePoseRefinementOptions.min_inlier_share"));
  options = FramePoseRefinementOptions();
  options.min_inliers = 3;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { tracker.RefineFramePose(0, Rigid3d(), options); },
                                          "FramePoseRefinementOptions.min_inliers"));
}

TEST(Tracker, BadOptionsThrowNamingTheField) {
  const Rig rig = MakeSyntheticRingRig(2, false, 0.0);
  TrackerOptions options;
  options.keyframes.min_tracked_share = 1.5;
  EXPECT_THROW((Tracker{rig, options}), OptionsError);
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { Tracker tracker(rig, options); },
                                          "TrackerOptions.keyframes.min_tracked_share: expected"));
  options = TrackerOptions();
  options.resection_ransac.confidence = 1.0;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { Tracker tracker(rig, options); },
                                          "TrackerOptions.resection_ransac.confidence"));
  options = TrackerOptions();
  options.num_free_keyframes = 0;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { Tracker tracker(rig, options); },
                                          "TrackerOptions.num_free_keyframes"));
  options = TrackerOptions();
  options.min_init_track_share = 1.0;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { Tracker tracker(rig, options); },
                                          "TrackerOptions.min_init_track_share"));
  options = TrackerOptions();
  options.frame_ray_step = -1;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { Tracker tracker(rig, options); },
                                          "TrackerOptions.frame_ray_step"));
  EXPECT_THROW((Tracker{Rig(), TrackerOptions()}), std::invalid_argument);  // no camera
}

}  // namespace
}  // namespace omni

namespace omni {
namespace {

// The frames read before the map exists are posed once it does, and a first keyframe that
// cannot start a map (a black frame) is given up for the next frame.
TEST(TrackerInitialisation, ResectsTheFramesReadWhileInitialisingAndRestartsAfterABlackFrame) {
  const SyntheticDrive drive = MakeDrive(0.05, 30, 0.0003, 0.03);
  Tracker tracker(drive.rig, TrackerOptions{});
  std::map<int, FrameResult> results;
  int initialised_at = -1;
  for (int f = 0; f < 30; ++f) {
    // Frame 0 is black: no observation.
    const std::vector<TrackObservation> observations =
        f == 0 ? std::vector<TrackObservation>{} : drive.frames[f];
    results[f] = tracker.AddFrame(observations);
    if (initialised_at < 0 && tracker.Initialised()) initialised_at = f;
    for (const Tracker::RevisedFrame& revised : tracker.TakeRevisedFrames())
      results[revised.frame] = revised.result;
  }
  tracker.Finish();
  EXPECT_FALSE(results[0].tracked) << results[0].status;
  EXPECT_EQ(results[0].status.rfind("initialisation restarted", 0), 0u) << results[0].status;
  // The drive's small steps keep frame 2 below the parallax the initialisation needs, so
  // there are frames between the new first keyframe (1) and the initialisation to resect.
  ASSERT_GT(initialised_at, 2);
  std::vector<Eigen::Vector3d> estimated, truth;
  for (int f = 1; f < 30; ++f) {
    ASSERT_TRUE(results[f].tracked) << "frame " << f << ": " << results[f].status;
    estimated.push_back(results[f].world_from_rig.translation);
    truth.push_back(drive.world_from_rig[f].translation);
  }
  for (int f = 2; f < initialised_at; ++f)
    EXPECT_EQ(results[f].status, "resected once the map existed");
  const Sim3d truth_from_estimated = EstimateSim3Umeyama(estimated, truth, true);
  EXPECT_LT(AlignmentRms(truth_from_estimated, estimated, truth), 0.01 * drive.length);
}

// A second frame that keeps only a small share of the first keyframe's tracks (the front end's
// search lost most of them) does not start the map, though its tracks would give a pose; the
// same frame with the share allowed, or with all its tracks, does.
TEST(TrackerInitialisation, AFrameThatKeepsFewOfTheFirstKeyframesTracksIsLeftToTheRetry) {
  const SyntheticDrive drive = MakeDrive(0.05, 30, 0.0003, 0.0);
  constexpr int kSecond = 8;  // 1.2 m from frame 0: parallax enough
  std::set<int> first_tracks;
  for (const TrackObservation& o : drive.frames[0]) first_tracks.insert(o.track);
  // Every other common track kept: half of the common ones.
  std::vector<TrackObservation> thinned;
  int common = 0;
  for (const TrackObservation& o : drive.frames[kSecond]) {
    if (!first_tracks.count(o.track)) continue;
    if (common++ % 2 == 0) thinned.push_back(o);
  }
  const double share =
      static_cast<double>(thinned.size()) / static_cast<double>(drive.frames[0].size());
  TrackerOptions options;
  ASSERT_GE(static_cast<int>(thinned.size()), 2 * options.min_init_points);
  ASSERT_LT(share, 0.5);
  auto initialise = [&](double min_share, const std::vector<TrackObservation>& second) {
    TrackerOptions o = options;
    o.min_init_track_share = min_share;
    Tracker tracker(drive.rig, o);
    tracker.AddFrame(drive.frames[0]);
    const FrameResult result = tracker.AddFrame(second);
    return std::make_pair(tracker.Initialised(), result.status);
  };
  const auto refused = initialise(share + 0.05, thinned);
  EXPECT_FALSE(refused.first);
  EXPECT_NE(refused.second.find("few of the first keyframe's tracks"), std::string::npos)
      << refused.second;
  EXPECT_TRUE(initialise(share - 0.05, thinned).first);
  EXPECT_TRUE(initialise(0.0, thinned).first);
  EXPECT_TRUE(initialise(share + 0.05, drive.frames[kSecond]).first);
}

}  // namespace
}  // namespace omni

namespace omni {
namespace {

// The global adjustments' stopping tolerance is checked with the tracker's options.
TEST(TrackerOptionsCheck, TheGlobalAdjustmentToleranceIsAShareOfTheCost) {
  TrackerOptions options;
  EXPECT_EQ(options.Check(), "");
  for (const double bad : {0.0, -1e-6, 1.0, std::nan("")}) {
    options.global_bundle_adjustment_function_tolerance = bad;
    EXPECT_NE(options.Check().find("global_bundle_adjustment_function_tolerance"),
              std::string::npos)
        << bad;
  }
}

}  // namespace
}  // namespace omni

namespace omni {
namespace {

// Poses and points of a run of the tracker over a drive, ended by the global adjustment.
struct TrackerRun {
  std::vector<Rigid3d> keyframe_poses;
  std::vector<int> keyframe_frames;
  std::vector<Rigid3d> frame_poses;
  int points = 0;
};

TrackerRun RunTracker(const SyntheticDrive& drive, const TrackerOptions& options) {
  Tracker tracker(drive.rig, options);
  TrackerRun run;
  for (const std::vector<TrackObservation>& frame : drive.frames)
    run.frame_poses.push_back(tracker.AddFrame(frame).world_from_rig);
  tracker.Finish();
  EXPECT_TRUE(tracker.GlobalBundleAdjust().success);
  run.keyframe_poses = tracker.KeyframePoses();
  run.keyframe_frames = tracker.KeyframeFrames();
  run.points = tracker.NumPoints();
  return run;
}

// Two runs of the tracker over the same drive give the same keyframes, poses and points to the
// last bit, whatever the threads did and wherever the allocator put things (the second run
// after blocks of many sizes were allocated and every other one freed).
class TrackerRepeatabilityTest : public ::testing::TestWithParam<Case> {};

TEST_P(TrackerRepeatabilityTest, TwoRunsGiveTheSamePosesToTheLastBit) {
  const SyntheticDrive drive = MakeDrive(GetParam().rig_radius, 40, 0.0005, 0.03);
  TrackerOptions options;
  options.central = GetParam().central;
  const TrackerRun first = RunTracker(drive, options);
  std::vector<std::vector<char>> blocks;
  for (int i = 0; i < 2000; ++i) blocks.emplace_back(16 + 8 * (i % 300), 1);
  for (size_t i = 0; i < blocks.size(); i += 2) blocks[i] = std::vector<char>();
  const TrackerRun second = RunTracker(drive, options);
  ASSERT_GE(first.keyframe_poses.size(), 4u);
  EXPECT_EQ(first.points, second.points);
  ASSERT_EQ(first.keyframe_frames, second.keyframe_frames);
  for (size_t k = 0; k < first.keyframe_poses.size(); ++k) {
    EXPECT_EQ(first.keyframe_poses[k].rotation.coeffs(), second.keyframe_poses[k].rotation.coeffs())
        << "keyframe " << k;
    EXPECT_EQ(first.keyframe_poses[k].translation, second.keyframe_poses[k].translation)
        << "keyframe " << k;
  }
  ASSERT_EQ(first.frame_poses.size(), second.frame_poses.size());
  for (size_t f = 0; f < first.frame_poses.size(); ++f)
    EXPECT_EQ(first.frame_poses[f].translation, second.frame_poses[f].translation) << "frame " << f;
}

INSTANTIATE_TEST_SUITE_P(Modes, TrackerRepeatabilityTest,
                         ::testing::Values(Case{true, 0.05}, Case{false, 0.3}));

}  // namespace
}  // namespace omni

namespace omni {
namespace {

// A tail adjustment (GlobalBundleAdjust from a first free keyframe on) moves only the keyframes
// from that one on, not one bit of those before, lowers the RMS angle of what it adjusts, keeps
// the keyframes within 1 % of the length of the truth, and is remembered as the last global
// adjustment, as a whole one is.
TEST(TrackerGlobalAdjustment, ATailAdjustmentMovesOnlyTheKeyframesFromTheFirstFreeOne) {
  const SyntheticDrive drive = MakeDrive(0.05, 150, 0.0005, 0.03);
  Tracker tracker(drive.rig, TrackerOptions());
  for (const std::vector<TrackObservation>& frame : drive.frames) tracker.AddFrame(frame);
  tracker.Finish();
  EXPECT_EQ(tracker.KeyframesAtLastGlobalAdjustment(), 0);
  const std::vector<Rigid3d> before = tracker.KeyframePoses();
  const int num_keyframes = static_cast<int>(before.size());
  ASSERT_GE(num_keyframes, 8);
  const int first_free = num_keyframes - 4;
  const BundleAdjustmentSummary tail = tracker.GlobalBundleAdjust(false, 0.0, nullptr, first_free);
  ASSERT_TRUE(tail.success);
  EXPECT_LE(tail.rms_angle_after, tail.rms_angle_before);
  EXPECT_EQ(tracker.KeyframesAtLastGlobalAdjustment(), num_keyframes);
  const std::vector<Rigid3d> after = tracker.KeyframePoses();
  ASSERT_EQ(after.size(), before.size());
  double largest_move = 0.0;
  for (int k = 0; k < num_keyframes; ++k) {
    const double move = (after[k].translation - before[k].translation).norm() +
                        after[k].rotation.angularDistance(before[k].rotation);
    if (k < first_free) {
      EXPECT_EQ(move, 0.0) << "keyframe " << k << " before the first free one moved";
    } else {
      largest_move = std::max(largest_move, move);
    }
  }
  EXPECT_GT(largest_move, 0.0);
  const std::vector<int> frames = tracker.KeyframeFrames();
  std::vector<Eigen::Vector3d> estimated, truth;
  for (int k = 0; k < num_keyframes; ++k) {
    estimated.push_back(after[k].translation);
    truth.push_back(drive.world_from_rig[frames[k]].translation);
  }
  EXPECT_LT(AlignmentRms(EstimateSim3Umeyama(estimated, truth, true), estimated, truth),
            0.01 * drive.length);
}

}  // namespace
}  // namespace omni

namespace omni {
namespace {

// A tracker that has tracked every frame of the drive and finished; *tracked, if given, receives
// each frame's tracked pose.
std::unique_ptr<Tracker> TrackWholeDrive(const SyntheticDrive& drive, const TrackerOptions& options,
                                         std::vector<Rigid3d>* tracked = nullptr) {
  auto tracker = std::make_unique<Tracker>(drive.rig, options);
  for (const std::vector<TrackObservation>& frame : drive.frames) {
    const Rigid3d world_from_rig = tracker->AddFrame(frame).world_from_rig;
    if (tracked != nullptr) tracked->push_back(world_from_rig);
  }
  tracker->Finish();
  return tracker;
}

// A global adjustment's own stopping tolerance (the loop closer's) replaces the tracker's: on
// one map, a loose one stops in fewer iterations than a tight one, both lower the RMS angle, and
// a tolerance outside [0, 1) is refused.
TEST(TrackerGlobalAdjustment, ItsOwnToleranceReplacesTheTrackers) {
  const SyntheticDrive drive = MakeDrive(0.3, 60, 0.0005, 0.03);
  TrackerOptions options;
  options.central = false;
  auto adjusted = [&](double function_tolerance) {
    return TrackWholeDrive(drive, options)
        ->GlobalBundleAdjust(false, 0.0, nullptr, 0, function_tolerance);
  };
  const BundleAdjustmentSummary tight = adjusted(1e-12);
  const BundleAdjustmentSummary loose = adjusted(0.5);
  ASSERT_TRUE(tight.success);
  ASSERT_TRUE(loose.success);
  EXPECT_LT(loose.num_iterations, tight.num_iterations);
  EXPECT_LT(tight.rms_angle_after, tight.rms_angle_before);
  EXPECT_LE(loose.rms_angle_after, loose.rms_angle_before);
  Tracker tracker(drive.rig, options);
  for (const double bad : {-1e-6, 1.0, std::nan("")}) {
    EXPECT_THROW(tracker.GlobalBundleAdjust(false, 0.0, nullptr, 0, bad), std::invalid_argument)
        << bad;
  }
}

// Frames between keyframes adjusted with the whole map (GlobalBundleAdjust's frames): each one
// with enough kept observations is adjusted, from a start 10 cm and 0.3 degrees off its tracked
// pose back to within 1 % of the length of the truth (after the keyframes' similarity), and
// closer than it started; a frame with no kept observations, or asked for more than it has, is
// left out and keeps its pose.
TEST(TrackerGlobalAdjustment, FramesBetweenKeyframesAreAdjustedWithTheMap) {
  const SyntheticDrive drive = MakeDrive(0.3, 60, 0.0005, 0.03);
  TrackerOptions options;
  options.central = false;
  options.keep_frame_observations = true;
  std::vector<Rigid3d> tracked;
  const std::unique_ptr<Tracker> tracked_drive = TrackWholeDrive(drive, options, &tracked);
  Tracker& tracker = *tracked_drive;
  const std::vector<int> keyframe_frames = tracker.KeyframeFrames();
  std::vector<AdjustedFrame> frames;
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(0.3 * M_PI / 180.0, Eigen::Vector3d::UnitZ()));
  for (int f = 0; f < static_cast<int>(drive.frames.size()); ++f) {
    if (std::count(keyframe_frames.begin(), keyframe_frames.end(), f)) continue;
    frames.push_back({f, Rigid3d(turn * tracked[f].rotation,
                                 tracked[f].translation + Eigen::Vector3d(0.1, 0, 0))});
  }
  ASSERT_GE(frames.size(), 20u);
  frames.push_back({1000, tracked.back()});  // never given to AddFrame: no observations
  const std::vector<AdjustedFrame> start = frames;
  ASSERT_TRUE(tracker.GlobalBundleAdjust(false, 0.0, nullptr, 0, 0.0, &frames).success);
  EXPECT_FALSE(frames.back().adjusted);
  EXPECT_EQ(frames.back().world_from_rig.translation, start.back().world_from_rig.translation);
  frames.pop_back();

  // The keyframes' similarity to the truth carries the frames.
  std::vector<Eigen::Vector3d> estimated, truth;
  const std::vector<Rigid3d> keyframe_poses = tracker.KeyframePoses();
  for (size_t k = 0; k < keyframe_poses.size(); ++k) {
    estimated.push_back(keyframe_poses[k].translation);
    truth.push_back(drive.world_from_rig[keyframe_frames[k]].translation);
  }
  const Sim3d truth_from_estimated = EstimateSim3Umeyama(estimated, truth, true);
  int adjusted = 0;
  for (size_t i = 0; i < frames.size(); ++i) {
    if (!frames[i].adjusted) continue;
    ++adjusted;
    const Eigen::Vector3d true_centre = drive.world_from_rig[frames[i].frame].translation;
    const double error =
        (truth_from_estimated * frames[i].world_from_rig.translation - true_centre).norm();
    const double error_before =
        (truth_from_estimated * start[i].world_from_rig.translation - true_centre).norm();
    EXPECT_LT(error, 0.01 * drive.length) << "frame " << frames[i].frame;
    EXPECT_LT(error, error_before) << "frame " << frames[i].frame;
  }
  EXPECT_GE(adjusted, static_cast<int>(0.9 * frames.size()));

  // More observations asked for than any frame has: none is adjusted.
  std::vector<AdjustedFrame> demanding = start;
  ASSERT_TRUE(tracker.GlobalBundleAdjust(false, 0.0, nullptr, 0, 0.0, &demanding, 1000000).success);
  for (const AdjustedFrame& frame : demanding) EXPECT_FALSE(frame.adjusted);
}

}  // namespace
}  // namespace omni

namespace omni {
namespace {

// The resection's consensus: 0 picks by mode (three times the angle in non-central mode, one
// angle in central mode, figures.md F52), an explicit factor applies in either mode, and a
// factor below 1 (a consensus narrower than the inliers) or NaN is refused.
TEST(TrackerOptionsCheck, TheResectionConsensusIsByModeOrAFactorOfAtLeastOne) {
  TrackerOptions options;
  options.central = false;
  EXPECT_EQ(options.ResectionConsensusAngleFactor(), 3.0);
  options.central = true;
  EXPECT_EQ(options.ResectionConsensusAngleFactor(), 1.0);
  options.resection_consensus_angle_factor = 2.0;
  EXPECT_EQ(options.ResectionConsensusAngleFactor(), 2.0);
  EXPECT_EQ(options.Check(), "");
  for (const double bad : {0.5, -1.0, 101.0, std::nan("")}) {
    options.resection_consensus_angle_factor = bad;
    EXPECT_NE(options.Check().find("resection_consensus_angle_factor"), std::string::npos) << bad;
  }
}

}  // namespace
}  // namespace omni
