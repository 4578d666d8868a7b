#include "sfm/relative_pose_central.h"

#include <cassert>
#include <opengv/relative_pose/CentralRelativeAdapter.hpp>
#include <opengv/sac_problems/relative_pose/CentralRelativePoseSacProblem.hpp>

#include "calib/error.h"
#include "sfm/opengv_ransac.h"

namespace omni {

RansacResult EstimateCentralRelativePose(const std::vector<Eigen::Vector3d>& bearings1,
                                         const std::vector<Eigen::Vector3d>& bearings2,
                                         const CentralRelativePoseOptions& options,
                                         Rigid3d* cam1_from_cam2) {
  assert(bearings1.size() == bearings2.size());
  ThrowIfInvalid(options.Check(), "CentralRelativePoseOptions");
  using Problem = opengv::sac_problems::relative_pose::CentralRelativePoseSacProblem;
  const opengv::bearingVectors_t f1 = internal::ToOpengvVectors(bearings1);
  const opengv::bearingVectors_t f2 = internal::ToOpengvVectors(bearings2);
  opengv::relative_pose::CentralRelativeAdapter adapter(f1, f2);
  const auto algorithm = options.solver == CentralRelativePoseOptions::Solver::kNister
                             ? Problem::NISTER
                             : Problem::STEWENIUS;
  auto problem = std::make_shared<Problem>(adapter, algorithm, /*randomSeed=*/false);
  opengv::transformation_t model;
  const RansacResult result = internal::RunOpengvRansac(
      problem, bearings1.size(), problem->getSampleSize(),
      2.0 * internal::AngleToOpengvScore(options.ransac.max_angle_error), options.ransac, &model);
  if (result.success) {
    *cam1_from_cam2 = internal::FromOpengvTransformation(model);
    const double norm = cam1_from_cam2->translation.norm();
    if (norm > 0.0) cam1_from_cam2->translation /= norm;
  }
  return result;
}

}  // namespace omni
