#include "sfm/relative_pose_noncentral.h"

#include <cassert>
#include <opengv/relative_pose/NoncentralRelativeAdapter.hpp>
#include <opengv/sac_problems/relative_pose/NoncentralRelativePoseSacProblem.hpp>

#include "calib/error.h"
#include "sfm/opengv_ransac.h"
#include "sfm/opengv_rig.h"

namespace omni {

RansacResult EstimateNoncentralRelativePose(
    const Rig& rig, const std::vector<Eigen::Vector3d>& bearings1, const std::vector<int>& cameras1,
    const std::vector<Eigen::Vector3d>& bearings2, const std::vector<int>& cameras2,
    const NoncentralRelativePoseOptions& options, Rigid3d* rig1_from_rig2) {
  assert(bearings1.size() == bearings2.size() && cameras1.size() == bearings1.size() &&
         cameras2.size() == bearings2.size());
  ThrowIfInvalid(options.Check(), "NoncentralRelativePoseOptions");
  using Problem = opengv::sac_problems::relative_pose::NoncentralRelativePoseSacProblem;
  const opengv::bearingVectors_t f1 = internal::ToOpengvVectors(bearings1);
  const opengv::bearingVectors_t f2 = internal::ToOpengvVectors(bearings2);
  opengv::translations_t cam_offsets;
  opengv::rotations_t cam_rotations;
  internal::ToOpengvRig(rig, &cam_offsets, &cam_rotations);
  opengv::relative_pose::NoncentralRelativeAdapter adapter(f1, f2, cameras1, cameras2, cam_offsets,
                                                           cam_rotations);
  Problem::algorithm_t algorithm = Problem::SEVENTEENPT;
  if (options.solver == NoncentralRelativePoseOptions::Solver::kGe) algorithm = Problem::GE;
  if (options.solver == NoncentralRelativePoseOptions::Solver::kSixPoint)
    algorithm = Problem::SIXPT;
  auto problem = std::make_shared<Problem>(adapter, algorithm, /*asCentral=*/false,
                                           /*randomSeed=*/false);
  opengv::transformation_t model;
  const RansacResult result = internal::RunOpengvRansac(
      problem, bearings1.size(), problem->getSampleSize(),
      2.0 * internal::AngleToOpengvScore(options.ransac.max_angle_error), options.ransac, &model);
  if (result.success) *rig1_from_rig2 = internal::FromOpengvTransformation(model);
  return result;
}

}  // namespace omni
