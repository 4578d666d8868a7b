#include "sfm/relative_pose_central.h"

#include <gtest/gtest.h>

#include "sfm/synthetic.h"
#include "tests/calib/options_error_check.h"
#include "tests/sfm/test_util.h"

namespace omni {
namespace {

struct Case {
  CentralRelativePoseOptions::Solver solver;
  uint32_t seed;
};

class CentralRelativePoseTest : public ::testing::TestWithParam<Case> {};

TEST_P(CentralRelativePoseTest, RecoversKnownPoseWithOutliers) {
  const Rig rig = MakeSyntheticRingRig(1, false, 0.0);  // one camera at the rig origin
  const Rigid3d world_from_rig0;
  const Rigid3d world_from_rig1(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.2, Eigen::Vector3d(0.3, 1.0, -0.2).normalized())),
      Eigen::Vector3d(0.2, -0.8, 0.5));
  test::TwoViewSceneOptions two_view;  // 300 points at 4–12 m, 15 % outliers
  two_view.seed = GetParam().seed;
  const SyntheticMatches matches =
      test::MakeTwoViewMatches(rig, world_from_rig0, world_from_rig1, two_view);
  ASSERT_GT(matches.bearings1.size(), 150u);

  CentralRelativePoseOptions options;
  options.solver = GetParam().solver;
  options.ransac.max_angle_error = 0.003;
  options.ransac.seed = GetParam().seed;
  Rigid3d cam1_from_cam2;
  const RansacResult result =
      EstimateCentralRelativePose(matches.bearings1, matches.bearings2, options, &cam1_from_cam2);
  ASSERT_TRUE(result.success);

  // cam1_from_cam2 = cam_from_rig * rig0_from_world * world_from_rig1 * rig_from_cam, up to
  // the scale of the translation.
  const Rigid3d& cam_from_rig = rig.cameras[0].cam_from_rig;
  const Rigid3d expected =
      cam_from_rig * world_from_rig0.Inverse() * world_from_rig1 * cam_from_rig.Inverse();
  EXPECT_LT(RotationAngleBetween(cam1_from_cam2.rotation, expected.rotation), 0.002);
  EXPECT_LT(AngleBetween(cam1_from_cam2.translation, expected.translation), 0.01);
  EXPECT_NEAR(cam1_from_cam2.translation.norm(), 1.0, 1e-9);
  test::ExpectMaskMatchesTruth(result.inlier_mask, matches.is_outlier, 0.95);
}

INSTANTIATE_TEST_SUITE_P(Solvers, CentralRelativePoseTest,
                         ::testing::Values(Case{CentralRelativePoseOptions::Solver::kStewenius, 1},
                                           Case{CentralRelativePoseOptions::Solver::kStewenius, 7},
                                           Case{CentralRelativePoseOptions::Solver::kNister, 3}));

TEST(CentralRelativePose, FailsWithTooFewCorrespondences) {
  const std::vector<Eigen::Vector3d> bearings(4, Eigen::Vector3d::UnitZ());
  Rigid3d cam1_from_cam2;
  const RansacResult result = EstimateCentralRelativePose(
      bearings, bearings, CentralRelativePoseOptions(), &cam1_from_cam2);
  EXPECT_FALSE(result.success);
  EXPECT_EQ(result.inlier_mask.size(), 4u);
}

TEST(RansacOptions, CheckRejectsBadValues) {
  RansacOptions options;
  EXPECT_TRUE(options.Check().empty());
  options.max_angle_error = 0.0;
  EXPECT_FALSE(options.Check().empty());
  options = RansacOptions();
  options.confidence = 1.0;
  EXPECT_FALSE(options.Check().empty());
}

TEST(CentralRelativePose, BadOptionsThrowNamingTheField) {
  CentralRelativePoseOptions options;
  options.ransac.max_angle_error = 0.0;
  Rigid3d cam1_from_cam2;
  EXPECT_TRUE(testing::ThrowsOptionsError(
      [&] { EstimateCentralRelativePose({}, {}, options, &cam1_from_cam2); },
      "CentralRelativePoseOptions.ransac.max_angle_error"));
}

}  // namespace
}  // namespace omni
