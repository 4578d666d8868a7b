#pragma once
// Options and result shared by the RANSAC pose wrappers (one problem per file:
// relative_pose_central.h, relative_pose_noncentral.h, absolute_pose_central.h,
// absolute_pose_noncentral.h). Every threshold is an angle between an observed bearing and the
// bearing predicted by the model, so that it means the same for every camera model.

#include <cstdint>
#include <string>
#include <vector>

#include "calib/pose.h"

namespace omni {

struct RansacOptions {
  // An observation is an inlier when the angle between its bearing and the model's predicted
  // bearing is below this (radians; 0.002 rad ≈ 1 pixel at a focal length of 500 px). For the
  // relative problems, the sum over both views of (1 − cos angle) is compared with
  // 2 (1 − cos max_angle_error).
  double max_angle_error = 0.002;
  int max_iterations = 1000;
  double confidence = 0.999;  // stop once P(an all-inlier sample was drawn) reaches this
  bool refine = true;         // non-linear refinement of the best model on its inliers
  int min_inliers = 0;        // below this count the estimate fails (0: the minimal sample size)
  uint32_t seed = 1;

  std::string Check() const;
};

// The range of the absolute-pose options' consensus_angle_factor (and of the tracker's, which
// also takes 0 for "by mode"): counting within at least the inliers' angle, at most 100 times.
inline bool ValidConsensusAngleFactor(double factor) { return factor >= 1.0 && factor <= 100.0; }

// A pose tried before the resection's RANSAC (the motion model's prediction, or the frame's
// earlier resection): its inliers at the RANSAC's threshold, the pose refined on them and the
// inliers selected again (twice, each kept only when it has at least as many), are the estimate
// without any sampling when they are at least accept_inliers (and the RANSAC's minimum).
// Otherwise the RANSAC runs as without it.
struct PosePrior {
  Rigid3d pose;  // in the frame the estimate is in (world_from_rig; central: world_from_cam)
  int accept_inliers = 0;
};

struct RansacResult {
  bool success = false;
  std::vector<char> inlier_mask;  // one per input correspondence
  int num_inliers = 0;
  int num_iterations = 0;
  bool from_prior = false;  // the PosePrior was taken (no sampling)
};

}  // namespace omni
