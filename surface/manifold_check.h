#pragma once
// A check of a triangle list as a closed 2-manifold, written independently of the sculptor's
// bookkeeping (it sees only the triangles): every edge in exactly two triangles, the link of
// every vertex one cycle (paper §3.1, general test), and a consistent orientation (every
// directed edge used once).

#include <cstddef>
#include <string>

#include "calib/ply.h"

namespace omni {

struct ManifoldReport {
  size_t vertices = 0;  // vertices used by a triangle
  size_t edges = 0;
  size_t triangles = 0;
  size_t degenerate_triangles = 0;    // a repeated vertex index
  size_t duplicate_triangles = 0;     // the same three vertices twice
  size_t edges_not_in_two = 0;        // edges in one or more than two triangles
  size_t vertices_not_one_cycle = 0;  // vertex links that are not a single cycle
  size_t misoriented_edges = 0;       // edges whose two triangles use them in the same direction
  size_t components = 0;              // connected components (through edges)
  long euler_characteristic = 0;      // V − E + F

  bool IsManifold() const {
    return degenerate_triangles == 0 && duplicate_triangles == 0 && edges_not_in_two == 0 &&
           vertices_not_one_cycle == 0;
  }
  bool IsOrientedManifold() const { return IsManifold() && misoriented_edges == 0; }
  std::string Summary() const;
};

ManifoldReport CheckManifold(const TriangleMesh& mesh);

}  // namespace omni
