#pragma once
// Ray casting and closest-point queries over a TriangleMesh with Embree 3. All ray casting of
// the tree goes through this library (the evaluation's and the synthetic renderer's), and it is
// the only code that sees Embree: its types stay behind the pimpl. A scene is built once; its
// queries are const and thread-safe, batches spread over every core with TBB. Embree works in
// single precision: by default the mesh is shifted to the centre of its bounding box first, so
// city-size coordinates keep millimetre precision.

#include <Eigen/Core>
#include <limits>
#include <memory>
#include <vector>

#include "calib/ply.h"

namespace omni {

struct RayHit {
  double distance = std::numeric_limits<double>::infinity();  // along the unit direction
  int triangle = -1;                                          // -1: no hit
  // Barycentric coordinates of a ray hit on its triangle abc: the point is
  // (1 - u - v) a + u b + v c (Embree's, in single precision; zero for Closest).
  double u = 0.0;
  double v = 0.0;
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

// How the scene is built and traced. The defaults suit measurements on city-size meshes; the
// synthetic renderer traces its city as it is, coherently.
struct RayCasterOptions {
  // Shift the mesh to the centre of its bounding box before it goes to single precision.
  bool recentre = true;
  // Robust traversal: no ray slips through the shared edge of two triangles (slower).
  bool robust = true;
  // The rays of a query are coherent (one origin, neighbouring directions: a camera's pixels).
  bool coherent = false;
};

class RayCaster {
 public:
  // Rays traced together by CastPacket.
  static constexpr int kPacketSize = 8;

  // Throws InputError when the mesh has no triangle or an index out of range.
  explicit RayCaster(const TriangleMesh& mesh, const RayCasterOptions& options = {});
  ~RayCaster();
  RayCaster(RayCaster&&) noexcept;
  RayCaster& operator=(RayCaster&&) noexcept;

  // First hit of the ray within (0, max_distance].
  RayHit Cast(const Ray& ray) const;
  // Cast for kPacketSize rays traced together in one packet (faster for coherent rays):
  // hits[k] is the first hit of rays[k] when valid[k], no hit otherwise.
  void CastPacket(const Ray* rays, const bool* valid, RayHit* hits) const;
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
