// Geometric verification of a loop candidate (sfm/loop_closure.h VerifyLoop): the
// relative pose of the rig from the matched bearings and the 3-D similarity of the matched map
// points, which must agree, on synthetic revisits with ground truth; and the linear appearance
// search against the pairwise scores.

#include <gtest/gtest.h>

#include <random>

#include "sfm/loop_closure.h"
#include "sfm/synthetic.h"

namespace omni {
namespace {

Eigen::Quaterniond Yaw(double angle) {
  return Eigen::Quaterniond(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()));
}

// A revisit: keyframe 0 ("then") at the place, keyframe `kNow` ("now") back near it after a
// loop of 40 keyframes on a circle (a path of ~100 m), turned by one ring camera (72°) plus a
// little, 1 m to the side. The map of "now" has drifted by `drift` (world_drifted_from_true).
struct Revisit {
  static constexpr int kNow = 40;
  Rig rig;
  Rigid3d world_from_then, world_from_now;  // true
  Sim3d drift;
  std::vector<Rigid3d> world_from_keyframe;  // the map: then true, now drifted
  LoopMatches matches;
  std::vector<char> is_outlier;  // of the 2-D matches
};

Revisit MakeRevisit(const Rig& rig, double outlier_ratio, uint32_t seed) {
  Revisit r;
  r.rig = rig;
  r.world_from_then = Rigid3d(Yaw(0.1), Eigen::Vector3d(0.0, 0.0, 0.0));
  r.world_from_now = Rigid3d(Yaw(0.1 + 2.0 * M_PI / 5.0 + 0.05), Eigen::Vector3d(0.3, 1.0, 0.05));
  r.drift = Sim3d(1.05, Yaw(0.03), Eigen::Vector3d(1.2, -0.8, 0.1));
  for (int k = 0; k <= Revisit::kNow; ++k) {
    const double angle = 2.0 * M_PI * k / (Revisit::kNow + 1);
    r.world_from_keyframe.emplace_back(
        Yaw(angle), Eigen::Vector3d(16.0 * std::sin(angle), 16.0 * (1.0 - std::cos(angle)), 0.0));
  }
  r.world_from_keyframe.front() = r.world_from_then;
  r.world_from_keyframe.back() = TransformPose(r.drift, r.world_from_now);

  SyntheticSceneOptions scene_options;
  scene_options.num_points = 400;
  scene_options.min_depth = 4.0;
  scene_options.max_depth = 15.0;
  scene_options.noise = 0.0007;
  scene_options.outlier_ratio = outlier_ratio;
  scene_options.seed = seed;
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {r.world_from_then, r.world_from_now}, scene_options);
  const SyntheticMatches m = MatchSyntheticFrames(scene, 0, 1);
  r.matches.bearings_then = m.bearings1;
  r.matches.cameras_then = m.cameras1;
  r.matches.bearings_now = m.bearings2;
  r.matches.cameras_now = m.cameras2;
  r.is_outlier = m.is_outlier;
  // Half of the matches have a map point in both keyframes, triangulated ~1 % of the depth off.
  std::mt19937 rng(seed);
  std::normal_distribution<double> error(0.0, 0.01);
  for (size_t i = 0; i < m.points.size(); i += 2) {
    if (m.is_outlier[i]) continue;
    const Eigen::Vector3d& p = scene.points_in_world[m.points[i]];
    const double depth = (p - r.world_from_then.translation).norm();
    const Eigen::Vector3d e1(error(rng), error(rng), error(rng)),
        e2(error(rng), error(rng), error(rng));
    r.matches.points_then.push_back(p + depth * e1);
    r.matches.points_now.push_back(r.drift * (p + depth * e2));
    r.matches.tracks.emplace_back(1000 + static_cast<int>(i), static_cast<int>(i));
    r.matches.match_of_point.push_back(static_cast<int>(i));
  }
  return r;
}

// The shift the turn of one camera means: now's ring camera ring[i] sees what then's camera
// ring[i] + 1 saw (MakeSyntheticRingRig numbers the side cameras by azimuth).
int ExpectedShift(const std::vector<int>& ring) {
  const int n = static_cast<int>(ring.size());
  for (int shift = 0; shift < n; ++shift)
    if (ring[shift % n] == (ring[0] + 1) % n) return shift;
  return -1;
}

