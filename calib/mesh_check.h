#pragma once
// The one topological check of a triangle mesh, used by mesh-check, eval, surface, reconstruct
// and the sculptor's tests: is it a closed (or, when allowed, bounded), consistently oriented
// 2-manifold without degenerate or duplicate triangles, and what are its components, Euler
// characteristic and genus. It sees only the triangles, independently of any bookkeeping of
// the code that made them.

#include <string>
#include <vector>

#include "calib/ply.h"

namespace omni {

struct MeshCheckOptions {
  // A triangle is degenerate when it repeats a vertex index or when its area is at most
  // degenerate_area_ratio times the square of its longest edge (zero area up to rounding).
  double degenerate_area_ratio = 1e-12;
  // Accept boundary edges (a 2-manifold with boundary) in MeshCheckReport::ok.
  bool allow_boundary = false;
  // Accept a mesh without any triangle in MeshCheckReport::ok (the empty surface of a
  // sculptor that has not carved anything yet).
  bool allow_empty = false;
  // Largest number of components listed one by one in the report (the totals count all).
  int max_listed_components = 20;

  std::string Check() const;
};

struct MeshComponentReport {
  long vertices = 0;
  long edges = 0;
  long triangles = 0;
  long euler_characteristic = 0;  // V - E + F
  bool closed = false;            // every edge in exactly two triangles
  bool manifold = false;          // no edge in more than two triangles, every vertex link one
                                  // cycle (or one path on the boundary)
  bool oriented = false;          // every edge with two triangles used once in each direction
  int genus = -1;                 // (2 - χ) / 2 when closed, manifold and oriented; else -1
};

struct MeshCheckReport {
  long vertices = 0;               // in the vertex list
  long unreferenced_vertices = 0;  // in no triangle
  long triangles = 0;
  long degenerate_triangles = 0;      // repeated index or zero area
  long repeated_index_triangles = 0;  // of which repeat an index (left out of the topology)
  long edges = 0;                     // distinct undirected edges
  long boundary_edges = 0;            // in one triangle
  // The loops of boundary edges: the independent cycles of the graph of the boundary edges
  // (its edges − vertices + components), one per hole of a 2-manifold with boundary.
  long boundary_loops = 0;
  long nonmanifold_edges = 0;        // in more than two triangles
  long misoriented_edges = 0;        // in two triangles that use it in the same direction
  long duplicate_triangles = 0;      // same vertex set as another triangle
  long vertices_link_not_cycle = 0;  // referenced vertices whose link is not one cycle
  long nonmanifold_vertices = 0;     // link neither one cycle nor one path
  long components = 0;               // connected through shared vertices
  long euler_characteristic = 0;     // V - E + F over referenced vertices
  long closed_components = 0;
  long genus = -1;  // sum over components when every one has a genus; else -1
  std::vector<MeshComponentReport> listed_components;  // largest first

  bool closed_manifold = false;  // no boundary, no non-manifold edge or vertex
  bool oriented = false;         // no misoriented edge
  bool ok = false;  // 2-manifold (closed unless allowed), oriented, no degenerate or duplicate
                    // triangle, not empty (unless allowed)

  // The figures on one line, for a log or a test failure.
  std::string Summary() const;
  // One line per figure, for the terminal.
  std::string ToText() const;
  // A JSON object with every field.
  std::string ToJson() const;
};

// Throws InputError when a triangle indexes a vertex that does not exist.
MeshCheckReport CheckMesh(const TriangleMesh& mesh, const MeshCheckOptions& options = {});

}  // namespace omni
