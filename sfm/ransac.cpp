#include "sfm/ransac.h"

#include <cmath>

namespace omni {

std::string RansacOptions::Check() const {
  if (!(max_angle_error > 0.0 && max_angle_error < M_PI / 2))
    return "max_angle_error: expected an angle in (0, pi/2) radians";
  if (max_iterations < 1) return "max_iterations: expected at least 1";
  if (!(confidence > 0.0 && confidence < 1.0)) return "confidence: expected a value in (0, 1)";
  if (min_inliers < 0) return "min_inliers: expected a non-negative count";
  return {};
}

}  // namespace omni
