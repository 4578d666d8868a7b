#pragma once
// The observed part of δO, what surface.ply holds (docs/design.md §6, §10). δO is closed: to
// stay the border of a solid it roofs the sky over the streets and caps the ends of the sculpted
// region with triangles that no point bounds (long slivers between far points, and triangles with
// a Steiner vertex). The observed mesh keeps the triangles of δO bounded by SfM points and seen
// from their rays, then drops the fewest triangles around the vertices where that left two
// boundary loops touching, so that it is an oriented 2-manifold with boundary whose triangles are
// a subset of δO's. Plain data: no CGAL.

#include <Eigen/Core>
#include <cstddef>
#include <string>
#include <vector>

#include "calib/ply.h"

namespace omni {

struct ObservedMeshOptions {
  // A triangle with an edge longer than max_edge_factor × s (s: the sculptor's scale, the mean
  // distance between consecutive keyframe centres) is dropped: a triangle bounded by points spans
  // the spacing of the points, a ceiling triangle spans the street; the growth below brings back
  // the longer triangles that continue a kept plane. 0: no bound.
  double max_edge_factor = 1.4;
  // A triangle whose longest edge subtends at most max_edge_angle (radians) from the nearest
  // optical centre of its vertices' rays passes the edge bounds whatever its length: points far
  // from the cameras are sparse in metres but not in the images, so a far facade spans longer
  // edges than max_edge_factor × s allows, while the ceiling over a street spans a wide angle
  // from the cameras that saw its corners. 0: off.
  double max_edge_angle = 0.0;
  // A triangle with an edge longer than max_spacing_factor × the local point spacing (the larger
  // of its vertices' spacings; a vertex's spacing is its shortest δO edge to another point) is
  // dropped: the bound follows the density of the points where s does not. 0: no bound.
  double max_spacing_factor = 0.0;
  // Drop a triangle that none of the optical centres of its vertices' rays sees from its front
  // (the free side δO faces): cos of the angle between its normal and the direction to the centre
  // above min_view_cosine. Off: only the edges and the Steiner vertices decide.
  bool require_seen = true;
  double min_view_cosine = 0.0;
  // Growth past the edge bound: a triangle dropped for its edges alone (bounded by points and
  // seen) joins when it shares an edge with a kept triangle whose normal is within
  // grow_max_normal_angle (radians) of its own and its longest edge is at most
  // grow_max_edge_factor × s, repeated from the triangles that joined: a sparse facade or
  // ground continues its plane, while the ceiling over a street and the caps meet the facades
  // at about a right angle. 0: off. With the edge bound at 1.4 s instead of 2 s (1.75 s in
  // `reconstruct`), higher F-scores and a lower tail on the perfect SfM's and the SfM's points
  // (docs/figures.md F63).
  double grow_max_edge_factor = 4.0;
  double grow_max_normal_angle = 0.2;
  // After the manifold repair, components (through shared vertices) with fewer triangles are
  // dropped. 0 or 1: none.
  int min_component_triangles = 0;

  std::string Check() const;
};

// Why the triangles of δO were left out of the observed mesh (each counted by the first reason).
struct ObservedMeshStats {
  size_t closed_triangles = 0;  // triangles of δO
  size_t steiner = 0;           // a Steiner vertex
  size_t long_edges = 0;        // max_edge_factor (and not within max_edge_angle)
  size_t grown = 0;             // dropped by max_edge_factor alone, kept by the growth
  size_t sparse = 0;            // max_spacing_factor
  size_t unseen = 0;            // require_seen
  size_t manifold_repair = 0;   // around the vertices where two boundary loops touched
  size_t small_components = 0;  // min_component_triangles
  size_t triangles = 0;         // kept
};

// A vertex of δO: an SfM point with the optical centres of its rays, or a Steiner vertex
// (origins null).
struct ObservedVertex {
  const std::vector<Eigen::Vector3d>* origins = nullptr;
};

// The observed mesh of the closed δO `closed` (one ObservedVertex per vertex), at scale s. Its
// vertices are those of the kept triangles, in their order in `closed`; kept_vertices, when
// given, receives the index in `closed` of each. Colours of `closed`, if any, follow their
// vertices.
TriangleMesh SelectObservedMesh(const TriangleMesh& closed,
                                const std::vector<ObservedVertex>& vertices, double scale,
                                const ObservedMeshOptions& options,
                                std::vector<int>* kept_vertices = nullptr,
                                ObservedMeshStats* stats = nullptr);

// `triangles` (indices below num_vertices) must be a subset of the triangles of a closed,
// oriented 2-manifold: each edge is then in at most two of them, used once each way, and the
// link of a vertex is its whole cycle or disjoint paths. Wherever it is several paths (boundary
// loops touching at the vertex), the triangles of every fan but the largest are dropped, again
// at the vertices that changed, until each link is one cycle or one path: an oriented
// 2-manifold with boundary; the others keep their order. Returns how many were dropped.
size_t RepairTouchingBoundaries(std::vector<Eigen::Vector3i>* triangles, size_t num_vertices);

}  // namespace omni
