// The ray walk of DelaunayMesh (paper §4.4) against a brute-force segment–tetrahedron
// intersection over every cell.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <random>
#include <set>

#include "surface/delaunay.h"

namespace omni {
namespace {

// Whether the segment a→b crosses the interior of the tetrahedron (clipping the parameter
// interval by the four half-spaces). Touching at a point is not crossing.
bool SegmentCrossesTetrahedron(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                               const std::array<Eigen::Vector3d, 4>& t) {
  double lo = 0.0, hi = 1.0;
  for (int k = 0; k < 4; ++k) {
    const Eigen::Vector3d& p0 = t[(k + 1) % 4];
    Eigen::Vector3d normal = (t[(k + 2) % 4] - p0).cross(t[(k + 3) % 4] - p0);
    if (normal.dot(t[k] - p0) < 0) normal = -normal;  // pointing inside
    const double fa = normal.dot(a - p0), fb = normal.dot(b - p0);
    // Inside where fa + s (fb − fa) ≥ 0.
    if (fa < 0 && fb < 0) return false;
    if (fa < 0) lo = std::max(lo, fa / (fa - fb));
    if (fb < 0) hi = std::min(hi, fa / (fa - fb));
  }
  return hi - lo > 1e-9;
}

// The corners of each cell.
std::vector<std::array<Eigen::Vector3d, 4>> Tetrahedra(const DelaunayMesh& mesh,
                                                       const std::vector<CellKey>& cells) {
  std::vector<std::array<Eigen::Vector3d, 4>> tets;
  for (const CellKey& c : cells)
    tets.push_back(
        {mesh.Position(c[0]), mesh.Position(c[1]), mesh.Position(c[2]), mesh.Position(c[3])});
  return tets;
}

TEST(DelaunayWalk, VisitsExactlyTheCellsTheSegmentCrosses) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  size_t checked = 0, cells_visited = 0;
  for (int trial = 0; trial < 4; ++trial) {
    DelaunayMesh mesh;
    const int n = 300;
    for (int i = 0; i < n; ++i) mesh.Insert(Eigen::Vector3d(u(rng), u(rng), u(rng)), i);
    ASSERT_TRUE(mesh.IsValid());
    const std::vector<CellKey> cells = mesh.FiniteCells();
    const std::vector<std::array<Eigen::Vector3d, 4>> tets = Tetrahedra(mesh, cells);
    for (int ray = 0; ray < 60; ++ray) {
      const int from = static_cast<int>(rng() % n);
      // Targets well inside the hull (the camera centres are inside the Steiner grid).
      const Eigen::Vector3d target(0.6 * u(rng), 0.6 * u(rng), 0.6 * u(rng));
      const std::vector<CellKey> walked = mesh.Walk(from, target);
      std::set<CellKey> walked_set(walked.begin(), walked.end());
      EXPECT_EQ(walked_set.size(), walked.size()) << "a cell visited twice";
      std::set<CellKey> expected;
      for (size_t c = 0; c < cells.size(); ++c) {
        if (SegmentCrossesTetrahedron(mesh.Position(from), target, tets[c])) {
          expected.insert(cells[c]);
        }
      }
      EXPECT_EQ(walked_set, expected) << "trial " << trial << " ray " << ray;
      EXPECT_FALSE(walked.empty());
      // The walk ends in the cell holding the target.
      if (!walked.empty()) {
        const CellKey& last = walked.back();
        const std::array<Eigen::Vector3d, 4> t = {mesh.Position(last[0]), mesh.Position(last[1]),
                                                  mesh.Position(last[2]), mesh.Position(last[3])};
        EXPECT_TRUE(
            SegmentCrossesTetrahedron(target, target + 1e-6 * (mesh.Position(from) - target), t));
      }
      ++checked;
      cells_visited += walked.size();
    }
  }
  EXPECT_GT(cells_visited, 2 * checked);  // the rays are not trivially short
}

TEST(DelaunayWalk, TraceRayIncrementsTheCellsOfTheWalk) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  DelaunayMesh mesh;
  for (int i = 0; i < 200; ++i) mesh.Insert(Eigen::Vector3d(u(rng), u(rng), u(rng)), i);
  const Eigen::Vector3d target(0.1, 0.2, -0.1);
  const std::vector<CellKey> walked = mesh.Walk(3, target);
  mesh.TraceRay(3, target);
  mesh.TraceRay(3, target);
  const std::set<CellKey> walked_set(walked.begin(), walked.end());
  for (const CellKey& c : mesh.FiniteCells()) {
    EXPECT_EQ(mesh.Counter(c), walked_set.count(c) ? 2 : 0);
  }
}

// The walk from vertices of a cartesian grid (the Steiner grid of §3.3): the stars of such
// vertices are maximally degenerate (co-spherical, co-planar vertices), which is where the start
// of the walk (a visibility walk in the star of the point, with a search of the whole star as
// fallback) is most likely to go wrong. Checked against a brute-force segment–tetrahedron test
// over every cell.
TEST(DelaunayWalk, FromCartesianGridVerticesVisitsExactlyTheCrossedCells) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  DelaunayMesh mesh;
  const int n = 6;  // n³ grid vertices at integer coordinates 0 .. n − 1
  std::vector<int> grid;
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      for (int k = 0; k < n; ++k) grid.push_back(mesh.Insert(Eigen::Vector3d(i, j, k), -1, true));
    }
  }
  // A few points inside, some on grid planes (more degenerate stars).
  std::vector<int> points;
  for (int i = 0; i < 60; ++i) {
    Eigen::Vector3d p(0.5 + 4.0 * u(rng), 0.5 + 4.0 * u(rng), 0.5 + 4.0 * u(rng));
    if (i % 3 == 0) p.z() = std::round(p.z());
    points.push_back(mesh.Insert(p, i));
  }
  ASSERT_TRUE(mesh.IsValid());
  const std::vector<CellKey> cells = mesh.FiniteCells();
  const std::vector<std::array<Eigen::Vector3d, 4>> tets = Tetrahedra(mesh, cells);
  size_t rays = 0, visited = 0, from_hull = 0;
  for (int ray = 0; ray < 300; ++ray) {
    // From grid vertices (hull vertices included: their stars hold infinite cells) and points,
    // to generic targets inside the grid.
    const bool from_grid = ray % 2 == 0;
    const int from = from_grid ? grid[rng() % grid.size()] : points[rng() % points.size()];
    const Eigen::Vector3d target(0.2 + 4.6 * u(rng), 0.2 + 4.6 * u(rng), 0.2 + 4.6 * u(rng));
    const Eigen::Vector3d p = mesh.Position(from);
    if (p.minCoeff() == 0.0 || p.maxCoeff() == n - 1) ++from_hull;
    const std::vector<CellKey> walked = mesh.Walk(from, target);
    const std::set<CellKey> walked_set(walked.begin(), walked.end());
    EXPECT_EQ(walked_set.size(), walked.size()) << "a cell visited twice, ray " << ray;
    std::set<CellKey> expected;
    for (size_t c = 0; c < cells.size(); ++c) {
      if (SegmentCrossesTetrahedron(p, target, tets[c])) expected.insert(cells[c]);
    }
    EXPECT_EQ(walked_set, expected) << "ray " << ray;
    ++rays;
    visited += walked.size();
  }
  EXPECT_GT(from_hull, 20u);     // the fallback of the start (infinite cells in the star) ran
  EXPECT_GT(visited, 3 * rays);  // the rays are not trivially short
}

}  // namespace
}  // namespace omni
