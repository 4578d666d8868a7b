#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "sfm/absolute_pose_central.h"
#include "sfm/absolute_pose_noncentral.h"
#include "sfm/synthetic.h"
#include "tests/sfm/test_util.h"

namespace omni {
namespace {

// Observations of one frame: bearings, cameras, true points and outlier flags.
struct FrameObservations {
  std::vector<Eigen::Vector3d> bearings, points;
  std::vector<int> cameras;
  std::vector<char> is_outlier;
};

FrameObservations ObservationsOfFrame(const SyntheticScene& scene, int frame) {
  FrameObservations result;
  for (const SyntheticObservation& observation : scene.observations) {
    if (observation.frame != frame) continue;
    result.bearings.push_back(observation.bearing);
    result.points.push_back(scene.points_in_world[observation.point]);
    result.cameras.push_back(observation.camera);
    result.is_outlier.push_back(observation.is_outlier);
  }
  return result;
}

const Rigid3d kWorldFromRig0(Eigen::Quaterniond(Eigen::AngleAxisd(-0.4, Eigen::Vector3d::UnitZ())),
                             Eigen::Vector3d(3.0, -1.0, 0.5));
const Rigid3d kWorldFromRig1(
    Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, -0.1, 1.0).normalized())),
    Eigen::Vector3d(3.7, -0.4, 0.6));

SyntheticSceneOptions SceneOptions(uint32_t seed) {
  SyntheticSceneOptions options;
  options.num_points = 300;
  options.min_depth = 2.0;
  options.max_depth = 10.0;
  options.noise = 0.0003;
  options.outlier_ratio = 0.3;
  options.seed = seed;
  return options;
}

// The non-central resection with `hypotheses` on frame 1 of a scene seen by a ring of five
// cameras `offset` metres from the rig's centre: the rig's pose within `max_angle` radians and
// `max_distance` metres, the outliers told apart.
void ExpectNoncentralRecoversRigPose(double offset, const SyntheticSceneOptions& scene_options,
                                     NoncentralHypotheses hypotheses, double max_angle,
                                     double max_distance) {
  const Rig rig = MakeSyntheticRingRig(5, true, offset);
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, scene_options);
  const FrameObservations frame = ObservationsOfFrame(scene, 1);
  ASSERT_GT(frame.bearings.size(), 100u);

  NoncentralAbsolutePoseOptions options;
  options.ransac.seed = scene_options.seed;
  options.hypotheses = hypotheses;
  Rigid3d world_from_rig;
  const RansacResult result = EstimateNoncentralAbsolutePose(
      rig, frame.bearings, frame.cameras, frame.points, options, &world_from_rig);
  ASSERT_TRUE(result.success);
  EXPECT_LT(RotationAngleBetween(world_from_rig.rotation, kWorldFromRig1.rotation), max_angle);
  EXPECT_LT((world_from_rig.translation - kWorldFromRig1.translation).norm(), max_distance);
  test::ExpectMaskMatchesTruth(result.inlier_mask, frame.is_outlier, 0.95);
}

class AbsolutePoseTest : public ::testing::TestWithParam<uint32_t> {};

TEST_P(AbsolutePoseTest, CentralP3PRecoversCameraPoseWithOutliers) {
  const Rig rig = MakeSyntheticRingRig(1, false, 0.0);
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, SceneOptions(GetParam()));
  const FrameObservations frame = ObservationsOfFrame(scene, 1);
  ASSERT_GT(frame.bearings.size(), 100u);

  CentralAbsolutePoseOptions options;
  options.ransac.seed = GetParam();
  Rigid3d world_from_cam;
  const RansacResult result =
      EstimateCentralAbsolutePose(frame.bearings, frame.points, options, &world_from_cam);
  ASSERT_TRUE(result.success);
  const Rigid3d expected = kWorldFromRig1 * rig.cameras[0].cam_from_rig.Inverse();
  EXPECT_LT(RotationAngleBetween(world_from_cam.rotation, expected.rotation), 0.002);
  EXPECT_LT((world_from_cam.translation - expected.translation).norm(), 0.01);
  test::ExpectMaskMatchesTruth(result.inlier_mask, frame.is_outlier, 0.95);
}

