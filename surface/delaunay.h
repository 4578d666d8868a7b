#pragma once
// The 3D Delaunay triangulation T of the sculpting (paper §2–§3), behind a plain interface:
// vertices are indexed in insertion order, a cell is named by the sorted indices of its four
// vertices (CellKey, -1 for the infinite vertex). It carries the per-cell state of the paper
// (ray counter, creation date, membership of O) and implements the ray walk (§4.4), the
// manifold tests (§3.1) and the extraction of the surface δO. CGAL stays in the .cpp files.

#include <Eigen/Core>
#include <array>
#include <cstddef>
#include <memory>
#include <vector>

#include "calib/ply.h"

namespace omni {

using CellKey = std::array<int, 4>;  // sorted vertex indices; -1 is the infinite vertex

// Numbers of vertices, edges and triangles of a cell that lie in |δO| (paper §3.1).
struct ManifoldCounts {
  int vertices = 0;
  int edges = 0;
  int triangles = 0;
  bool operator==(const ManifoldCounts& o) const {
    return vertices == o.vertices && edges == o.edges && triangles == o.triangles;
  }
};

struct TriangulationCounts {
  size_t vertices = 0;                      // finite vertices
  size_t edges = 0, facets = 0, cells = 0;  // all, infinite ones included
  size_t finite_edges = 0, finite_facets = 0, finite_cells = 0;
};

class DelaunayMesh {
 public:
  struct Impl;  // internal (surface/internal/cgal_delaunay.h)

  DelaunayMesh();
  ~DelaunayMesh();
  DelaunayMesh(DelaunayMesh&&) noexcept;
  DelaunayMesh& operator=(DelaunayMesh&&) noexcept;

  // Inserts a point (located from the previous insertion as a hint) and returns its vertex
  // index; a point equal to an existing vertex returns that vertex's index. `point` is the
  // caller's id (-1 for Steiner vertices).
  int Insert(const Eigen::Vector3d& position, int point = -1, bool steiner = false);
  size_t NumVertices() const;
  Eigen::Vector3d Position(int vertex) const;

  bool IsValid() const;  // CGAL's combinatorial and geometric (Delaunay) validity
  TriangulationCounts Counts() const;
  std::vector<CellKey> FiniteCells() const;

  // The cells crossed by the segment from vertex `from` to `target`, in walk order (paper §4.4).
  std::vector<CellKey> Walk(int from, const Eigen::Vector3d& target) const;
  // Walks the segment and increments the counter of every cell crossed.
  void TraceRay(int from, const Eigen::Vector3d& target);
  int Counter(const CellKey& cell) const;

  // O membership (cell must be finite) and the manifold tests of §3.1.
  void SetInO(const CellKey& cell, bool in_o);
  bool InO(const CellKey& cell) const;
  ManifoldCounts CountsInSurface(const CellKey& cell) const;
  // Subtraction test if the cell is in O, addition test otherwise.
  bool SingleCellTest(const CellKey& cell) const;
  bool GeneralTest(int vertex) const;
  size_t NumInO() const;
  size_t NumSurfaceTriangles() const;

  // δO as a triangle list, triangles counter-clockwise seen from O (the free space), vertices
  // compacted to those on the surface.
  TriangleMesh ExtractSurface() const;

  Impl* impl() { return impl_.get(); }  // for surface/*.cpp only (Impl is internal)
  const Impl* impl() const { return impl_.get(); }

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace omni
