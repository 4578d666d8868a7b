// The observed surface (surface/observed_mesh.h, IncrementalSculptor::ExtractObservedMesh): on
// the street between two walls it has no Steiner vertex, no ceiling triangle and is an oriented
// 2-manifold with boundary by the independent CheckMesh, its triangles a subset of the closed δO;
// the repair of touching boundaries on hand-made sheets and on random subsets of δO.

#include "surface/observed_mesh.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <random>
#include <set>
#include <unordered_map>

#include "calib/mesh_check.h"
#include "surface/sculptor.h"
#include "tests/surface/step6_scenes.h"

namespace omni {
namespace {

MeshCheckOptions Bounded() {
  MeshCheckOptions options;
  options.allow_boundary = true;
  return options;
}

// An oriented triangle up to rotation: its smallest index first.
std::array<int, 3> Canonical(int a, int b, int c) {
  if (b < a && b < c) return {b, c, a};
  if (c < a && c < b) return {c, a, b};
  return {a, b, c};
}

struct Street {
  IncrementalSculptor sculptor;
  explicit Street(const SculptorOptions& options) : sculptor(options) {
    for (const SurfaceKeyframe& kf : testing::NoisyStreet(40, 100, 0.0, 11, 8.0, 10.0))
      sculptor.AddKeyframe(kf);
    sculptor.Finish();
  }
};

SculptorOptions StreetOptions() {
  SculptorOptions options;
  options.init_keyframes = 10;
  return options;
}

TEST(ObservedMesh, StreetHasNoSteinerVertexNoCeilingAndIsABoundedSubsetOfTheClosedSurface) {
  const Street street(StreetOptions());
  const IncrementalSculptor& sculptor = street.sculptor;
  std::vector<PointId> closed_points, observed_points;
  const TriangleMesh closed = sculptor.ExtractMesh(&closed_points);
  ObservedMeshStats stats;
  const TriangleMesh observed = sculptor.ExtractObservedMesh(&observed_points, &stats);

  // The closed δO is still a closed oriented 2-manifold, and has Steiner vertices.
  const MeshCheckReport closed_report = CheckMesh(closed);
  EXPECT_TRUE(closed_report.ok) << closed_report.Summary();
  ASSERT_EQ(closed_points.size(), closed.vertices.size());
  EXPECT_TRUE(std::any_of(closed_points.begin(), closed_points.end(),
                          [](PointId id) { return !id.IsValid(); }));
  // The same δO without vertex ids.
  EXPECT_EQ(sculptor.ExtractMesh().triangles, closed.triangles);

  // The observed mesh: a 2-manifold with boundary, oriented, of point vertices only.
  const MeshCheckReport report = CheckMesh(observed, Bounded());
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_FALSE(report.closed_manifold);
  EXPECT_GT(report.boundary_loops, 0);
  EXPECT_GT(observed.triangles.size(), closed.triangles.size() / 2);
  EXPECT_LT(observed.triangles.size(), closed.triangles.size());
  ASSERT_EQ(observed_points.size(), observed.vertices.size());
  for (PointId id : observed_points) EXPECT_TRUE(id.IsValid());
  EXPECT_EQ(stats.closed_triangles, closed.triangles.size());
  EXPECT_EQ(stats.triangles, observed.triangles.size());
  EXPECT_EQ(stats.closed_triangles, stats.triangles + stats.steiner + stats.long_edges +
                                        stats.sparse + stats.unseen + stats.manifold_repair +
                                        stats.small_components);
  EXPECT_GT(stats.steiner, 0u);

  // Its triangles, oriented as they are, are triangles of δO at the same positions.
  std::unordered_map<uint32_t, int> closed_index;
  for (size_t v = 0; v < closed_points.size(); ++v) {
    if (closed_points[v].IsValid()) closed_index[closed_points[v].value] = static_cast<int>(v);
  }
  std::set<std::array<int, 3>> closed_triangles;
  for (const Eigen::Vector3i& t : closed.triangles)
    closed_triangles.insert(Canonical(t[0], t[1], t[2]));
  for (size_t v = 0; v < observed.vertices.size(); ++v) {
    const int c = closed_index.at(observed_points[v].value);
    EXPECT_EQ(observed.vertices[v], closed.vertices[c]);
  }
  for (const Eigen::Vector3i& t : observed.triangles) {
    const int a = closed_index.at(observed_points[t[0]].value);
    const int b = closed_index.at(observed_points[t[1]].value);
    const int c = closed_index.at(observed_points[t[2]].value);
    EXPECT_TRUE(closed_triangles.count(Canonical(a, b, c))) << a << " " << b << " " << c;
  }

  // The ceiling over the street (between the wall tops, 16 m apart) and the caps at its ends
  // are left out: no edge longer than 8 m, none longer than max_edge_factor · s but those the
  // growth brought back (within grow_max_edge_factor · s), all of them facing a ray centre.
  const ObservedMeshOptions defaults;
  const double max_edge = defaults.grow_max_edge_factor * sculptor.scale();
  ASSERT_GT(defaults.grow_max_edge_factor, defaults.max_edge_factor);
  size_t long_observed = 0;
  size_t long_closed = 0;
  for (const Eigen::Vector3i& t : closed.triangles) {
    for (int k = 0; k < 3; ++k) {
      long_closed += (closed.vertices[t[k]] - closed.vertices[t[(k + 1) % 3]]).norm() > 8.0;
    }
  }
  EXPECT_GT(long_closed, 0u);
  for (const Eigen::Vector3i& t : observed.triangles) {
    double longest = 0.0;
    for (int k = 0; k < 3; ++k) {
      const double length = (observed.vertices[t[k]] - observed.vertices[t[(k + 1) % 3]]).norm();
      EXPECT_LE(length, std::min(8.0, max_edge));
      longest = std::max(longest, length);
    }
    long_observed += longest > defaults.max_edge_factor * sculptor.scale();
  }
  EXPECT_GT(stats.grown, 0u);
  EXPECT_LE(long_observed, stats.grown);  // the repair may drop grown ones

  // Without any filter but the Steiner vertices it is still a bounded manifold subset.
  SculptorOptions loose = StreetOptions();
  loose.observed.max_edge_factor = 0.0;
  loose.observed.require_seen = false;
  const Street loose_street(loose);
  const TriangleMesh loose_mesh = loose_street.sculptor.ExtractObservedMesh();
  EXPECT_TRUE(CheckMesh(loose_mesh, Bounded()).ok) << CheckMesh(loose_mesh, Bounded()).Summary();
  EXPECT_GT(loose_mesh.triangles.size(), observed.triangles.size());
}

// A sheet of n × n unit squares, two triangles each, without the squares in `holes`.
std::vector<Eigen::Vector3i> Sheet(int n, const std::vector<std::pair<int, int>>& holes) {
  std::vector<Eigen::Vector3i> triangles;
  for (int row = 0; row < n; ++row) {
    for (int column = 0; column < n; ++column) {
      if (std::find(holes.begin(), holes.end(), std::make_pair(column, row)) != holes.end())
        continue;
      const int a = row * (n + 1) + column;
      triangles.emplace_back(a, a + 1, a + n + 2);
      triangles.emplace_back(a, a + n + 2, a + n + 1);
    }
  }
  return triangles;
}

TriangleMesh SheetMesh(int n, const std::vector<Eigen::Vector3i>& triangles) {
  TriangleMesh mesh;
  for (int row = 0; row <= n; ++row) {
    for (int column = 0; column <= n; ++column) mesh.vertices.emplace_back(column, row, 0.0);
  }
  mesh.triangles = triangles;
  return mesh;
}

TEST(ObservedMesh, RepairDropsTheSmallerFanWhereTwoHolesTouch) {
  // Holes (1, 1) and (2, 2) touch at the vertex (2, 2): its link is two paths of one triangle.
  std::vector<Eigen::Vector3i> triangles = Sheet(5, {{1, 1}, {2, 2}});
  EXPECT_FALSE(CheckMesh(SheetMesh(5, triangles), Bounded()).ok);
  const size_t before = triangles.size();
  const size_t dropped = RepairTouchingBoundaries(&triangles, 36);
  EXPECT_EQ(dropped, 1u);
  EXPECT_EQ(triangles.size(), before - 1);
  const MeshCheckReport report = CheckMesh(SheetMesh(5, triangles), Bounded());
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_EQ(report.boundary_loops, 2);  // the rim, and the two holes become one
  // A manifold with boundary is left as it is.
  std::vector<Eigen::Vector3i> apart = Sheet(5, {{1, 1}, {3, 3}});
  const std::vector<Eigen::Vector3i> copy = apart;
  EXPECT_EQ(RepairTouchingBoundaries(&apart, 36), 0u);
  EXPECT_EQ(apart, copy);
}

TEST(ObservedMesh, RepairMakesAnyTriangleSubsetOfTheClosedSurfaceABoundedManifold) {
  SculptorOptions options = StreetOptions();
  const Street street(options);
  const TriangleMesh closed = street.sculptor.ExtractMesh();
  ASSERT_TRUE(CheckMesh(closed).ok);
  std::mt19937 rng(5);
  for (double keep : {0.95, 0.7, 0.4}) {
    SCOPED_TRACE(keep);
    std::bernoulli_distribution kept(keep);
    TriangleMesh subset = closed;
    subset.triangles.clear();
    for (const Eigen::Vector3i& t : closed.triangles) {
      if (kept(rng)) subset.triangles.push_back(t);
    }
    const size_t before = subset.triangles.size();
    const MeshCheckReport broken = CheckMesh(subset, Bounded());
    EXPECT_GT(broken.nonmanifold_vertices, 0);
    const size_t dropped = RepairTouchingBoundaries(&subset.triangles, subset.vertices.size());
    EXPECT_EQ(subset.triangles.size(), before - dropped);
    MeshCheckOptions bounded = Bounded();
    bounded.allow_empty = true;
    const MeshCheckReport report = CheckMesh(subset, bounded);
    EXPECT_TRUE(report.ok) << report.Summary();
    // Fewer triangles go than there were bad vertices times their valence.
    EXPECT_LT(dropped, before / 2);
  }
}

TEST(ObservedMesh, ColorMeshVerticesGivesEachVertexItsPointsColourAndSteinerGrey) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  const std::vector<PointId> points = {PointId(7), PointId::Invalid(), PointId(9)};
  const std::unordered_map<PointId, Rgb8> colors = {{PointId(7), Rgb8(200, 10, 30)}};
  ColorMeshVertices(points, colors, &mesh);
  ASSERT_EQ(mesh.colors.size(), 3u);
  EXPECT_EQ(mesh.colors[0], Rgb8(200, 10, 30));
  EXPECT_EQ(mesh.colors[1], Rgb8(128, 128, 128));  // Steiner
  EXPECT_EQ(mesh.colors[2], Rgb8(128, 128, 128));  // no colour known
  EXPECT_THROW(ColorMeshVertices({PointId(7)}, colors, &mesh), std::invalid_argument);
}

// Two closed tetrahedra with 4 m edges seen from a camera at the origin, one 40 m away and one
// 5 m away, at s = 1 m: the edge bound (2 s) drops both; within 0.2 rad of the nearest ray
// centre (a chord of 8 m at 40 m, 1 m at 5 m) the far one is kept, whole, and the near one is
// not.
TEST(ObservedMesh, TheEdgeAngleKeepsFarTrianglesSmallInViewAndNotNearLongOnes) {
  TriangleMesh closed;
  const Eigen::Vector3i faces[] = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  for (double distance : {40.0, 5.0}) {
    const int first = static_cast<int>(closed.vertices.size());
    const Eigen::Vector3d centre(distance, 0.0, 0.0);
    const double a = 4.0 / std::sqrt(8.0);  // corners (±a, ±a, ±a): edges 4 m
    closed.vertices.push_back(centre + Eigen::Vector3d(a, a, a));
    closed.vertices.push_back(centre + Eigen::Vector3d(a, -a, -a));
    closed.vertices.push_back(centre + Eigen::Vector3d(-a, a, -a));
    closed.vertices.push_back(centre + Eigen::Vector3d(-a, -a, a));
    for (const Eigen::Vector3i& f : faces) closed.triangles.push_back(f.array() + first);
  }
  const std::vector<Eigen::Vector3d> origins = {Eigen::Vector3d::Zero()};
  const std::vector<ObservedVertex> vertices(closed.vertices.size(), ObservedVertex{&origins});
  ObservedMeshOptions options;
  options.require_seen = false;
  ObservedMeshStats stats;
  EXPECT_TRUE(
      SelectObservedMesh(closed, vertices, 1.0, options, nullptr, &stats).triangles.empty());
  EXPECT_EQ(stats.long_edges, 8u);

  options.max_edge_angle = 0.2;
  std::vector<int> kept_vertices;
  const TriangleMesh kept =
      SelectObservedMesh(closed, vertices, 1.0, options, &kept_vertices, &stats);
  EXPECT_EQ(kept.triangles.size(), 4u);
  EXPECT_EQ(kept_vertices, (std::vector<int>{0, 1, 2, 3}));
  EXPECT_EQ(stats.long_edges, 4u);
  EXPECT_TRUE(CheckMesh(kept).ok) << CheckMesh(kept).Summary();

  // 0.05 rad (a 2 m chord at 40 m) keeps neither.
  options.max_edge_angle = 0.05;
  EXPECT_TRUE(SelectObservedMesh(closed, vertices, 1.0, options).triangles.empty());
}

// A closed box 8 m long, 1 m wide and 4 m high whose floor is a strip of squares: four of 1 m
// (diagonals 1.41 m) then one of 4 m (diagonal 4.12 m); its walls and roof have edges of 4 m
// and more. At s = 1 and an edge bound of 2 s only the small squares pass; the growth brings
// back the large square, which continues their plane, and never the walls at a right angle to
// it, however long they may be.
TEST(ObservedMesh, TheGrowthContinuesAPlaneAcrossLongEdgesAndStopsAtAFold) {
  const std::vector<double> floor_x = {0, 1, 2, 3, 4, 8};
  const int m = static_cast<int>(floor_x.size());
  const double height = 4.0;
  TriangleMesh closed;
  for (double x : floor_x) closed.vertices.emplace_back(x, 0.0, 0.0);  // 0 .. m-1: y = 0
  for (double x : floor_x) closed.vertices.emplace_back(x, 1.0, 0.0);  // m .. 2m-1: y = 1
  const int t00 = 2 * m, t01 = t00 + 1, t10 = t00 + 2, t11 = t00 + 3;  // the roof's corners
  closed.vertices.emplace_back(0.0, 0.0, height);
  closed.vertices.emplace_back(0.0, 1.0, height);
  closed.vertices.emplace_back(8.0, 0.0, height);
  closed.vertices.emplace_back(8.0, 1.0, height);
  auto b0 = [](int i) { return i; };
  auto b1 = [m](int i) { return m + i; };
  for (int i = 0; i + 1 < m; ++i) {  // the floor, facing down (outwards)
    closed.triangles.emplace_back(b0(i), b1(i), b1(i + 1));
    closed.triangles.emplace_back(b0(i), b1(i + 1), b0(i + 1));
  }
  closed.triangles.emplace_back(t00, t10, t11);  // the roof
  closed.triangles.emplace_back(t00, t11, t01);
  for (int i = 0; i + 1 < m; ++i) {  // the long walls, fans from the roof's corners
    closed.triangles.emplace_back(t00, b0(i), b0(i + 1));
    closed.triangles.emplace_back(t01, b1(i + 1), b1(i));
  }
  closed.triangles.emplace_back(t00, b0(m - 1), t10);
  closed.triangles.emplace_back(t01, t11, b1(m - 1));
  closed.triangles.emplace_back(b0(0), t00, t01);  // the end walls
  closed.triangles.emplace_back(b0(0), t01, b1(0));
  closed.triangles.emplace_back(b0(m - 1), b1(m - 1), t11);
  closed.triangles.emplace_back(b0(m - 1), t11, t10);
  ASSERT_TRUE(CheckMesh(closed).ok) << CheckMesh(closed).Summary();

  const std::vector<Eigen::Vector3d> origins = {Eigen::Vector3d(4.0, 0.5, -3.0)};
  const std::vector<ObservedVertex> vertices(closed.vertices.size(), ObservedVertex{&origins});
  ObservedMeshOptions options;
  options.max_edge_factor = 2.0;
  options.grow_max_edge_factor = 0.0;  // no growth
  options.require_seen = false;
  ObservedMeshStats stats;
  EXPECT_EQ(SelectObservedMesh(closed, vertices, 1.0, options, nullptr, &stats).triangles.size(),
            8u);
  EXPECT_EQ(stats.grown, 0u);
  EXPECT_EQ(stats.long_edges, closed.triangles.size() - 8u);

  // Growth up to 4.6 m: the large square (4.12 m) joins; the end walls (4.12 m) and the first
  // fans of the long walls (4.12 and 4.47 m) would pass the length but meet the floor at 90°.
  options.grow_max_edge_factor = 4.6;
  options.grow_max_normal_angle = 0.35;
  std::vector<int> kept_vertices;
  const TriangleMesh grown =
      SelectObservedMesh(closed, vertices, 1.0, options, &kept_vertices, &stats);
  EXPECT_EQ(grown.triangles.size(), 10u);
  EXPECT_EQ(stats.grown, 2u);
  EXPECT_EQ(kept_vertices, (std::vector<int>{0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11}));
  for (const Eigen::Vector3d& v : grown.vertices) EXPECT_EQ(v.z(), 0.0);
  const MeshCheckReport report = CheckMesh(grown, Bounded());
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_EQ(report.boundary_loops, 1);

  // Below the large square's diagonal, nothing grows.
  options.grow_max_edge_factor = 4.0;
  EXPECT_EQ(SelectObservedMesh(closed, vertices, 1.0, options, nullptr, &stats).triangles.size(),
            8u);
  // The fold is what stops it: at an angle of up to 100° the walls within 4.6 m grow too.
  options.grow_max_edge_factor = 4.6;
  options.grow_max_normal_angle = 1.75;
  EXPECT_GT(SelectObservedMesh(closed, vertices, 1.0, options, nullptr, &stats).triangles.size(),
            10u);
}

TEST(ObservedMeshOptions, CheckRejectsBadValues) {
  EXPECT_EQ(ObservedMeshOptions().Check(), "");
  ObservedMeshOptions o;
  o.max_edge_factor = -1.0;
  EXPECT_NE(o.Check().find("observed.max_edge_factor"), std::string::npos);
  o = {};
  o.max_edge_angle = -0.1;
  EXPECT_NE(o.Check().find("observed.max_edge_angle"), std::string::npos);
  o.max_edge_angle = 4.0;
  EXPECT_NE(o.Check().find("observed.max_edge_angle"), std::string::npos);
  o = {};
  o.max_spacing_factor = -0.5;
  EXPECT_NE(o.Check().find("observed.max_spacing_factor"), std::string::npos);
  o = {};
  o.min_view_cosine = 1.0;
  EXPECT_NE(o.Check().find("observed.min_view_cosine"), std::string::npos);
  o = {};
  o.grow_max_edge_factor = -1.0;
  EXPECT_NE(o.Check().find("observed.grow_max_edge_factor"), std::string::npos);
  o = {};
  o.grow_max_normal_angle = 0.0;
  EXPECT_NE(o.Check().find("observed.grow_max_normal_angle"), std::string::npos);
  o = {};
  o.min_component_triangles = -1;
  EXPECT_NE(o.Check().find("observed.min_component_triangles"), std::string::npos);
  SculptorOptions sculptor;
  sculptor.observed.max_edge_factor = -1.0;
  EXPECT_NE(sculptor.Check().find("observed.max_edge_factor"), std::string::npos);
}

}  // namespace
}  // namespace omni
