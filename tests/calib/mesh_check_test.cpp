// The one mesh checker on hand-made meshes: a zero-area triangle in a closed mesh, a bounded
// mesh counted with its boundary, duplicate and empty meshes. (The evaluation's tests check it
// on boxes, spheres and tori too.)

#include "calib/mesh_check.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <utility>
#include <vector>

namespace omni {
namespace {

// A tetrahedron, triangles counter-clockwise seen from outside.
TriangleMesh Tetrahedron() {
  TriangleMesh tet;
  tet.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  return tet;
}

// A square sheet of n × n unit squares in the plane z = 0, two triangles each, counter-clockwise
// seen from +z, without the squares listed in `holes` (column, row).
TriangleMesh SheetWithHoles(int n, const std::vector<std::pair<int, int>>& holes) {
  TriangleMesh sheet;
  for (int row = 0; row <= n; ++row) {
    for (int column = 0; column <= n; ++column) sheet.vertices.emplace_back(column, row, 0.0);
  }
  auto at = [n](int column, int row) { return row * (n + 1) + column; };
  for (int row = 0; row < n; ++row) {
    for (int column = 0; column < n; ++column) {
      if (std::find(holes.begin(), holes.end(), std::make_pair(column, row)) != holes.end())
        continue;
      sheet.triangles.emplace_back(at(column, row), at(column + 1, row), at(column + 1, row + 1));
      sheet.triangles.emplace_back(at(column, row), at(column + 1, row + 1), at(column, row + 1));
    }
  }
  return sheet;
}

TEST(MeshCheck, ClosedTetrahedronIsOk) {
  const MeshCheckReport report = CheckMesh(Tetrahedron());
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_TRUE(report.closed_manifold);
  EXPECT_TRUE(report.oriented);
  EXPECT_EQ(report.euler_characteristic, 2);
  EXPECT_EQ(report.genus, 0);
  EXPECT_EQ(report.degenerate_triangles, 0);
}

TEST(MeshCheck, ZeroAreaTriangleInAClosedMeshIsDegenerate) {
  // Vertex 3 on the edge 0-1: the triangle (0, 1, 3) has zero area while the topology stays a
  // closed, oriented sphere. Every caller (mesh-check, eval, surface, reconstruct) gets the
  // same verdict from the one checker: not ok.
  TriangleMesh flat = Tetrahedron();
  flat.vertices[3] = Eigen::Vector3d(0.5, 0.0, 0.0);
  const MeshCheckReport report = CheckMesh(flat);
  EXPECT_FALSE(report.ok) << report.Summary();
  EXPECT_EQ(report.degenerate_triangles, 1);
  EXPECT_EQ(report.repeated_index_triangles, 0);
  EXPECT_TRUE(report.closed_manifold);
  EXPECT_TRUE(report.oriented);
  EXPECT_EQ(report.genus, 0);
  EXPECT_NE(report.Summary().find("degenerate=1"), std::string::npos) << report.Summary();
  // Zero area is degenerate whatever the ratio, even 0.
  MeshCheckOptions exact;
  exact.degenerate_area_ratio = 0.0;
  EXPECT_FALSE(CheckMesh(flat, exact).ok);
  // Lifted off the edge by a millimetre, the triangle has area again (a ratio of 5e-4).
  flat.vertices[3] = Eigen::Vector3d(0.5, 0.0, 1e-3);
  EXPECT_TRUE(CheckMesh(flat).ok) << CheckMesh(flat).Summary();
  MeshCheckOptions coarse;
  coarse.degenerate_area_ratio = 1e-3;
  EXPECT_EQ(CheckMesh(flat, coarse).degenerate_triangles, 1);
}

TEST(MeshCheck, RepeatedIndexIsDegenerateAndLeftOutOfTheTopology) {
  TriangleMesh mesh = Tetrahedron();
  mesh.triangles.emplace_back(0, 1, 1);
  const MeshCheckReport report = CheckMesh(mesh);
  EXPECT_FALSE(report.ok);
  EXPECT_EQ(report.degenerate_triangles, 1);
  EXPECT_EQ(report.repeated_index_triangles, 1);
  EXPECT_TRUE(report.closed_manifold);  // the other four still close the sphere
  EXPECT_EQ(report.edges, 6);
}

TEST(MeshCheck, BoundedMeshIsCountedWithItsBoundary) {
  // The tetrahedron without its face (1, 2, 3): an open cup whose rim is three edges.
  TriangleMesh cup = Tetrahedron();
  cup.triangles.pop_back();
  const MeshCheckReport report = CheckMesh(cup);
  EXPECT_FALSE(report.ok);
  EXPECT_FALSE(report.closed_manifold);
  EXPECT_TRUE(report.oriented);
  EXPECT_EQ(report.triangles, 3);
  EXPECT_EQ(report.edges, 6);
  EXPECT_EQ(report.boundary_edges, 3);
  EXPECT_EQ(report.nonmanifold_edges, 0);
  EXPECT_EQ(report.vertices_link_not_cycle, 3);  // the rim's vertices: their links are paths
  EXPECT_EQ(report.nonmanifold_vertices, 0);
  EXPECT_EQ(report.components, 1);
  EXPECT_EQ(report.closed_components, 0);
  EXPECT_EQ(report.euler_characteristic, 1);  // 4 - 6 + 3: a disc
  EXPECT_EQ(report.genus, -1);
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  const MeshCheckReport allowed = CheckMesh(cup, bounded);
  EXPECT_TRUE(allowed.ok) << allowed.Summary();
  EXPECT_EQ(allowed.boundary_edges, 3);
  EXPECT_EQ(allowed.boundary_loops, 1);
  EXPECT_EQ(CheckMesh(Tetrahedron()).boundary_loops, 0);
  // A boundary does not excuse a misoriented edge.
  std::swap(cup.triangles[0][1], cup.triangles[0][2]);
  EXPECT_FALSE(CheckMesh(cup, bounded).ok);
}

TEST(MeshCheck, BoundaryLoopsAreCountedOnePerHole) {
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  // The rim of the sheet and two holes apart from it and from each other: three loops.
  const MeshCheckReport two_holes = CheckMesh(SheetWithHoles(5, {{1, 1}, {3, 2}}), bounded);
  EXPECT_TRUE(two_holes.ok) << two_holes.Summary();
  EXPECT_EQ(two_holes.boundary_edges, 5 * 4 + 4 + 4);
  EXPECT_EQ(two_holes.boundary_loops, 3);
  EXPECT_EQ(two_holes.euler_characteristic, 1 - 2);  // a disc with two holes
  EXPECT_NE(two_holes.ToText().find("boundary loops 3\n"), std::string::npos) << two_holes.ToText();
  EXPECT_NE(two_holes.ToJson().find("\"boundary_loops\": 3"), std::string::npos);
  EXPECT_EQ(CheckMesh(SheetWithHoles(5, {}), bounded).boundary_loops, 1);
  // Two holes that touch at a corner vertex: still two loops (the cycles of the boundary
  // edges), but the shared vertex's link is two paths, so the sheet is no 2-manifold.
  const MeshCheckReport pinched = CheckMesh(SheetWithHoles(5, {{1, 1}, {2, 2}}), bounded);
  EXPECT_EQ(pinched.boundary_loops, 3);
  EXPECT_EQ(pinched.nonmanifold_vertices, 1);
  EXPECT_FALSE(pinched.ok);
}

TEST(MeshCheck, TwoTrianglesBackToBackAreDuplicatesAndNotOk) {
  // Every edge in two triangles, used once each way, every link one cycle: only the duplicate
  // count tells that this is no surface.
  TriangleMesh pillow;
  pillow.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  pillow.triangles = {{0, 1, 2}, {0, 2, 1}};
  const MeshCheckReport report = CheckMesh(pillow);
  EXPECT_TRUE(report.closed_manifold);
  EXPECT_TRUE(report.oriented);
  EXPECT_EQ(report.duplicate_triangles, 1);
  EXPECT_FALSE(report.ok) << report.Summary();
}

TEST(MeshCheck, EmptyMeshIsOkOnlyWhenAllowed) {
  EXPECT_FALSE(CheckMesh(TriangleMesh{}).ok);
  MeshCheckOptions options;
  options.allow_empty = true;
  EXPECT_TRUE(CheckMesh(TriangleMesh{}, options).ok);
  // Allowing the empty mesh changes nothing for a non-empty one.
  TriangleMesh cup = Tetrahedron();
  cup.triangles.pop_back();
  EXPECT_FALSE(CheckMesh(cup, options).ok);
}

}  // namespace
}  // namespace omni
