#pragma once
// INTERNAL to surface/*.cpp: step 6 of the sculpting (paper §4.6), genus refinement
// (surface/genus_refinement.cpp) and incremental smoothing (surface/smoothing.cpp), called by
// the sculptor after step 5 on the cells where O may have changed in the keyframe.

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <limits>
#include <utility>
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
  // Intersection checks run in parallel first, and those of them taken again because a vertex
  // they read was sent back meanwhile (0 with SmoothingOptions::reference_checks).
  size_t prechecked = 0, rechecked = 0;
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
  // A δO triangle (v, a, b) of the umbrella of a recomputed vertex v, counter-clockwise seen
  // from O, by vertex index, with its normal at the Delaunay positions.
  struct Triangle {
    int a, b;
    Eigen::Vector3d normal;
  };
  // A vertex recomputed in the current call; its umbrella and ring (distinct δO neighbours)
  // are ranges of triangles_ and ring_.
  struct Local {
    VertexHandle v;
    int index = -1;
    Eigen::Vector3d own, previous;
    uint32_t triangles_begin = 0, triangles_end = 0, ring_begin = 0, ring_end = 0;
    int reverts = 0;
  };
  using Facet = std::array<int, 3>;  // a δO triangle by vertex index
  // A δO triangle by vertex index, then the fourth vertex of its cell of O.
  using StarFacet = std::array<int, 4>;

  void Grow(const DelaunayMesh::Impl& t);
  // The cells around vertex `index` (a range of star_cells_), gathered once per call.
  std::pair<uint32_t, uint32_t> Star(const DelaunayMesh::Impl& t, int index);
  // The δO facets of the cells of O around vertex `index`, gathered once per call.
  std::pair<uint32_t, uint32_t> StarFacets(const DelaunayMesh::Impl& t, int index);
  // StarFacets of the vertex of `local` and of its ring (before MeetsNearby, which only reads
  // them, so that checks may run in parallel).
  void GatherStarFacets(const DelaunayMesh::Impl& t, const Local& local);
  // Whether the umbrella of `local` at the current positions meets a δO triangle of the cells
  // of O around the vertex or its ring (the vertex's triangles against the others). Without
  // `reference`, the facets around them must have been gathered (GatherStarFacets); then it
  // writes only `candidates` (scratch) and may run in parallel.
  bool MeetsNearby(const DelaunayMesh::Impl& t, const Local& local, bool reference,
                   std::vector<Facet>& candidates) const;

  // By vertex index: the output position (its point when not smoothed), whether it differs
  // from the point, and the hash of the δO umbrella (when has_umbrella_).
  std::vector<Eigen::Vector3d> out_;
  std::vector<uint8_t> moved_, has_umbrella_;
  std::vector<uint64_t> umbrella_;
  // Scratch of one call, kept for its capacity: the recomputed vertices (slot_ by vertex index,
  // valid when slot_stamp_ equals call_), their umbrellas and rings, and the δO facets around
  // the vertices met (star_ by vertex index, valid when star_stamp_ equals call_).
  uint32_t call_ = 0;
  std::vector<uint32_t> slot_stamp_, star_stamp_;
  // By vertex index: equal to call_ when a revert in this call moved the vertex or a neighbour
  // in T (a first check of a vertex is then taken again, see UpdateVertices).
  std::vector<uint32_t> dirty_stamp_;
  // The stars of Star: star_cells_range_ by vertex index, valid when star_cells_stamp_ equals
  // call_.
  std::vector<CellHandle> star_cells_;
  std::vector<std::pair<uint32_t, uint32_t>> star_cells_range_;
  std::vector<uint32_t> star_cells_stamp_;
  std::vector<uint8_t> first_check_;  // by slot: the parallel first check (0 none, 1, 2 meets)
  std::vector<int> slot_;
  std::vector<std::pair<uint32_t, uint32_t>> star_;
  std::vector<Local> locals_;
  std::vector<Triangle> triangles_;
  std::vector<int> ring_;
  std::vector<StarFacet> facets_;
  std::vector<Facet> candidates_;
};

}  // namespace omni::internal
