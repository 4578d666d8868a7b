// The resection's RANSAC (sfm/absolute_pose_ransac.h: hypotheses in parallel batches, counts
// that stop once they cannot win, the refinement on analytic derivatives) against OpenGV's
// sequential opengv::sac::Ransac and its refinement (sfm/opengv_ransac.h) on the same problem
// and seed: the same iterations and inliers, the same model.

#include "sfm/absolute_pose_ransac.h"

#include <gtest/gtest.h>

#include <opengv/absolute_pose/CentralAbsoluteAdapter.hpp>
#include <opengv/absolute_pose/NoncentralAbsoluteAdapter.hpp>

#include "sfm/opengv_rig.h"
#include "sfm/synthetic.h"

namespace omni {
namespace {

using Problem = opengv::sac_problems::absolute_pose::AbsolutePoseSacProblem;

struct Frame {
  std::vector<Eigen::Vector3d> bearings, points;
  std::vector<int> cameras;
};

Frame FrameOf(const Rig& rig, double outlier_ratio, uint32_t seed) {
  SyntheticSceneOptions options;
  options.num_points = 300;
  options.noise = 0.0005;
  options.outlier_ratio = outlier_ratio;
  options.seed = seed;
  const Rigid3d world_from_rig1(
      Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(0.2, -0.1, 1.0).normalized())),
      Eigen::Vector3d(0.7, 0.4, 0.1));
  const SyntheticScene scene = MakeSyntheticScene(rig, {Rigid3d(), world_from_rig1}, options);
  Frame frame;
  for (const SyntheticObservation& o : scene.observations) {
    if (o.frame != 1) continue;
    frame.bearings.push_back(o.bearing);
    frame.points.push_back(scene.points_in_world[o.point]);
    frame.cameras.push_back(o.camera);
  }
  return frame;
}

// The refinements differ (OpenGV: numerical derivatives; here: analytic) but reach the same
// minimum of a flat (quartic) cost: the refined models agree to 1e-5 (metres, rotation entries:
// 0.005 pixel at 500 px, far below the noise of 5e-4 rad), the inliers exactly.
void ExpectSameEstimate(const RansacResult& sequential, const opengv::transformation_t& expected,
                        const RansacResult& batched, const opengv::transformation_t& model,
                        bool refined) {
  ASSERT_EQ(batched.success, sequential.success);
  EXPECT_EQ(batched.num_iterations, sequential.num_iterations);
  EXPECT_EQ(batched.num_inliers, sequential.num_inliers);
  EXPECT_EQ(batched.inlier_mask, sequential.inlier_mask);
  if (sequential.success) {
    EXPECT_LT((model - expected).cwiseAbs().maxCoeff(), refined ? 1e-5 : 1e-12);
  }
}

// OpenGV's sequential RANSAC and the batched one on the same problem: the same estimate.
void ExpectBatchedAsSequential(opengv::absolute_pose::AbsoluteAdapterBase& adapter,
                               Problem::algorithm_t algorithm,
                               const internal::AbsolutePoseScorer& scorer, uint32_t seed,
                               bool refine) {
  RansacOptions options;
  options.seed = seed;
  options.refine = refine;
  const double threshold = internal::AngleToOpengvScore(options.max_angle_error);
  auto problem = std::make_shared<Problem>(adapter, algorithm, false);
  opengv::transformation_t expected, model;
  const RansacResult sequential =
      internal::RunOpengvRansac(problem, adapter.getNumberCorrespondences(),
                                problem->getSampleSize(), threshold, options, &expected);
  auto again = std::make_shared<Problem>(adapter, algorithm, false);
  const RansacResult batched =
      internal::RunAbsolutePoseRansac(again, scorer, threshold, options, &model);
  ExpectSameEstimate(sequential, expected, batched, model, refine);
  EXPECT_TRUE(sequential.success);
}

class AbsolutePoseRansacTest : public ::testing::TestWithParam<std::tuple<double, uint32_t, bool>> {
};

TEST_P(AbsolutePoseRansacTest, CentralGivesOpengvsSequentialEstimate) {
  const auto [outliers, seed, refine] = GetParam();
  const Frame frame = FrameOf(MakeSyntheticRingRig(1, false, 0.0), outliers, seed);
  ASSERT_GT(frame.bearings.size(), 100u);
  const opengv::bearingVectors_t f(frame.bearings.begin(), frame.bearings.end());
  const opengv::points_t p(frame.points.begin(), frame.points.end());
  opengv::absolute_pose::CentralAbsoluteAdapter adapter(f, p);
  const internal::AbsolutePoseScorer scorer(frame.bearings, frame.points);
  ExpectBatchedAsSequential(adapter, Problem::KNEIP, scorer, seed, refine);
}

TEST_P(AbsolutePoseRansacTest, NoncentralGivesOpengvsSequentialEstimate) {
  const auto [outliers, seed, refine] = GetParam();
  const Rig rig = MakeSyntheticRingRig(5, true, 0.5);
  const Frame frame = FrameOf(rig, outliers, seed);
  ASSERT_GT(frame.bearings.size(), 100u);
  const opengv::bearingVectors_t f(frame.bearings.begin(), frame.bearings.end());
  const opengv::points_t p(frame.points.begin(), frame.points.end());
  opengv::translations_t offsets;
  opengv::rotations_t rotations;
  internal::ToOpengvRig(rig, &offsets, &rotations);
  opengv::absolute_pose::NoncentralAbsoluteAdapter adapter(f, frame.cameras, p, offsets, rotations);
  const internal::AbsolutePoseScorer scorer(frame.bearings, frame.points, &frame.cameras,
                                            &rotations, &offsets);
  ExpectBatchedAsSequential(adapter, Problem::GP3P, scorer, seed, refine);
}

TEST(AbsolutePoseRansac, IterationLimitIsTheSequentialOne) {
  // Mostly outliers: the adaptive stopping would ask for more than max_iterations (so few that
  // the best model may not even reach the minimal count: both must fail alike then).
  const Frame frame = FrameOf(MakeSyntheticRingRig(1, false, 0.0), 0.7, 7);
  const opengv::bearingVectors_t f(frame.bearings.begin(), frame.bearings.end());
  const opengv::points_t p(frame.points.begin(), frame.points.end());
  opengv::absolute_pose::CentralAbsoluteAdapter adapter(f, p);
  RansacOptions options;
  options.max_iterations = 5;
  const double threshold = internal::AngleToOpengvScore(options.max_angle_error);
  auto problem = std::make_shared<Problem>(adapter, Problem::KNEIP, false);
  opengv::transformation_t expected, model;
  const RansacResult sequential = internal::RunOpengvRansac(
      problem, f.size(), problem->getSampleSize(), threshold, options, &expected);
  auto again = std::make_shared<Problem>(adapter, Problem::KNEIP, false);
  const internal::AbsolutePoseScorer scorer(frame.bearings, frame.points);
  const RansacResult batched =
      internal::RunAbsolutePoseRansac(again, scorer, threshold, options, &model);
  EXPECT_GE(sequential.num_iterations, options.max_iterations);
  ExpectSameEstimate(sequential, expected, batched, model, options.refine);
}

INSTANTIATE_TEST_SUITE_P(OutliersSeedsRefinement, AbsolutePoseRansacTest,
                         ::testing::Combine(::testing::Values(0.0, 0.3, 0.6),
                                            ::testing::Values(1u, 2u, 3u), ::testing::Bool()));

}  // namespace
}  // namespace omni