Rig LadybugLikeRig() {
  Rig rig = MakeSyntheticRingRig(5, true, 0.04);
  rig.central = true;  // 4 cm offsets: the central approximation, as rig.json says
  return rig;
}

TEST(LoopVerification, AcceptsATurnedRevisitWithTheRightShiftAndRelativePose) {
  const Revisit r = MakeRevisit(LadybugLikeRig(), 0.1, 3);
  const LoopClosureOptions options;
  const LoopDetector detector(r.rig, options.detection);
  ASSERT_EQ(detector.ring().size(), 5u);
  const int shift = ExpectedShift(detector.ring());
  ASSERT_GT(shift, 0);
  ASSERT_GT(r.matches.bearings_now.size(), 150u);
  ASSERT_GT(r.matches.points_now.size(), 60u);

  const LoopVerification v = VerifyLoop(r.rig, detector.ring(), shift, r.matches,
                                        r.world_from_keyframe, 0, Revisit::kNow, options, 1);
  ASSERT_TRUE(v.accepted) << v.refusal;
  EXPECT_EQ(v.ring_shift, shift);
  const Rigid3d truth = r.world_from_then.Inverse() * r.world_from_now;
  // The central approximation costs up to offset / depth (4 cm at 4 m: 10 mrad) per bearing.
  EXPECT_LT(RotationAngleBetween(v.then_from_now.rotation, truth.rotation), 0.01);
  // Central: the translation's direction only (unit).
  EXPECT_NEAR(v.then_from_now.translation.norm(), 1.0, 1e-9);
  EXPECT_LT(AngleBetween(v.then_from_now.translation, truth.translation), 0.1);
  // Most true matches kept, most outliers not.
  int kept = 0, inliers = 0;
  for (char o : r.is_outlier) inliers += o ? 0 : 1;
  kept = v.relative_inliers;
  EXPECT_GT(kept, 0.85 * inliers);
  EXPECT_LT(kept, inliers + 0.1 * (r.is_outlier.size() - inliers));
  // The similarity undoes the drift, and agrees with the relative pose.
  const Sim3d undo = r.drift.Inverse();
  EXPECT_NEAR(v.similarity.scale, undo.scale, 0.01);
  EXPECT_LT(RotationAngleBetween(v.similarity.rotation, undo.rotation), 0.01);
  EXPECT_LT(v.rotation_disagreement, 0.01);
  // The pairs to merge: inliers of both checks.
  EXPECT_LE(static_cast<int>(v.inlier_tracks.size()), v.similarity_inliers);
  EXPECT_GE(static_cast<int>(v.inlier_tracks.size()), 0.9 * v.similarity_inliers);
  EXPECT_LT(v.drift_share, options.max_drift_share);

  // The same matches with a wrong appearance shift: the rotation says otherwise.
  const LoopVerification wrong = VerifyLoop(r.rig, detector.ring(), (shift + 1) % 5, r.matches,
                                            r.world_from_keyframe, 0, Revisit::kNow, options, 1);
  EXPECT_FALSE(wrong.accepted);
  EXPECT_EQ(wrong.ring_shift, shift);
}

TEST(LoopVerification, GeneralizedRelativePoseIsMetricWithLargeOffsets) {
  // Offsets of 0.5 m against 4–15 m depths: the generalised solver sees the scale.
  const Revisit r = MakeRevisit(MakeSyntheticRingRig(5, true, 0.5), 0.03, 5);
  LoopClosureOptions options;
  options.relative_pose_model = LoopClosureOptions::RelativePoseModel::kGeneralized;
  options.generalized_relative_pose.ransac.max_angle_error = 0.003;
  const LoopDetector detector(r.rig, options.detection);
  const int shift = ExpectedShift(detector.ring());
  const LoopVerification v = VerifyLoop(r.rig, detector.ring(), shift, r.matches,
                                        r.world_from_keyframe, 0, Revisit::kNow, options, 2);
  ASSERT_TRUE(v.accepted) << v.refusal;
  EXPECT_EQ(v.ring_shift, shift);
  const Rigid3d truth = r.world_from_then.Inverse() * r.world_from_now;
  EXPECT_LT(RotationAngleBetween(v.then_from_now.rotation, truth.rotation), 0.005);
  EXPECT_LT((v.then_from_now.translation - truth.translation).norm(),
            0.1 * truth.translation.norm());
}

