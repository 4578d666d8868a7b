#include "sfm/triangulation.h"

#include <Eigen/Dense>
#include <cmath>

#include "calib/error.h"

namespace omni {
namespace {

double AngleBetweenVectors(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

}  // namespace

std::string TriangulationOptions::Check() const {
  if (!(min_ray_angle >= 0.0 && min_ray_angle < M_PI))
    return "min_ray_angle: expected an angle in [0, pi) radians";
  if (!(max_angle_error > 0.0 && max_angle_error < M_PI))
    return "max_angle_error: expected an angle in (0, pi) radians";
  if (refine_iterations < 0) return "refine_iterations: expected a non-negative count";
  return {};
}

const char* TriangulationStatusName(TriangulationStatus status) {
  switch (status) {
    case TriangulationStatus::kOk:
      return "ok";
    case TriangulationStatus::kTooFewRays:
      return "too few rays";
    case TriangulationStatus::kDegenerate:
      return "degenerate";
    case TriangulationStatus::kSmallAngle:
      return "small ray angle";
    case TriangulationStatus::kBehind:
      return "behind a camera";
    case TriangulationStatus::kLargeError:
      return "large angular error";
  }
  return "unknown";
}

TriangulationStatus TriangulatePoint(const std::vector<WorldRay>& rays,
                                     const TriangulationOptions& options,
                                     Eigen::Vector3d* point_in_world) {
  ThrowIfInvalid(options.Check(), "TriangulationOptions");
  if (rays.size() < 2) return TriangulationStatus::kTooFewRays;

  // Midpoint: minimise sum_i |(I - d_i d_i^T)(X - c_i)|^2, i.e.
  // (sum_i P_i) X = sum_i P_i c_i with P_i = I - d_i d_i^T.
  Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (const WorldRay& ray : rays) {
    const Eigen::Vector3d d = ray.direction.normalized();
    const Eigen::Matrix3d projector = Eigen::Matrix3d::Identity() - d * d.transpose();
    normal += projector;
    rhs += projector * ray.center;
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(normal);
  // Parallel rays leave a null direction: the smallest eigenvalue is then ~0 (it is
  // ~ n sin^2(angle) / 2 for two rays at that angle).
  if (!(eigen.eigenvalues()(0) > 1e-12 * eigen.eigenvalues()(2)))
    return TriangulationStatus::kDegenerate;
  Eigen::Vector3d point = normal.ldlt().solve(rhs);

  // Gauss-Newton on the tangent-plane angular residuals r_i = P_i (X - c_i) / |X - c_i|
  // (first-order angle between the ray and the direction to the point).
  for (int iteration = 0; iteration < options.refine_iterations; ++iteration) {
    Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
    Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
    bool behind = false;
    for (const WorldRay& ray : rays) {
      const Eigen::Vector3d d = ray.direction.normalized();
      const Eigen::Vector3d v = point - ray.center;
      const double depth = v.norm();
      if (depth <= 0.0 || v.dot(d) <= 0.0) {
        behind = true;
        break;
      }
      const Eigen::Matrix3d projector = Eigen::Matrix3d::Identity() - d * d.transpose();
      const Eigen::Vector3d r = projector * v / depth;
      // d r / d X ≈ P / depth (the derivative of 1/depth is second order near the solution).
      const Eigen::Matrix3d jacobian = projector / depth;
      jtj += jacobian.transpose() * jacobian;
      jtr += jacobian.transpose() * r;
    }
    if (behind) break;
    const Eigen::Vector3d step = jtj.ldlt().solve(-jtr);
    if (!step.allFinite()) break;
    point += step;
    if (step.norm() < 1e-12 * (1.0 + point.norm())) break;
  }

  double max_angle = 0.0;
  for (size_t i = 0; i < rays.size(); ++i) {
    const Eigen::Vector3d vi = point - rays[i].center;
    if (vi.dot(rays[i].direction) <= 0.0) return TriangulationStatus::kBehind;
    if (AngleBetweenVectors(vi, rays[i].direction) > options.max_angle_error)
      return TriangulationStatus::kLargeError;
    for (size_t j = i + 1; j < rays.size(); ++j)
      max_angle = std::max(max_angle, AngleBetweenVectors(vi, point - rays[j].center));
  }
  if (max_angle < options.min_ray_angle) return TriangulationStatus::kSmallAngle;
  *point_in_world = point;
  return TriangulationStatus::kOk;
}

}  // namespace omni
