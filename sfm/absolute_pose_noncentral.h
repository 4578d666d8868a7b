#pragma once
// Absolute pose (resection) of a non-central rig from bearing-to-point correspondences with the
// rig's true cam_from_rig offsets: GP3P (Kneip, through OpenGV) in RANSAC, or the central P3P's
// hypotheses scored with the offsets, refined on the inliers with the offsets.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/ransac.h"

namespace omni {

struct NoncentralAbsolutePoseOptions {
  RansacOptions ransac;
  // The RANSAC's hypotheses from the central P3P on the bearings turned into the rig's axes, as
  // seen from the cameras' mean centre (a far cheaper minimal solver than GP3P), each scored
  // with the true offsets; the best one refined on its inliers with the true offsets, and its
  // inliers selected again. False: GP3P with the true offsets.
  bool central_hypotheses = false;

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
