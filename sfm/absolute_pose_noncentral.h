#pragma once
// Absolute pose (resection) of a non-central rig from bearing-to-point correspondences with the
// rig's true cam_from_rig offsets: a RANSAC whose hypotheses come from GP3P (Kneip, through
// OpenGV) or from the central P3P (NoncentralHypotheses), scored with the offsets, the best
// refined on its inliers with the offsets.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/ransac.h"

namespace omni {

// How the resection's RANSAC makes its hypotheses. Every hypothesis is scored with the true
// offsets, and the best one refined on its inliers with them and its inliers selected again.
enum class NoncentralHypotheses {
  // GP3P (the generalised P3P) on three correspondences from any cameras, with the offsets.
  kGp3p,
  // The central P3P of one camera: three correspondences drawn from the same camera give that
  // camera's pose, taken to the rig's pose through the camera's own offset and rotation: exact
  // for the rig (no approximation of the offsets), with a far cheaper solver than GP3P. A fourth
  // correspondence, from any camera, picks among the P3P's solutions as with GP3P. When no
  // camera has three correspondences, GP3P.
  kCameraP3p,
  // The central P3P on the bearings turned into the rig's axes, as seen from the cameras' mean
  // centre: an approximation of the offsets (its hypotheses are off by the offsets' angle).
  kRigCentreP3p,
};

struct NoncentralAbsolutePoseOptions {
  RansacOptions ransac;
  // As CentralAbsolutePoseOptions::consensus_angle_factor (1: OpenGV's RANSAC).
  double consensus_angle_factor = 1.0;
  NoncentralHypotheses hypotheses = NoncentralHypotheses::kGp3p;

  std::string Check() const {
    if (!ValidConsensusAngleFactor(consensus_angle_factor))
      return "consensus_angle_factor: expected 1 to 100";
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