TEST_P(AbsolutePoseTest, NoncentralGP3PRecoversRigPoseWithOutliers) {
  ExpectNoncentralRecoversRigPose(0.3, SceneOptions(GetParam()), NoncentralHypotheses::kGp3p, 0.002,
                                  0.01);
}

TEST_P(AbsolutePoseTest, NoncentralCameraP3PRecoversRigPoseWithOutliers) {
  // Offsets of 1 m: the hypotheses from one camera's P3P, taken to the rig by that camera's
  // offset, give the rig's pose as GP3P does, and separate the outliers.
  ExpectNoncentralRecoversRigPose(1.0, SceneOptions(GetParam()), NoncentralHypotheses::kCameraP3p,
                                  0.002, 0.01);
}

TEST_P(AbsolutePoseTest, NoncentralCameraP3PHypothesesAreExactWhereTheRigCentreP3PIsNot) {
  // Exact bearings, no outliers, no refinement, the fewest iterations: the first hypotheses are
  // the estimate. One camera's P3P taken to the rig is the rig's pose to the solver's rounding
  // (a sample mixing cameras would not be); the P3P from the cameras' mean centre is off by the
  // 1 m offsets' angles.
  const Rig rig = MakeSyntheticRingRig(5, true, 1.0);
  SyntheticSceneOptions scene_options = SceneOptions(GetParam());
  scene_options.noise = 0.0;
  scene_options.outlier_ratio = 0.0;
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, scene_options);
  const FrameObservations frame = ObservationsOfFrame(scene, 1);
  ASSERT_GT(frame.bearings.size(), 100u);

  NoncentralAbsolutePoseOptions options;
  options.ransac.seed = GetParam();
  options.ransac.refine = false;
  options.ransac.max_iterations = 1;
  options.hypotheses = NoncentralHypotheses::kCameraP3p;
  Rigid3d camera_p3p, rig_centre_p3p;
  ASSERT_TRUE(EstimateNoncentralAbsolutePose(rig, frame.bearings, frame.cameras, frame.points,
                                             options, &camera_p3p)
                  .success);
  EXPECT_LT(RotationAngleBetween(camera_p3p.rotation, kWorldFromRig1.rotation), 1e-6);
  EXPECT_LT((camera_p3p.translation - kWorldFromRig1.translation).norm(), 1e-6);
  options.hypotheses = NoncentralHypotheses::kRigCentreP3p;
  EstimateNoncentralAbsolutePose(rig, frame.bearings, frame.cameras, frame.points, options,
                                 &rig_centre_p3p);
  EXPECT_GT((rig_centre_p3p.translation - kWorldFromRig1.translation).norm(), 1e-3);
}

TEST(AbsolutePose, NoncentralCameraP3PFallsBackToGP3PWhenNoCameraHasThreeCorrespondences) {
  // Two correspondences per camera: no camera's P3P can be drawn, GP3P poses the rig.
  const Rig rig = MakeSyntheticRingRig(5, true, 0.3);
  SyntheticSceneOptions scene_options = SceneOptions(1);
  scene_options.outlier_ratio = 0.0;
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, scene_options);
  const FrameObservations all = ObservationsOfFrame(scene, 1);
  FrameObservations frame;
  std::vector<int> per_camera(rig.cameras.size(), 0);
  for (size_t i = 0; i < all.bearings.size(); ++i) {
    if (per_camera[all.cameras[i]]++ >= 2) continue;
    frame.bearings.push_back(all.bearings[i]);
    frame.points.push_back(all.points[i]);
    frame.cameras.push_back(all.cameras[i]);
  }
  ASSERT_EQ(frame.bearings.size(), 2 * rig.cameras.size());

  NoncentralAbsolutePoseOptions options;
  options.hypotheses = NoncentralHypotheses::kCameraP3p;
  Rigid3d world_from_rig;
  const RansacResult result = EstimateNoncentralAbsolutePose(
      rig, frame.bearings, frame.cameras, frame.points, options, &world_from_rig);
  ASSERT_TRUE(result.success);
  EXPECT_EQ(result.num_inliers, static_cast<int>(frame.bearings.size()));
  EXPECT_LT(RotationAngleBetween(world_from_rig.rotation, kWorldFromRig1.rotation), 0.002);
  EXPECT_LT((world_from_rig.translation - kWorldFromRig1.translation).norm(), 0.01);
}

