#pragma once
// INTERNAL to surface/*.cpp: step 6 of the sculpting (paper §4.6), genus refinement
// (surface/genus_refinement.cpp) and incremental smoothing (surface/smoothing.cpp), called by
// the sculptor after step 5 on the cells where O may have changed in the keyframe.

#include <Eigen/Core>
#include <functional>
#include <limits>
#include <unordered_map>
#include <vector>

#include "calib/ply.h"
#include "surface/internal/cgal_delaunay.h"
#include "surface/sculptor.h"

namespace omni::internal {

struct GenusRefinementResult {
  size_t free_before = 0, free_after = 0;  // region cells of F outside O
  size_t groups = 0;                       // groups added at once (edge stars and larger)
  long euler_change = 0;                   // Δχ of δO
};

// Adds groups of cells of F \ O of `region` to O while δO stays a 2-manifold (see
// GenusRefinementOptions), then grows one cell at once from them inside the region.
// `in_region` tells the membership of any cell.
GenusRefinementResult RefineGenus(DelaunayMesh::Impl& t, const std::vector<CellHandle>& region,
                                  const std::function<bool(CellHandle)>& in_region,
                                  const GenusRefinementOptions& options);

struct SmoothingResult {
  size_t vertices = 0;  // δO vertices recomputed
  size_t rejected = 0;  // moves rejected (flip, degenerate or local intersection)
};

// The smoothed positions of the δO vertices, kept beside T (whose vertices never move).
class SurfaceSmoother {
 public:
  // Recomputes the δO vertices of `region` inside B_radius(centre) whose umbrella changed since
  // the last call, and their δO neighbours in the ball. No other vertex moves.
  SmoothingResult Update(const DelaunayMesh::Impl& t, const std::vector<CellHandle>& region,
                         const Eigen::Vector3d& centre, double radius,
                         const SmoothingOptions& options);
  // The same on the given vertices (any order, no duplicate) instead of those of a region:
  // the caller names the vertices whose umbrella may have changed.
  SmoothingResult UpdateVertices(const DelaunayMesh::Impl& t, std::vector<VertexHandle> vertices,
                                 const Eigen::Vector3d& centre, double radius,
                                 const SmoothingOptions& options);
  // δO at the smoothed positions, triangles counter-clockwise seen from O.
  TriangleMesh Extract(const DelaunayMesh::Impl& t) const;
  Eigen::Vector3d Position(VertexHandle v) const;

 private:
  std::unordered_map<int, Eigen::Vector3d> moved_;  // by vertex index, when not at its point
  std::unordered_map<int, uint64_t> umbrella_;      // by vertex index: hash of its δO umbrella
};

}  // namespace omni::internal
