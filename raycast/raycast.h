#pragma once
// Ray casting and closest-point queries over a TriangleMesh with Embree 3 (all ray
// casting of the tree goes through Embree), batches spread over every core with TBB. Embree works
// in single precision: the mesh is shifted to the centre of its bounding box first, so city-size
// coordinates keep millimetre precision.

#include <Eigen/Core>
#include <limits>
#include <memory>
#include <vector>

#include "calib/ply.h"

namespace omni {

struct RayHit {
  double distance = std::numeric_limits<double>::infinity();  // along the unit direction
  int triangle = -1;                                          // -1: no hit
  bool Hit() const { return triangle >= 0; }
};

struct Ray {
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
  Eigen::Vector3d direction = Eigen::Vector3d::UnitZ();  // unit
  double max_distance = std::numeric_limits<double>::infinity();
};

// Closest point of triangle abc to p (Ericson, Real-Time Collision Detection, 5.1.5); the
// nearest corner when the triangle is degenerate.
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c);

class RayCaster {
 public:
  // Throws InputError when the mesh has no triangle or an index out of range.
  explicit RayCaster(const TriangleMesh& mesh);
  ~RayCaster();
  RayCaster(RayCaster&&) noexcept;
  RayCaster& operator=(RayCaster&&) noexcept;

  // First hit of the ray within (0, max_distance].
  RayHit Cast(const Ray& ray) const;
  // Cast for every ray, in parallel.
  std::vector<RayHit> CastMany(const std::vector<Ray>& rays) const;
  // Closest point of the mesh within max_distance: its distance and triangle (no hit: -1).
  RayHit Closest(const Eigen::Vector3d& point,
                 double max_distance = std::numeric_limits<double>::infinity()) const;
  // Closest distance for every point, in parallel (infinity where none within max_distance).
  std::vector<double> DistancesTo(
      const std::vector<Eigen::Vector3d>& points,
      double max_distance = std::numeric_limits<double>::infinity()) const;

  // Unit normal of a triangle (counter-clockwise side), zero when degenerate.
  Eigen::Vector3d TriangleNormal(int triangle) const;
  size_t NumTriangles() const;
  // Bounding box of the mesh.
  Eigen::Vector3d MinCorner() const;
  Eigen::Vector3d MaxCorner() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace omni
