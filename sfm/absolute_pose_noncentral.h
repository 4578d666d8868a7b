#pragma once
// Absolute pose (resection) of a non-central rig from bearing-to-point correspondences with the
// rig's true cam_from_rig offsets: GP3P (Kneip, through OpenGV) in RANSAC, refined on the
// inliers.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/ransac.h"

namespace omni {

struct NoncentralAbsolutePoseOptions {
  RansacOptions ransac;

  std::string Check() const {
    const std::string problem = ransac.Check();
    return problem.empty() ? problem : "ransac." + problem;
  }
};

// bearings[i] (unit, frame of camera cameras[i]) observes points_in_world[i]. On success
// world_from_rig is the rig's pose. A prior (sfm/ransac.h) is tried before the RANSAC.
RansacResult EstimateNoncentralAbsolutePose(const Rig& rig,
                                            const std::vector<Eigen::Vector3d>& bearings,
                                            const std::vector<int>& cameras,
                                            const std::vector<Eigen::Vector3d>& points_in_world,
                                            const NoncentralAbsolutePoseOptions& options,
                                            Rigid3d* world_from_rig,
                                            const PosePrior* prior = nullptr);

}  // namespace omni