TEST_P(AbsolutePoseTest, NoncentralFromCentralHypothesesRecoversRigPoseWithOutliers) {
  // Offsets of 5 cm, points 3 to 12 m away: the central P3P's hypotheses, scored and refined
  // with the true offsets, give the rig's pose (the central approximation alone is off by
  // centimetres: the translation is checked to 5 mm) and separate the outliers.
  SyntheticSceneOptions scene_options = SceneOptions(GetParam());
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  ExpectNoncentralRecoversRigPose(0.05, scene_options, NoncentralHypotheses::kRigCentreP3p, 0.001,
                                  0.005);
}

TEST_P(AbsolutePoseTest, NoncentralGP3PNeedsTheTrueOffsets) {
  // The same observations explained with a rig whose cameras all sit at the origin fit worse:
  // the wrapper must be using the offsets.
  const Rig rig = MakeSyntheticRingRig(5, true, 1.0);
  SyntheticSceneOptions scene_options = SceneOptions(GetParam());
  scene_options.outlier_ratio = 0.0;
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, scene_options);
  const FrameObservations frame = ObservationsOfFrame(scene, 1);
  Rig central_rig = rig;
  for (Camera& camera : central_rig.cameras) camera.cam_from_rig.translation.setZero();

  NoncentralAbsolutePoseOptions options;
  Rigid3d with_offsets, without_offsets;
  const RansacResult good = EstimateNoncentralAbsolutePose(rig, frame.bearings, frame.cameras,
                                                           frame.points, options, &with_offsets);
  const RansacResult bad = EstimateNoncentralAbsolutePose(
      central_rig, frame.bearings, frame.cameras, frame.points, options, &without_offsets);
  ASSERT_TRUE(good.success);
  EXPECT_GE(good.num_inliers, 0.98 * frame.bearings.size());
  EXPECT_LT(bad.num_inliers, 0.8 * frame.bearings.size());
}

TEST_P(AbsolutePoseTest, NoncentralPriorNearTheTruthIsTakenWithoutSampling) {
  const Rig rig = MakeSyntheticRingRig(5, true, 0.3);
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, SceneOptions(GetParam()));
  const FrameObservations frame = ObservationsOfFrame(scene, 1);
  NoncentralAbsolutePoseOptions options;
  options.ransac.seed = GetParam();
  // A prediction off by 3 cm and 0.1°: its inliers, refined on, give the pose.
  PosePrior prior;
  prior.pose = Rigid3d(kWorldFromRig1.rotation * Eigen::Quaterniond(Eigen::AngleAxisd(
                                                     0.1 * M_PI / 180, Eigen::Vector3d::UnitY())),
                       kWorldFromRig1.translation + Eigen::Vector3d(0.03, 0.0, -0.01));
  prior.accept_inliers = static_cast<int>(0.5 * frame.bearings.size());
  Rigid3d world_from_rig;
  const RansacResult result = EstimateNoncentralAbsolutePose(
      rig, frame.bearings, frame.cameras, frame.points, options, &world_from_rig, &prior);
  ASSERT_TRUE(result.success);
  EXPECT_TRUE(result.from_prior);
  EXPECT_EQ(result.num_iterations, 0);
  EXPECT_LT(RotationAngleBetween(world_from_rig.rotation, kWorldFromRig1.rotation), 0.002);
  EXPECT_LT((world_from_rig.translation - kWorldFromRig1.translation).norm(), 0.01);
  test::ExpectMaskMatchesTruth(result.inlier_mask, frame.is_outlier, 0.95);
}

TEST_P(AbsolutePoseTest, PriorFarFromTheTruthLeavesTheRansacsEstimate) {
  const Rig rig = MakeSyntheticRingRig(1, false, 0.0);
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, SceneOptions(GetParam()));
  const FrameObservations frame = ObservationsOfFrame(scene, 1);
  CentralAbsolutePoseOptions options;
  options.ransac.seed = GetParam();
  Rigid3d without, with;
  const RansacResult plain =
      EstimateCentralAbsolutePose(frame.bearings, frame.points, options, &without);
  PosePrior prior;  // the previous frame's pose: 0.9 m and 40° away
  prior.pose = kWorldFromRig0 * rig.cameras[0].cam_from_rig.Inverse();
  prior.accept_inliers = static_cast<int>(0.5 * frame.bearings.size());
  const RansacResult tried =
      EstimateCentralAbsolutePose(frame.bearings, frame.points, options, &with, &prior);
  ASSERT_TRUE(plain.success);
  ASSERT_TRUE(tried.success);
  EXPECT_FALSE(tried.from_prior);
  EXPECT_EQ(tried.num_iterations, plain.num_iterations);
  EXPECT_EQ(tried.inlier_mask, plain.inlier_mask);
  EXPECT_LT((with.translation - without.translation).norm(), 1e-12);
}

