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
  // The largest angle (radians) between a candidate facet and its neighbour on the front
  // for which the facet is "plausible" (CGAL's beta, its default 0.52).
  double beta = 0.52;
  // A candidate facet with an edge longer than this (the points' units) is never taken (CGAL's
  // priority functor returns infinity for it); 0: no bound, CGAL's default. CGAL's other
  // parameter, radius_ratio_bound, is left at its default 5: its extend() step raises its
  // bound from 1.1 without that limit (on the short drive's COLMAP model 5, 2 and 1 gave the
  // same 138,769 triangles).
  double max_edge = 0.0;

  std::string Check() const;
};

// The triangle mesh over `points`: its vertices are the input points that are in a triangle, in
// their input order; its triangles as CGAL orients them. Fewer than 3 points give no triangle.
// *input_of_vertex, if given, receives each vertex's index in `points`.
TriangleMesh AdvancingFrontSurface(const std::vector<Eigen::Vector3d>& points,
                                   const AdvancingFrontOptions& options = {},
                                   std::vector<size_t>* input_of_vertex = nullptr);

}  // namespace omni
