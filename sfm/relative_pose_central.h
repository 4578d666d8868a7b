#pragma once
// Relative pose of two views of a central camera from bearing correspondences: five-point
// solver (Stewenius or Nister, through OpenGV) in RANSAC.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "sfm/ransac.h"

namespace omni {

struct CentralRelativePoseOptions {
  enum class Solver { kStewenius, kNister };
  Solver solver = Solver::kStewenius;
  RansacOptions ransac;

  std::string Check() const {
    const std::string problem = ransac.Check();
    return problem.empty() ? problem : "ransac." + problem;
  }
};

// bearings1[i] (unit, view 1's frame) and bearings2[i] (view 2's frame) see the same point.
// On success, cam1_from_cam2 maps view 2's frame to view 1's; its translation has unit norm
// (the scale is not observable).
RansacResult EstimateCentralRelativePose(const std::vector<Eigen::Vector3d>& bearings1,
                                         const std::vector<Eigen::Vector3d>& bearings2,
                                         const CentralRelativePoseOptions& options,
                                         Rigid3d* cam1_from_cam2);

}  // namespace omni