// A repetitive street: the candidate is another place, 30 m further, where the houses on one
// side repeat the revisit's (the same layout, each element 12 to 20 cm off: under the
// similarity's tolerance of 3 % of the median depth). The drifted map puts the revisit next to
// the candidate. The facade's matched points fit a similarity; the rest of the view (the other
// cameras: look-alike texture, wrong matches) fits no relative pose with the facade's bearings.
TEST(LoopVerification, RefusesARepetitiveStreetThatOnlyTheSimilarityFits) {
  const Rig rig = LadybugLikeRig();
  const Rigid3d world_from_then(Yaw(0.0), Eigen::Vector3d::Zero());
  const Eigen::Vector3d period(30.0, 0.0, 0.0);
  const Rigid3d world_from_now(Yaw(0.02), period + Eigen::Vector3d(0.2, 0.4, 0.0));
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 300;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  scene_options.noise = 0.0005;
  scene_options.seed = 7;
  const SyntheticScene street = MakeSyntheticScene(rig, {world_from_then}, scene_options);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> off(0.12, 0.2), angle(0.0, 2.0 * M_PI);
  std::normal_distribution<double> noise(0.0, scene_options.noise);
  // The drifted map: the revisit's world shifted back by the period (plus a little).
  const Sim3d drift(1.0, Yaw(0.01), -period + Eigen::Vector3d(0.5, -0.3, 0.0));
  std::vector<Rigid3d> world_from_keyframe;
  for (int k = 0; k <= Revisit::kNow; ++k)
    world_from_keyframe.emplace_back(Yaw(0.0), (k * 2.5) * Eigen::Vector3d::UnitY());
  world_from_keyframe.front() = world_from_then;
  world_from_keyframe.back() = TransformPose(drift, world_from_now);

  auto bearing_in = [&](const Rigid3d& world_from_rig, const Eigen::Vector3d& p, int* camera) {
    // The camera whose axis is closest to the point, and the noisy bearing there.
    double best = -2.0;
    Eigen::Vector3d result = Eigen::Vector3d::UnitZ();
    for (size_t c = 0; c < rig.cameras.size(); ++c) {
      const Eigen::Vector3d in_cam = (rig.cameras[c].cam_from_rig * world_from_rig.Inverse()) * p;
      const double cosine = in_cam.normalized().z();
      if (cosine > best) {
        best = cosine;
        *camera = static_cast<int>(c);
        result = in_cam.normalized();
      }
    }
    const Eigen::Vector3d jitter(noise(rng), noise(rng), noise(rng));
    return Eigen::Vector3d((result + jitter).normalized());
  };
  const int facade_camera = 1;  // looks at azimuth 72°: the houses on the left
  LoopMatches matches, exact;
  int facade = 0;
  for (size_t i = 0; i < street.points_in_world.size(); ++i) {
    const Eigen::Vector3d& p = street.points_in_world[i];
    const Eigen::Vector3d sight = p - world_from_then.translation;
    const Eigen::Vector3d across =
        Eigen::AngleAxisd(angle(rng), sight.normalized()) * sight.unitOrthogonal();
    int camera_then = 0, camera_now = 0, camera_exact = 0;
    const Eigen::Vector3d bearing_then = bearing_in(world_from_then, p, &camera_then);
    // Exactly repeated, for the control below.
    exact.bearings_then.push_back(bearing_then);
    exact.cameras_then.push_back(camera_then);
    exact.bearings_now.push_back(bearing_in(world_from_now, p + period, &camera_exact));
    exact.cameras_now.push_back(camera_exact);
    matches.bearings_then.push_back(bearing_then);
    matches.cameras_then.push_back(camera_then);
    if (camera_then == facade_camera) {
      ++facade;
      const Eigen::Vector3d repeated = p + period + off(rng) * across;
      matches.bearings_now.push_back(bearing_in(world_from_now, repeated, &camera_now));
      if (i % 2 == 0) {  // half of them with map points
        matches.points_then.push_back(p);
        matches.points_now.push_back(drift * repeated);
        matches.tracks.emplace_back(1000 + static_cast<int>(i), static_cast<int>(i));
      }
    } else {
      // Elsewhere a look-alike: the match lands on some other point of the same camera.
      const Eigen::Vector3d elsewhere =
          world_from_now * (rig.cameras[camera_exact].cam_from_rig.Inverse() *
                            Eigen::Vector3d(off(rng) * 4.0 * std::cos(angle(rng)),
                                            off(rng) * 4.0 * std::sin(angle(rng)), 1.0) *
                            (3.0 + 9.0 * off(rng)));
      matches.bearings_now.push_back(bearing_in(world_from_now, elsewhere, &camera_now));
    }
    matches.cameras_now.push_back(camera_now);
  }
  ASSERT_GT(facade, 40);
  const LoopClosureOptions options;
  const LoopDetector detector(rig, options.detection);
  const LoopVerification v = VerifyLoop(rig, detector.ring(), 0, matches, world_from_keyframe, 0,
                                        Revisit::kNow, options, 1);
  // The similarity alone would have closed this loop (the former verification) ...
  EXPECT_GE(v.similarity_inliers, options.min_inliers);
  EXPECT_LT(v.drift_share, options.max_drift_share);
  // ... the relative pose refuses it.
  EXPECT_FALSE(v.accepted);
  EXPECT_EQ(v.refusal.rfind("relative pose", 0), 0u) << v.refusal;
  EXPECT_LT(v.relative_inliers, options.min_relative_inlier_ratio * v.matches);

  // Control: the same street exactly repeated everywhere is a consistent geometry for the
  // relative pose (only the drift bound could tell), so the refusal above is the mismatch's.
  exact.points_now = matches.points_now;
  exact.points_then = matches.points_then;
  exact.tracks = matches.tracks;
  const LoopVerification control =
      VerifyLoop(rig, detector.ring(), 0, exact, world_from_keyframe, 0, Revisit::kNow, options, 1);
  EXPECT_GE(control.relative_inliers, 0.9 * control.matches);
}

