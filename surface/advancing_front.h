#pragma once
// A baseline for the sculptor's surface: CGAL's advancing front surface reconstruction (Cohen-
// Steiner & Da, "A greedy Delaunay-based surface reconstruction algorithm") of a point set, the
// 2-manifold-with-boundary triangles picked greedily among the Delaunay facets of the points. It
// knows no ray: no visibility, no free space. `omnisculpt surface --method advancing-front`.
// CGAL stays in advancing_front.cpp (its one translation unit).

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/ply.h"

namespace omni {

struct AdvancingFrontOptions {
  // A candidate facet is left out when its radius is more than this times the mean length of
  // the edges of the front it joins (CGAL's radius_ratio_bound; 0: no bound).
  double radius_ratio_bound = 5.0;
  // The largest angle (radians) between a candidate facet and its neighbour on the front
  // for which the facet is "plausible" (CGAL's beta, π/6 by default).
  double beta = 0.52;

  std::string Check() const;
};

// The triangle mesh over `points`: its vertices are the input points that are in a triangle, in
// their input order; its triangles as CGAL orients them. Fewer than 3 points give no triangle.
TriangleMesh AdvancingFrontSurface(const std::vector<Eigen::Vector3d>& points,
                                   const AdvancingFrontOptions& options = {});

}  // namespace omni
