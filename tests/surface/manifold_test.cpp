// The manifold tests of paper §3.1 (subtraction, addition, general) on triangulations of
// random points, checked against each other and against the independent CheckMesh.

#include <gtest/gtest.h>

#include <algorithm>
#include <map>
#include <random>

#include "calib/mesh_check.h"
#include "surface/delaunay.h"

namespace omni {
namespace {

using Triplet = std::tuple<int, int, int>;

Triplet AsTriplet(const ManifoldCounts& k) { return {k.vertices, k.edges, k.triangles}; }

bool HasSurfaceFacet(const DelaunayMesh& mesh, const CellKey& c) {
  return mesh.CountsInSurface(c).triangles > 0;
}

TEST(ManifoldCheck, TetrahedronIsAnOrientedSphereAndTwoSharingAVertexIsNot) {
  TriangleMesh tet;
  tet.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  tet.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  MeshCheckReport r = CheckMesh(tet);
  EXPECT_TRUE(r.ok) << r.Summary();
  EXPECT_EQ(r.euler_characteristic, 2);
  tet.triangles[3] = {1, 3, 2};  // flipped
  r = CheckMesh(tet);
  EXPECT_TRUE(r.closed_manifold);
  EXPECT_FALSE(r.ok);
  // Two tetrahedra glued at one vertex: the vertex link is two cycles.
  TriangleMesh two;
  two.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {-1, 0, 0}, {0, -1, 0}, {0, 0, -1}};
  two.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3},
                   {0, 4, 5}, {0, 6, 4}, {0, 5, 6}, {4, 6, 5}};
  r = CheckMesh(two);
  EXPECT_EQ(r.boundary_edges + r.nonmanifold_edges, 0);
  EXPECT_EQ(r.vertices_link_not_cycle, 1);
  EXPECT_FALSE(r.closed_manifold);
  // An open triangle.
  TriangleMesh open;
  open.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  open.triangles = {{0, 1, 2}};
  EXPECT_FALSE(CheckMesh(open).closed_manifold);
}

// Random walk on O: toggle random cells near δO; after each toggle the single-cell test's
// verdict must match the general test at the cell's vertices and the independent check.
TEST(ManifoldTests, SingleCellTestsAgreeWithGeneralTestAndIndependentCheck) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  DelaunayMesh mesh;
  const int n = 120;
  for (int i = 0; i < n; ++i) mesh.Insert(Eigen::Vector3d(u(rng), u(rng), u(rng)), i);
  ASSERT_TRUE(mesh.IsValid());
  const std::vector<CellKey> cells = mesh.FiniteCells();
  std::map<Triplet, int> allowed_add, allowed_sub, forbidden;
  int forbidden_but_manifold = 0, toggles = 0;
  for (int step = 0; step < 3000; ++step) {
    const CellKey& c = cells[rng() % cells.size()];
    if (mesh.NumInO() > 0 && !HasSurfaceFacet(mesh, c) && rng() % 4 != 0) continue;
    const bool was_in = mesh.InO(c);
    const ManifoldCounts counts = mesh.CountsInSurface(c);
    const bool single = mesh.SingleCellTest(c);
    // The fast single-cell test agrees with the full counts of §3.1.
    const std::vector<ManifoldCounts> allowed_counts = {
        {0, 0, 0}, {3, 3, 1}, {4, 5, 2}, {4, 6, 3}, {4, 6, 4}};
    EXPECT_EQ(single, std::find(allowed_counts.begin(), allowed_counts.end(), counts) !=
                          allowed_counts.end());
    mesh.SetInO(c, !was_in);
    bool general = true;
    for (int v : c) general = general && mesh.GeneralTest(v);
    MeshCheckOptions empty_allowed;  // a toggle may leave no surface at all
    empty_allowed.allow_empty = true;
    const MeshCheckReport report = CheckMesh(mesh.ExtractSurface(), empty_allowed);
    // The surface was a manifold before the toggle, so the general test at the cell's vertices
    // decides whether it still is.
    EXPECT_EQ(general, report.ok) << report.Summary();
    // The single-cell test accepts exactly the toggles that keep the manifold here.
    EXPECT_EQ(single, general) << "counts " << counts.vertices << counts.edges << counts.triangles;
    EXPECT_EQ(mesh.NumSurfaceTriangles(), static_cast<size_t>(report.triangles));
    if (single) {
      EXPECT_TRUE(general) << "allowed counts " << counts.vertices << counts.edges
                           << counts.triangles << " broke the manifold";
      (was_in ? allowed_sub : allowed_add)[AsTriplet(counts)]++;
    } else {
      forbidden[AsTriplet(counts)]++;
      if (general) ++forbidden_but_manifold;
    }
    if (!general) {
      mesh.SetInO(c, was_in);  // undo: keep O's border manifold
    } else {
      ++toggles;
    }
  }
  const std::vector<Triplet> allowed = {{0, 0, 0}, {3, 3, 1}, {4, 5, 2}, {4, 6, 3}, {4, 6, 4}};
  std::string seen;
  for (const auto& [t, count] : allowed_add)
    seen += "+(" + std::to_string(std::get<0>(t)) + std::to_string(std::get<1>(t)) +
            std::to_string(std::get<2>(t)) + "):" + std::to_string(count) + " ";
  for (const auto& [t, count] : allowed_sub)
    seen += "-(" + std::to_string(std::get<0>(t)) + std::to_string(std::get<1>(t)) +
            std::to_string(std::get<2>(t)) + "):" + std::to_string(count) + " ";
  for (const auto& [t, count] : forbidden)
    seen += "x(" + std::to_string(std::get<0>(t)) + std::to_string(std::get<1>(t)) +
            std::to_string(std::get<2>(t)) + "):" + std::to_string(count) + " ";
  std::cout << "cases: " << seen << " forbidden_but_manifold=" << forbidden_but_manifold
            << " toggles=" << toggles << "\n";
  for (const Triplet& t : allowed) {
    EXPECT_GT(allowed_add[t] + allowed_sub[t], 0)
        << "allowed case (" << std::get<0>(t) << "," << std::get<1>(t) << "," << std::get<2>(t)
        << ") never met";
  }
  EXPECT_GE(forbidden.size(), 3u) << "too few kinds of forbidden cases met";
  EXPECT_GT(mesh.NumInO(), 0u);
}

}  // namespace
}  // namespace omni
