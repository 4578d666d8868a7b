#pragma once
// Absolute pose (resection) of a central camera from bearing-to-point correspondences: P3P
// (Kneip, through OpenGV) in RANSAC, refined on the inliers.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "sfm/ransac.h"

namespace omni {

struct CentralAbsolutePoseOptions {
  RansacOptions ransac;

  std::string Check() const {
    const std::string problem = ransac.Check();
    return problem.empty() ? problem : "ransac." + problem;
  }
};

// bearings[i] (unit, camera frame) observes points_in_world[i]. On success world_from_cam is
// the camera's pose. A prior (sfm/ransac.h) is tried before the RANSAC. For a rig in central mode
// the "camera" is the rig's central frame.
RansacResult EstimateCentralAbsolutePose(const std::vector<Eigen::Vector3d>& bearings,
                                         const std::vector<Eigen::Vector3d>& points_in_world,
                                         const CentralAbsolutePoseOptions& options,
                                         Rigid3d* world_from_cam, const PosePrior* prior = nullptr);

}  // namespace omni