TEST(AbsolutePose, NoncentralWiderConsensusSamplesLessAndRefinesOnMore) {
  // Correspondences as the tracker's: the map points' errors spread over a few times the
  // RANSAC's angle (here a noise of that angle), and 30 % outliers. Counted within three times
  // the angle, the inliers are most of the true correspondences, so the adaptive stopping
  // draws far fewer samples, and the pose refined on them is closer to the truth; the inliers
  // returned are still those within the angle of that pose.
  const Rig rig = MakeSyntheticRingRig(5, true, 0.5);
  int iterations[2] = {0, 0};
  double distance[2] = {0.0, 0.0}, angle[2] = {0.0, 0.0};
  for (uint32_t seed = 1; seed <= 6; ++seed) {
    SyntheticSceneOptions scene_options = SceneOptions(seed);
    NoncentralAbsolutePoseOptions options;
    options.ransac.seed = seed;
    scene_options.noise = options.ransac.max_angle_error;
    const SyntheticScene scene =
        MakeSyntheticScene(rig, {kWorldFromRig0, kWorldFromRig1}, scene_options);
    const FrameObservations frame = ObservationsOfFrame(scene, 1);
    ASSERT_GT(frame.bearings.size(), 100u);
    for (int wide = 0; wide < 2; ++wide) {
      options.consensus_angle_factor = wide ? 3.0 : 1.0;
      Rigid3d world_from_rig;
      const RansacResult result = EstimateNoncentralAbsolutePose(
          rig, frame.bearings, frame.cameras, frame.points, options, &world_from_rig);
      ASSERT_TRUE(result.success) << "seed " << seed << " factor "
                                  << options.consensus_angle_factor;
      iterations[wide] += result.num_iterations;
      distance[wide] += (world_from_rig.translation - kWorldFromRig1.translation).norm();
      angle[wide] += RotationAngleBetween(world_from_rig.rotation, kWorldFromRig1.rotation);
      // The mask: exactly the correspondences within the angle of the returned pose.
      int within = 0;
      for (size_t i = 0; i < frame.bearings.size(); ++i) {
        const Camera& camera = rig.cameras[frame.cameras[i]];
        const Eigen::Vector3d seen =
            (camera.cam_from_rig * (world_from_rig.Inverse() * frame.points[i])).normalized();
        const bool inside = std::acos(std::clamp(seen.dot(frame.bearings[i]), -1.0, 1.0)) <
                            options.ransac.max_angle_error * (1.0 + 1e-9);
        // Within rounding of the angle either way: no assertion on that correspondence.
        const bool near_edge =
            std::abs(std::acos(std::clamp(seen.dot(frame.bearings[i]), -1.0, 1.0)) -
                     options.ransac.max_angle_error) < 1e-9;
        if (!near_edge) {
          EXPECT_EQ(result.inlier_mask[i] != 0, inside) << "correspondence " << i;
        }
        within += inside ? 1 : 0;
      }
      EXPECT_NEAR(result.num_inliers, within, 1);
    }
  }
  EXPECT_LT(3 * iterations[1], iterations[0]);
  EXPECT_LT(distance[1], distance[0]);
  EXPECT_LT(angle[1], angle[0]);
  // One angle for all (the default) is OpenGV's RANSAC, which absolute_pose_ransac_test.cpp
  // compares with the sequential one.
  EXPECT_EQ(NoncentralAbsolutePoseOptions().consensus_angle_factor, 1.0);
  NoncentralAbsolutePoseOptions bad;
  bad.consensus_angle_factor = 0.5;
  EXPECT_NE(bad.Check().find("consensus_angle_factor"), std::string::npos);
}

INSTANTIATE_TEST_SUITE_P(Seeds, AbsolutePoseTest, ::testing::Values(1u, 2u, 3u));

}  // namespace
}  // namespace omni
