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
  // The hypotheses are scored, and the adaptive stopping counts their inliers, within
  // ransac.max_angle_error times this; the best is refined on the correspondences within that
  // angle, then the inliers (the result's mask and count) are those within max_angle_error of it
  // refined on them. Map points a pixel or two off are right but outside a sub-pixel
  // max_angle_error: counted, they let far fewer samples find the pose, and the refinement uses
  // them. 1: one angle for all (OpenGV's RANSAC). docs/design.md §9.
  double consensus_angle_factor = 1.0;

  std::string Check() const {
    if (!ValidConsensusAngleFactor(consensus_angle_factor))
      return "consensus_angle_factor: expected 1 to 100";
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
