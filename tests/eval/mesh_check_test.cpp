#include "calib/mesh_check.h"

#include <gtest/gtest.h>

#include "calib/error.h"
#include "eval/primitives.h"

namespace omni {
namespace {

TEST(MeshCheck, PrimitivesFaceOutwards) {
  EXPECT_NEAR(SignedVolume(MakeBox({0, 0, 0}, {1, 2, 3})), 6.0, 1e-12);
  EXPECT_GT(SignedVolume(MakeIcosphere({1, 2, 3}, 2.0, 2)), 0.9 * 4.0 / 3.0 * M_PI * 8.0);
  EXPECT_GT(SignedVolume(MakeTorus(3.0, 1.0, 24, 12)), 0.0);
}

TEST(MeshCheck, AcceptsBox) {
  const MeshCheckReport report = CheckMesh(MakeBox({0, 0, 0}, {1, 1, 1}));
  EXPECT_TRUE(report.ok);
  EXPECT_EQ(report.vertices, 8);
  EXPECT_EQ(report.triangles, 12);
  EXPECT_EQ(report.edges, 18);
  EXPECT_EQ(report.euler_characteristic, 2);
  EXPECT_EQ(report.genus, 0);
}

TEST(MeshCheck, AcceptsIcosphereWithEulerCharacteristicTwo) {
  const TriangleMesh sphere = MakeIcosphere({0, 0, 0}, 1.0, 3);
  const MeshCheckReport report = CheckMesh(sphere);
  EXPECT_TRUE(report.ok) << report.ToText();
  EXPECT_TRUE(report.closed_manifold);
  EXPECT_TRUE(report.oriented);
  EXPECT_EQ(report.triangles, 20 * 64);
  EXPECT_EQ(report.vertices, 642);
  EXPECT_EQ(report.edges, 30 * 64);
  EXPECT_EQ(report.euler_characteristic, 2);
  EXPECT_EQ(report.genus, 0);
  EXPECT_EQ(report.components, 1);
  EXPECT_EQ(report.boundary_edges, 0);
  EXPECT_EQ(report.vertices_link_not_cycle, 0);
}

TEST(MeshCheck, AcceptsTorusWithGenusOne) {
  const MeshCheckReport report = CheckMesh(MakeTorus(3.0, 1.0, 24, 12));
  EXPECT_TRUE(report.ok) << report.ToText();
  EXPECT_EQ(report.euler_characteristic, 0);
  EXPECT_EQ(report.genus, 1);
  EXPECT_EQ(report.components, 1);
}

TEST(MeshCheck, CountsComponentsAndSumsGenus) {
  TriangleMesh mesh = MakeTorus(3.0, 1.0, 16, 8);
  AppendMesh(MakeIcosphere({10, 0, 0}, 1.0, 1), &mesh);
  AppendMesh(MakeTorus(2.0, 0.5, 12, 6), &mesh);
  const MeshCheckReport report = CheckMesh(mesh);
  EXPECT_TRUE(report.ok);
  EXPECT_EQ(report.components, 3);
  EXPECT_EQ(report.closed_components, 3);
  EXPECT_EQ(report.euler_characteristic, 2);
  EXPECT_EQ(report.genus, 2);
  ASSERT_EQ(report.listed_components.size(), 3u);
  EXPECT_GE(report.listed_components[0].triangles, report.listed_components[1].triangles);
}

TEST(MeshCheck, RejectsTwoCubesTouchingAtAVertex) {
  TriangleMesh mesh = MakeBox({0, 0, 0}, {1, 1, 1});
  AppendMesh(MakeBox({1, 1, 1}, {2, 2, 2}), &mesh);
  mesh = WeldVertices(mesh);
  ASSERT_EQ(mesh.vertices.size(), 15u);
  const MeshCheckReport report = CheckMesh(mesh);
  EXPECT_FALSE(report.ok);
  EXPECT_FALSE(report.closed_manifold);
  EXPECT_EQ(report.nonmanifold_vertices, 1);  // its link is two cycles
  EXPECT_EQ(report.vertices_link_not_cycle, 1);
  EXPECT_EQ(report.nonmanifold_edges, 0);
  EXPECT_EQ(report.boundary_edges, 0);
  EXPECT_TRUE(report.oriented);
  EXPECT_EQ(report.components, 1);
  EXPECT_EQ(report.euler_characteristic, 3);  // 15 - 36 + 24
  EXPECT_EQ(report.genus, -1);
}

TEST(MeshCheck, RejectsEdgeInThreeTriangles) {
  TriangleMesh mesh = MakeBox({0, 0, 0}, {1, 1, 1});
  // A fin on the edge between vertices 0 and 1.
  mesh.vertices.emplace_back(0.5, -1.0, -1.0);
  mesh.triangles.emplace_back(0, 1, 8);
  const MeshCheckReport report = CheckMesh(mesh);
  EXPECT_FALSE(report.ok);
  EXPECT_EQ(report.nonmanifold_edges, 1);
  EXPECT_EQ(report.boundary_edges, 2);
  EXPECT_FALSE(report.closed_manifold);
  EXPECT_EQ(report.genus, -1);
}

TEST(MeshCheck, RejectsOneFlippedTriangleForOrientation) {
  TriangleMesh mesh = MakeIcosphere({0, 0, 0}, 1.0, 2);
  std::swap(mesh.triangles[7][1], mesh.triangles[7][2]);
  const MeshCheckReport report = CheckMesh(mesh);
  EXPECT_FALSE(report.ok);
  EXPECT_TRUE(report.closed_manifold);
  EXPECT_FALSE(report.oriented);
  EXPECT_EQ(report.misoriented_edges, 3);
  EXPECT_EQ(report.genus, -1);
  EXPECT_EQ(report.euler_characteristic, 2);
}

TEST(MeshCheck, OpenSquareReportsBoundaryEdges) {
  TriangleMesh square;
  square.vertices = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  square.triangles = {{0, 1, 2}, {0, 2, 3}};
  const MeshCheckReport report = CheckMesh(square);
  EXPECT_FALSE(report.ok);
  EXPECT_EQ(report.boundary_edges, 4);
  EXPECT_EQ(report.edges, 5);
  EXPECT_EQ(report.vertices_link_not_cycle, 4);
  EXPECT_EQ(report.nonmanifold_vertices, 0);
  EXPECT_EQ(report.euler_characteristic, 1);
  MeshCheckOptions options;
  options.allow_boundary = true;
  EXPECT_TRUE(CheckMesh(square, options).ok);
}

TEST(MeshCheck, CountsDegenerateTriangles) {
  TriangleMesh mesh = MakeBox({0, 0, 0}, {1, 1, 1});
  mesh.triangles.emplace_back(0, 0, 1);  // repeated index
  mesh.vertices.emplace_back(0.5, 0.0, 0.0);
  mesh.vertices.emplace_back(2.0, 0.0, 0.0);
  mesh.vertices.emplace_back(3.0, 0.0, 0.0);
  mesh.triangles.emplace_back(8, 9, 10);  // collinear
  const MeshCheckReport report = CheckMesh(mesh);
  EXPECT_EQ(report.degenerate_triangles, 2);
  EXPECT_EQ(report.repeated_index_triangles, 1);
  EXPECT_FALSE(report.ok);
}

TEST(MeshCheck, EmptyMeshIsNotOk) {
  const MeshCheckReport report = CheckMesh(TriangleMesh{});
  EXPECT_FALSE(report.ok);
  EXPECT_EQ(report.components, 0);
}

TEST(MeshCheck, IndexOutOfRangeIsInputError) {
  TriangleMesh mesh = MakeBox({0, 0, 0}, {1, 1, 1});
  mesh.triangles.emplace_back(0, 1, 8);
  EXPECT_THROW(CheckMesh(mesh), InputError);
}

TEST(MeshCheck, JsonNamesEveryFigure) {
  const std::string json = CheckMesh(MakeTorus(3.0, 1.0, 8, 6)).ToJson();
  EXPECT_NE(json.find("\"genus\": 1"), std::string::npos) << json;
  EXPECT_NE(json.find("\"ok\": true"), std::string::npos);
}

}  // namespace
}  // namespace omni
