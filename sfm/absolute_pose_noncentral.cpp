#include "sfm/absolute_pose_noncentral.h"

#include <cassert>
#include <opengv/absolute_pose/CentralAbsoluteAdapter.hpp>
#include <opengv/absolute_pose/NoncentralAbsoluteAdapter.hpp>
#include <opengv/sac_problems/absolute_pose/AbsolutePoseSacProblem.hpp>

#include "calib/error.h"
#include "sfm/absolute_pose_ransac.h"
#include "sfm/opengv_rig.h"

namespace omni {

RansacResult EstimateNoncentralAbsolutePose(const Rig& rig,
                                            const std::vector<Eigen::Vector3d>& bearings,
                                            const std::vector<int>& cameras,
                                            const std::vector<Eigen::Vector3d>& points_in_world,
                                            const NoncentralAbsolutePoseOptions& options,
                                            Rigid3d* world_from_rig, const PosePrior* prior) {
  assert(bearings.size() == points_in_world.size() && cameras.size() == bearings.size());
  ThrowIfInvalid(options.Check(), "NoncentralAbsolutePoseOptions");
  using Problem = opengv::sac_problems::absolute_pose::AbsolutePoseSacProblem;
  const opengv::bearingVectors_t f = internal::ToOpengvVectors(bearings);
  const opengv::points_t points(points_in_world.begin(), points_in_world.end());
  opengv::translations_t cam_offsets;
  opengv::rotations_t cam_rotations;
  internal::ToOpengvRig(rig, &cam_offsets, &cam_rotations);
  opengv::transformation_t model;
  const internal::AbsolutePoseScorer scorer(bearings, points_in_world, &cameras, &cam_rotations,
                                            &cam_offsets);
  const double threshold = internal::AngleToOpengvScore(options.ransac.max_angle_error);
  RansacResult result;
  if (options.central_hypotheses) {
    // The bearings in the rig's axes, from the mean camera centre.
    opengv::bearingVectors_t rig_bearings(f.size());
    for (size_t i = 0; i < f.size(); ++i) rig_bearings[i] = cam_rotations[cameras[i]] * f[i];
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const opengv::translation_t& offset : cam_offsets) centre += offset;
    centre /= static_cast<double>(cam_offsets.size());
    opengv::absolute_pose::CentralAbsoluteAdapter adapter(rig_bearings, points);
    auto problem = std::make_shared<Problem>(adapter, Problem::KNEIP, /*randomSeed=*/false);
    result = internal::RunAbsolutePoseRansac(problem, scorer, threshold, options.ransac, &model,
                                             prior, &centre);
  } else {
    opengv::absolute_pose::NoncentralAbsoluteAdapter adapter(f, cameras, points, cam_offsets,
                                                             cam_rotations);
    auto problem = std::make_shared<Problem>(adapter, Problem::GP3P, /*randomSeed=*/false);
    result =
        internal::RunAbsolutePoseRansac(problem, scorer, threshold, options.ransac, &model, prior);
  }
  if (result.success) *world_from_rig = internal::FromOpengvTransformation(model);
  return result;
}

}  // namespace omni
