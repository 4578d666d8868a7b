#include "sfm/absolute_pose_central.h"

#include <cassert>
#include <opengv/absolute_pose/CentralAbsoluteAdapter.hpp>
#include <opengv/sac_problems/absolute_pose/AbsolutePoseSacProblem.hpp>

#include "calib/error.h"
#include "sfm/absolute_pose_ransac.h"

namespace omni {

RansacResult EstimateCentralAbsolutePose(const std::vector<Eigen::Vector3d>& bearings,
                                         const std::vector<Eigen::Vector3d>& points_in_world,
                                         const CentralAbsolutePoseOptions& options,
                                         Rigid3d* world_from_cam, const PosePrior* prior) {
  assert(bearings.size() == points_in_world.size());
  ThrowIfInvalid(options.Check(), "CentralAbsolutePoseOptions");
  using Problem = opengv::sac_problems::absolute_pose::AbsolutePoseSacProblem;
  const opengv::bearingVectors_t f = internal::ToOpengvVectors(bearings);
  const opengv::points_t points(points_in_world.begin(), points_in_world.end());
  opengv::absolute_pose::CentralAbsoluteAdapter adapter(f, points);
  auto problem = std::make_shared<Problem>(adapter, Problem::KNEIP, /*randomSeed=*/false);
  opengv::transformation_t model;
  const internal::AbsolutePoseScorer scorer(bearings, points_in_world);
  const RansacResult result = internal::RunAbsolutePoseRansac(
      problem, scorer, internal::AngleToOpengvScore(options.ransac.max_angle_error), options.ransac,
      &model, prior, nullptr,
      internal::AngleToOpengvScore(options.consensus_angle_factor *
                                   options.ransac.max_angle_error));
  if (result.success) *world_from_cam = internal::FromOpengvTransformation(model);
  return result;
}

}  // namespace omni
