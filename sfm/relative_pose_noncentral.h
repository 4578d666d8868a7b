#pragma once
// Relative pose of two views of a non-central rig from bearing correspondences, with the rig's
// true cam_from_rig offsets: seventeen-point linear solver or ge (Kneip's eigen-solver), through
// OpenGV, in RANSAC. The translation is metric (the offsets fix the scale) when the motion and
// the offsets make it observable.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/ransac.h"

namespace omni {

struct NoncentralRelativePoseOptions {
  enum class Solver { kSeventeenPoint, kGe, kSixPoint };
  Solver solver = Solver::kSeventeenPoint;
  RansacOptions ransac;

  std::string Check() const {
    const std::string problem = ransac.Check();
    return problem.empty() ? problem : "ransac." + problem;
  }
};

// Correspondence i: bearings1[i] in camera cameras1[i] of view 1 and bearings2[i] in camera
// cameras2[i] of view 2 see the same point. On success rig1_from_rig2 maps the rig frame of
// view 2 to the rig frame of view 1.
RansacResult EstimateNoncentralRelativePose(
    const Rig& rig, const std::vector<Eigen::Vector3d>& bearings1, const std::vector<int>& cameras1,
    const std::vector<Eigen::Vector3d>& bearings2, const std::vector<int>& cameras2,
    const NoncentralRelativePoseOptions& options, Rigid3d* rig1_from_rig2);

}  // namespace omni
