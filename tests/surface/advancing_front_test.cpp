// CGAL's advancing front surface (the baseline of `surface --method advancing-front`) on points
// sampled on a sphere: a closed triangle mesh of the input points whose triangles lie on the
// sphere and cover it.

#include "surface/advancing_front.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <vector>

#include "calib/error.h"
#include "calib/mesh_check.h"

namespace omni {
namespace {

// n points uniform on the sphere of radius r about c.
std::vector<Eigen::Vector3d> SpherePoints(size_t n, double r, const Eigen::Vector3d& c) {
  std::mt19937 rng(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::vector<Eigen::Vector3d> points;
  for (size_t i = 0; i < n; ++i) {
    const Eigen::Vector3d d(normal(rng), normal(rng), normal(rng));
    points.push_back(c + r * d.normalized());
  }
  return points;
}

TEST(AdvancingFront, PointsOnASphereGiveAClosedMeshOnTheSphere) {
  const double r = 2.0;
  const Eigen::Vector3d c(10.0, -3.0, 1.0);
  const std::vector<Eigen::Vector3d> points = SpherePoints(2000, r, c);
  const TriangleMesh mesh = AdvancingFrontSurface(points);
  ASSERT_GT(mesh.triangles.size(), 3000u);
  // Every vertex is an input point, in the input order.
  size_t next = 0;
  for (const Eigen::Vector3d& v : mesh.vertices) {
    while (next < points.size() && points[next] != v) ++next;
    ASSERT_LT(next, points.size()) << "a vertex that is not an input point, or out of order";
  }
  // The indices it gives back name those input points, in increasing order.
  std::vector<size_t> input_of_vertex;
  const TriangleMesh indexed = AdvancingFrontSurface(points, {}, &input_of_vertex);
  ASSERT_EQ(input_of_vertex.size(), indexed.vertices.size());
  ASSERT_EQ(indexed.vertices.size(), mesh.vertices.size());
  for (size_t v = 0; v < input_of_vertex.size(); ++v) {
    ASSERT_LT(input_of_vertex[v], points.size());
    EXPECT_EQ(points[input_of_vertex[v]], indexed.vertices[v]) << "vertex " << v;
    if (v > 0) {
      EXPECT_LT(input_of_vertex[v - 1], input_of_vertex[v]);
    }
  }
  // The faces lie on the sphere: each centroid within the sag of a chord of the point spacing
  // (about 0.08 r for 2,000 points) -- a facet across the sphere's inside would be at r.
  const double spacing = std::sqrt(4.0 * M_PI * r * r / points.size());
  double area = 0.0, worst_sag = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], d = mesh.vertices[t[2]];
    const double edge = std::max({(a - b).norm(), (b - d).norm(), (d - a).norm()});
    EXPECT_LT(edge, 4.0 * spacing);
    worst_sag = std::max(worst_sag, r - ((a + b + d) / 3.0 - c).norm());
    area += 0.5 * (b - a).cross(d - a).norm();
    // Oriented outwards or inwards, the same for every face of the sphere: the normal is radial.
    const Eigen::Vector3d normal = (b - a).cross(d - a).normalized();
    EXPECT_GT(std::abs(normal.dot(((a + b + d) / 3.0 - c).normalized())), 0.8);
  }
  EXPECT_LT(worst_sag, 0.1 * r);
  EXPECT_GT(worst_sag, 0.0);
  // It covers the sphere: the area of the inscribed mesh is a little below 4 pi r^2.
  EXPECT_NEAR(area / (4.0 * M_PI * r * r), 0.99, 0.02);
  // A closed, consistently oriented 2-manifold.
  const MeshCheckReport report = CheckMesh(mesh);
  EXPECT_TRUE(report.ok) << report.ToText();
  EXPECT_GT(mesh.vertices.size(), 0.98 * points.size());
}

TEST(AdvancingFront, NoTriangleHasAnEdgeAboveTheBound) {
  const double r = 2.0;
  const std::vector<Eigen::Vector3d> points = SpherePoints(2000, r, {0, 0, 0});
  const double spacing = std::sqrt(4.0 * M_PI * r * r / points.size());
  double longest_unbounded = 0.0;
  auto longest_edge = [](const TriangleMesh& mesh) {
    double longest = 0.0;
    for (const Eigen::Vector3i& t : mesh.triangles) {
      for (int k = 0; k < 3; ++k) {
        longest = std::max(longest, (mesh.vertices[t[k]] - mesh.vertices[t[(k + 1) % 3]]).norm());
      }
    }
    return longest;
  };
  const TriangleMesh unbounded = AdvancingFrontSurface(points);
  longest_unbounded = longest_edge(unbounded);
  AdvancingFrontOptions options;
  options.max_edge = 0.6 * longest_unbounded;
  ASSERT_GT(options.max_edge, 0.5 * spacing);
  const TriangleMesh bounded = AdvancingFrontSurface(points, options);
  EXPECT_LE(longest_edge(bounded), options.max_edge);
  EXPECT_GT(bounded.triangles.size(), 0.8 * unbounded.triangles.size());
  EXPECT_LT(bounded.triangles.size(), unbounded.triangles.size());  // holes where they were
}

TEST(AdvancingFront, TooFewPointsGiveNoTriangleAndBadOptionsAreRefused) {
  EXPECT_TRUE(AdvancingFrontSurface({{0, 0, 0}, {1, 0, 0}}).triangles.empty());
  AdvancingFrontOptions options;
  options.beta = 0.0;
  EXPECT_THROW(AdvancingFrontSurface(SpherePoints(10, 1.0, {0, 0, 0}), options), std::exception);
  options = {};
  options.max_edge = -1.0;
  EXPECT_NE(options.Check(), "");
}

}  // namespace
}  // namespace omni
