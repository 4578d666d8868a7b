#pragma once
// Triangulation of one point from several rays (optical centre + bearing, both in the world
// frame): the point nearest to all rays in the least-squares sense (midpoint method), then
// the checks that decide whether it is kept (minimum ray angle, positive depth in
// every view, small angular error).

#include <Eigen/Core>
#include <cmath>
#include <string>
#include <vector>

namespace omni {

struct WorldRay {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();      // optical centre, world frame
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // unit bearing rotated to the world
};

struct TriangulationOptions {
  // Largest angle between two rays, seen from the point, must exceed this (radians; 2° as
  // Mouragnon et al. keep only well-conditioned points).
  double min_ray_angle = 2.0 * M_PI / 180.0;
  // Every ray's angle to the direction from its centre to the point must stay below this.
  double max_angle_error = 0.004;
  // Gauss-Newton iterations on the angular errors after the linear midpoint solution.
  int refine_iterations = 5;

  std::string Check() const;
};

enum class TriangulationStatus {
  kOk,
  kTooFewRays,  // fewer than two rays
  kDegenerate,  // parallel rays: the least-squares system is singular
  kSmallAngle,  // largest ray angle below min_ray_angle
  kBehind,      // negative depth along some ray
  kLargeError,  // some ray's angular error above max_angle_error
};
const char* TriangulationStatusName(TriangulationStatus status);

TriangulationStatus TriangulatePoint(const std::vector<WorldRay>& rays,
                                     const TriangulationOptions& options,
                                     Eigen::Vector3d* point_in_world);

}  // namespace omni