TEST(LoopVerification, RefusesWhenTheSimilarityAndTheRelativePoseDisagreeOnTheRotation) {
  // The matched map points of the revisit fit a similarity that turns it `turn` rad more than
  // the bearings do (wrong 3-D matches of a rigid look-alike). 0.033 rad: the look-alike place
  // of the paper drive that a 0.05 rad bound let through; 0.002 rad: what true loops show.
  for (const double angle : {0.2, 0.033, 0.002}) {
    SCOPED_TRACE(angle);
    Revisit r = MakeRevisit(LadybugLikeRig(), 0.0, 11);
    const Eigen::Vector3d centre = r.world_from_keyframe.back().translation;
    const Sim3d turn(1.0, Yaw(angle), centre - Yaw(angle) * centre);
    for (Eigen::Vector3d& p : r.matches.points_now) p = turn * p;
    const LoopClosureOptions options;
    const LoopDetector detector(r.rig, options.detection);
    const LoopVerification v =
        VerifyLoop(r.rig, detector.ring(), ExpectedShift(detector.ring()), r.matches,
                   r.world_from_keyframe, 0, Revisit::kNow, options, 1);
    EXPECT_GE(v.relative_inliers, options.min_relative_inliers);
    EXPECT_GE(v.similarity_inliers, options.min_inliers);
    EXPECT_NEAR(v.rotation_disagreement, angle, 0.01);  // the revisit's own noise: ~0.005
    EXPECT_EQ(v.accepted, angle < 0.01) << v.refusal;
  }
}

TEST(LoopWithinReach, IsTheDriftBoundPlusTheReachBeforeAnyMatching) {
  // 1 m steps out along x for 25 keyframes, then back on a parallel line `side` away: keyframe
  // 50 is `side` from keyframe 0 after a path of 49 + hypot(1, side).
  auto there_and_back = [](double side) {
    std::vector<Rigid3d> poses;
    for (int i = 0; i <= 50; ++i)
      poses.emplace_back(Eigen::Quaterniond::Identity(),
                         i <= 25 ? Eigen::Vector3d(i, 0.0, 0.0) : Eigen::Vector3d(50 - i, side, 0));
    return poses;
  };
  LoopClosureOptions options;  // reach: 10 % of the path + 10 mean steps
  EXPECT_TRUE(LoopWithinReach(there_and_back(0.0), 0, 50, options));
  // side 20: path 69.02, reach 6.90 + 13.80 = 20.70.
  EXPECT_TRUE(LoopWithinReach(there_and_back(20.0), 0, 50, options));
  // side 30: path 79.02, reach 7.90 + 15.80 = 23.70.
  EXPECT_FALSE(LoopWithinReach(there_and_back(30.0), 0, 50, options));
  options.revisit_reach_keyframes = 20.0;  // 7.90 + 31.61
  EXPECT_TRUE(LoopWithinReach(there_and_back(30.0), 0, 50, options));
  // Straight on: keyframe 20 is 20 m from keyframe 0 after 20 m (reach 2 + 10 m).
  EXPECT_FALSE(LoopWithinReach(there_and_back(0.0), 0, 20, LoopClosureOptions()));
  EXPECT_FALSE(LoopWithinReach(there_and_back(0.0), 20, 20, LoopClosureOptions()));
}

