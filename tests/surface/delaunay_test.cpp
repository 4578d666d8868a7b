#include "surface/delaunay.h"

#include <gtest/gtest.h>

#include <random>

namespace omni {
namespace {

std::vector<Eigen::Vector3d> RandomPoints(int n, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Vector3d> points(n);
  for (auto& p : points) p = Eigen::Vector3d(u(rng), u(rng), u(rng));
  return points;
}

TEST(DelaunayMesh, RandomPointsGiveAValidTriangulationWithEulerRelations) {
  for (uint32_t seed : {1u, 2u, 3u}) {
    DelaunayMesh mesh;
    const auto points = RandomPoints(500, seed);
    for (size_t i = 0; i < points.size(); ++i) {
      EXPECT_EQ(mesh.Insert(points[i], static_cast<int>(i)), static_cast<int>(i));
    }
    // A point inserted twice is the same vertex.
    EXPECT_EQ(mesh.Insert(points[7]), 7);
    ASSERT_TRUE(mesh.IsValid());
    const TriangulationCounts k = mesh.Counts();
    EXPECT_EQ(k.vertices, points.size());
    // T with the infinite vertex triangulates the 3-sphere: χ = V − E + F − C = 0.
    EXPECT_EQ(static_cast<long>(k.vertices + 1) - static_cast<long>(k.edges) +
                  static_cast<long>(k.facets) - static_cast<long>(k.cells),
              0);
    // Every cell has four facets, every facet two cells.
    EXPECT_EQ(4 * k.cells, 2 * k.facets);
    // The finite part triangulates the convex hull, a 3-ball: χ = 1.
    EXPECT_EQ(static_cast<long>(k.vertices) - static_cast<long>(k.finite_edges) +
                  static_cast<long>(k.finite_facets) - static_cast<long>(k.finite_cells),
              1);
    EXPECT_EQ(mesh.FiniteCells().size(), k.finite_cells);
    for (int v = 0; v < 5; ++v) EXPECT_EQ(mesh.Position(v), points[v]);
  }
}

}  // namespace
}  // namespace omni
