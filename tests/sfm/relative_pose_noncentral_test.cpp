#include "sfm/relative_pose_noncentral.h"

#include <gtest/gtest.h>

#include "sfm/synthetic.h"
#include "tests/sfm/test_util.h"

namespace omni {
namespace {

struct Case {
  NoncentralRelativePoseOptions::Solver solver;
  uint32_t seed;
};

class NoncentralRelativePoseTest : public ::testing::TestWithParam<Case> {};

TEST_P(NoncentralRelativePoseTest, RecoversMetricPoseWithOutliers) {
  // Five side cameras and one up, 0.5 m from the rig origin: offsets large for the 2–8 m
  // scene, so that the scale of the motion is observable.
  const Rig rig = MakeSyntheticRingRig(5, true, 0.5);
  const Rigid3d world_from_rig0(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(1.0, 2.0, 0.0));
  const Rigid3d world_from_rig1(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d(0.1, 0.2, 1.0).normalized())),
      Eigen::Vector3d(1.8, 2.6, 0.2));
  test::TwoViewSceneOptions two_view;
  two_view.num_points = 400;
  two_view.min_depth = 2.0;
  two_view.max_depth = 8.0;
  two_view.noise = 0.0002;
  two_view.outlier_ratio = 0.1;
  two_view.seed = GetParam().seed;
  const SyntheticMatches matches =
      test::MakeTwoViewMatches(rig, world_from_rig0, world_from_rig1, two_view);
  ASSERT_GT(matches.bearings1.size(), 200u);

  NoncentralRelativePoseOptions options;
  options.solver = GetParam().solver;
  options.ransac.max_angle_error = 0.002;
  options.ransac.seed = GetParam().seed;
  Rigid3d rig1_from_rig2;
  const RansacResult result =
      EstimateNoncentralRelativePose(rig, matches.bearings1, matches.cameras1, matches.bearings2,
                                     matches.cameras2, options, &rig1_from_rig2);
  ASSERT_TRUE(result.success);

  const Rigid3d expected = world_from_rig0.Inverse() * world_from_rig1;
  EXPECT_LT(RotationAngleBetween(rig1_from_rig2.rotation, expected.rotation), 0.005);
  // Metric translation: within 5 % of the 1 m motion.
  EXPECT_LT((rig1_from_rig2.translation - expected.translation).norm(),
            0.05 * expected.translation.norm());
  test::ExpectMaskMatchesTruth(result.inlier_mask, matches.is_outlier, 0.9);
}

INSTANTIATE_TEST_SUITE_P(
    Solvers, NoncentralRelativePoseTest,
    ::testing::Values(Case{NoncentralRelativePoseOptions::Solver::kSeventeenPoint, 1},
                      Case{NoncentralRelativePoseOptions::Solver::kSeventeenPoint, 5},
                      Case{NoncentralRelativePoseOptions::Solver::kGe, 2}));

}  // namespace
}  // namespace omni