TEST(LoopClosureOptions, CheckNamesTheBadField) {
  EXPECT_EQ(LoopClosureOptions().Check(), "");
  LoopClosureOptions options;
  options.min_relative_inlier_ratio = 1.5;
  EXPECT_NE(options.Check().find("min_relative_inlier_ratio"), std::string::npos);
  options = LoopClosureOptions();
  options.max_rotation_disagreement = 0.0;
  EXPECT_NE(options.Check().find("max_rotation_disagreement"), std::string::npos);
  options = LoopClosureOptions();
  options.central_relative_pose.ransac.max_angle_error = -1.0;
  EXPECT_NE(options.Check().find("central_relative_pose"), std::string::npos);
}

TEST(LoopDetectorQuery, BestCandidatesAreThePairwiseScoresBest) {
  const Rig rig = LadybugLikeRig();
  LoopDetectionOptions options;
  options.min_keyframe_gap = 5;
  options.min_score = 0.1;
  LoopDetector detector(rig, options);
  std::mt19937 rng(3);
  std::normal_distribution<float> value(0.0f, 1.0f);
  auto random_descriptor = [&] {
    PlaceDescriptor d;
    for (size_t c = 0; c < rig.cameras.size(); ++c) {
      std::vector<float> v(48);
      float sum = 0.0f, norm = 0.0f;
      for (float& x : v) sum += (x = value(rng));
      for (float& x : v) {
        x -= sum / v.size();
        norm += x * x;
      }
      for (float& x : v) x /= std::sqrt(norm);
      d.cameras.push_back(v);
    }
    return d;
  };
  std::vector<PlaceDescriptor> stored;
  for (int k = 0; k < 60; ++k) {
    stored.push_back(random_descriptor());
    detector.Add(stored.back());
  }
  // A query that resembles keyframes 7 and 30 (turned by 2 and 4 ring cameras).
  PlaceDescriptor query = random_descriptor();
  const std::vector<int>& ring = detector.ring();
  for (int i = 0; i < 5; ++i)
    for (size_t j = 0; j < 48; ++j)
      query.cameras[ring[i]][j] = 0.6f * stored[7].cameras[ring[(i + 2) % 5]][j] +
                                  0.4f * stored[30].cameras[ring[(i + 4) % 5]][j];
  const int before = 50;  // keyframes 0..45 may be candidates
  const std::vector<LoopCandidate> best = detector.QueryBest(query, before, 3);
  // Brute force over the pairwise scores.
  std::vector<LoopCandidate> all;
  for (int k = 0; k <= before - options.min_keyframe_gap; ++k)
    for (int s = 0; s < 5; ++s) {
      const double score = detector.Score(query, stored[k], s);
      if (score >= options.min_score) all.push_back({k, s, score});
    }
  std::sort(all.begin(), all.end(),
            [](const LoopCandidate& a, const LoopCandidate& b) { return a.score > b.score; });
  ASSERT_GE(best.size(), 2u);
  EXPECT_EQ(best[0].keyframe, 7);
  EXPECT_EQ(best[0].shift, 2);
  EXPECT_NEAR(best[0].score, all[0].score, 1e-5);
  EXPECT_EQ(best[1].keyframe, 30);
  EXPECT_EQ(best[1].shift, 4);
  EXPECT_NEAR(best[1].score, detector.Score(query, stored[30], 4), 1e-5);
  EXPECT_EQ(detector.Query(query, before).keyframe, 7);
  // Keyframes too recent are never candidates.
  for (const LoopCandidate& c : detector.QueryBest(query, 10, 60)) EXPECT_LE(c.keyframe, 5);
}

}  // namespace
}  // namespace omni
