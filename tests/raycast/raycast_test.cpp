// The ray caster against meshes whose hits are known in closed form: distances and barycentric
// coordinates, misses, the closest of stacked triangles, and batches equal to single rays.

#include "raycast/raycast.h"

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "calib/error.h"

namespace omni {
namespace {

// One triangle a b c in the plane z = height, shifted by `offset`.
void AddTriangle(double height, const Eigen::Vector3d& offset, TriangleMesh* mesh) {
  const int first = static_cast<int>(mesh->vertices.size());
  mesh->vertices.push_back(offset + Eigen::Vector3d(0, 0, height));
  mesh->vertices.push_back(offset + Eigen::Vector3d(4, 0, height));
  mesh->vertices.push_back(offset + Eigen::Vector3d(0, 4, height));
  mesh->triangles.emplace_back(first, first + 1, first + 2);
}

TriangleMesh OneTriangle(const Eigen::Vector3d& offset = Eigen::Vector3d::Zero()) {
  TriangleMesh mesh;
  AddTriangle(5.0, offset, &mesh);
  return mesh;
}

RayCasterOptions PlainOptions() {
  RayCasterOptions options;
  options.recentre = false;
  options.robust = false;
  options.coherent = true;
  return options;
}

Ray MakeRay(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
            double max_distance = std::numeric_limits<double>::infinity()) {
  Ray ray;
  ray.origin = origin;
  ray.direction = direction.normalized();
  ray.max_distance = max_distance;
  return ray;
}

TEST(RayCast, HitsAKnownTriangleAtTheAnalyticDistanceAndBarycentrics) {
  // The point (1, 2, 5) is a + u (b - a) + v (c - a) with u = 1/4, v = 1/2.
  for (const Eigen::Vector3d& offset :
       {Eigen::Vector3d(0, 0, 0), Eigen::Vector3d(1000.0, -2000.0, 30.0)}) {
    for (const RayCasterOptions& options : {RayCasterOptions{}, PlainOptions()}) {
      const RayCaster caster(OneTriangle(offset), options);
      ASSERT_EQ(caster.NumTriangles(), 1u);
      const RayHit straight = caster.Cast(MakeRay(offset + Eigen::Vector3d(1, 2, 0), {0, 0, 1}));
      ASSERT_TRUE(straight.Hit());
      EXPECT_EQ(straight.triangle, 0);
      EXPECT_NEAR(straight.distance, 5.0, 1e-5);
      EXPECT_NEAR(straight.u, 0.25, 1e-5);
      EXPECT_NEAR(straight.v, 0.5, 1e-5);
      const RayHit oblique = caster.Cast(MakeRay(offset, {1, 2, 5}));
      ASSERT_TRUE(oblique.Hit());
      EXPECT_NEAR(oblique.distance, std::sqrt(30.0), 1e-5);
      EXPECT_NEAR(oblique.u, 0.25, 1e-5);
      EXPECT_NEAR(oblique.v, 0.5, 1e-5);
      // Seen from above, the triangle is hit from behind just the same.
      const RayHit behind = caster.Cast(MakeRay(offset + Eigen::Vector3d(1, 2, 8), {0, 0, -1}));
      ASSERT_TRUE(behind.Hit());
      EXPECT_NEAR(behind.distance, 3.0, 1e-5);
      EXPECT_NEAR(caster.TriangleNormal(0).z(), 1.0, 1e-12);
    }
  }
}

TEST(RayCast, MissesMiss) {
  const RayCaster caster(OneTriangle());
  // Away from the triangle, beside it, beyond the diagonal edge, and stopped short of it.
  EXPECT_FALSE(caster.Cast(MakeRay({1, 2, 0}, {0, 0, -1})).Hit());
  EXPECT_FALSE(caster.Cast(MakeRay({5, 5, 0}, {0, 0, 1})).Hit());
  EXPECT_FALSE(caster.Cast(MakeRay({2.1, 2.1, 0}, {0, 0, 1})).Hit());
  EXPECT_FALSE(caster.Cast(MakeRay({1, 2, 0}, {0, 0, 1}, 4.9)).Hit());
  EXPECT_TRUE(caster.Cast(MakeRay({1, 2, 0}, {0, 0, 1}, 5.1)).Hit());
  const RayHit miss = caster.Cast(MakeRay({5, 5, 0}, {0, 0, 1}));
  EXPECT_EQ(miss.triangle, -1);
  EXPECT_TRUE(std::isinf(miss.distance));
}

TEST(RayCast, ReturnsTheClosestOfTwoStackedTriangles) {
  TriangleMesh mesh;
  AddTriangle(5.0, Eigen::Vector3d::Zero(), &mesh);  // triangle 0, the farther from below
  AddTriangle(3.0, Eigen::Vector3d::Zero(), &mesh);  // triangle 1
  for (const RayCasterOptions& options : {RayCasterOptions{}, PlainOptions()}) {
    const RayCaster caster(mesh, options);
    const RayHit from_below = caster.Cast(MakeRay({1, 1, 0}, {0, 0, 1}));
    ASSERT_TRUE(from_below.Hit());
    EXPECT_EQ(from_below.triangle, 1);
    EXPECT_NEAR(from_below.distance, 3.0, 1e-5);
    const RayHit from_above = caster.Cast(MakeRay({1, 1, 10}, {0, 0, -1}));
    ASSERT_TRUE(from_above.Hit());
    EXPECT_EQ(from_above.triangle, 0);
    EXPECT_NEAR(from_above.distance, 5.0, 1e-5);
    // Between the two, looking up: the upper one.
    const RayHit between = caster.Cast(MakeRay({1, 1, 4}, {0, 0, 1}));
    EXPECT_EQ(between.triangle, 0);
    EXPECT_NEAR(between.distance, 1.0, 1e-5);
  }
}

TEST(RayCast, BatchesEqualSingleRays) {
  TriangleMesh mesh;
  AddTriangle(5.0, Eigen::Vector3d::Zero(), &mesh);
  AddTriangle(3.0, Eigen::Vector3d(2, 2, 0), &mesh);
  AddTriangle(7.0, Eigen::Vector3d(-3, -1, 0), &mesh);
  for (const RayCasterOptions& options : {RayCasterOptions{}, PlainOptions()}) {
    const RayCaster caster(mesh, options);
    // A fan of rays from one origin: some hit each triangle, some miss.
    std::vector<Ray> rays;
    for (int i = 0; i < 203; ++i) {
      const double a = 0.31 * i, b = 0.02 * (i % 50);
      rays.push_back(MakeRay({0.5, 0.5, 0}, {b * std::cos(a), b * std::sin(a), 1.0}));
    }
    const std::vector<RayHit> many = caster.CastMany(rays);
    ASSERT_EQ(many.size(), rays.size());
    int hits = 0, misses = 0;
    for (size_t i = 0; i < rays.size(); ++i) {
      const RayHit one = caster.Cast(rays[i]);
      EXPECT_EQ(many[i].triangle, one.triangle) << i;
      EXPECT_EQ(many[i].distance, one.distance) << i;
      EXPECT_EQ(many[i].u, one.u) << i;
      EXPECT_EQ(many[i].v, one.v) << i;
      ++(one.Hit() ? hits : misses);
    }
    EXPECT_GT(hits, 50);
    EXPECT_GT(misses, 10);
    // Packets of 8, the last one partly valid, and one lane left out in every packet.
    for (size_t first = 0; first < rays.size(); first += RayCaster::kPacketSize) {
      Ray packet[RayCaster::kPacketSize];
      bool valid[RayCaster::kPacketSize];
      RayHit packet_hits[RayCaster::kPacketSize];
      for (int k = 0; k < RayCaster::kPacketSize; ++k) {
        valid[k] = first + k < rays.size() && k != 3;
        if (first + k < rays.size()) packet[k] = rays[first + k];
      }
      caster.CastPacket(packet, valid, packet_hits);
      for (int k = 0; k < RayCaster::kPacketSize; ++k) {
        if (!valid[k]) {
          EXPECT_FALSE(packet_hits[k].Hit());
          continue;
        }
        const RayHit& one = many[first + k];
        EXPECT_EQ(packet_hits[k].triangle, one.triangle) << first + k;
        if (!one.Hit()) continue;
        EXPECT_NEAR(packet_hits[k].distance, one.distance, 1e-5) << first + k;
        EXPECT_NEAR(packet_hits[k].u, one.u, 1e-5) << first + k;
        EXPECT_NEAR(packet_hits[k].v, one.v, 1e-5) << first + k;
      }
    }
  }
}

TEST(RayCast, ClosestPointAndItsBatch) {
  const RayCaster caster(OneTriangle());
  const RayHit above = caster.Closest({1, 1, 7});
  EXPECT_EQ(above.triangle, 0);
  EXPECT_NEAR(above.distance, 2.0, 1e-12);
  EXPECT_NEAR(caster.Closest({-3, 0, 5}).distance, 3.0, 1e-12);  // to corner a
  EXPECT_FALSE(caster.Closest({1, 1, 7}, 1.5).Hit());
  const std::vector<double> distances = caster.DistancesTo({{1, 1, 7}, {-3, 0, 5}, {1, 1, 20}}, 10);
  ASSERT_EQ(distances.size(), 3u);
  EXPECT_NEAR(distances[0], 2.0, 1e-12);
  EXPECT_NEAR(distances[1], 3.0, 1e-12);
  EXPECT_TRUE(std::isinf(distances[2]));
  EXPECT_EQ(caster.MinCorner(), Eigen::Vector3d(0, 0, 5));
  EXPECT_EQ(caster.MaxCorner(), Eigen::Vector3d(4, 4, 5));
}

TEST(RayCast, EmptyMeshAndBadIndicesAreInputErrors) {
  EXPECT_THROW(RayCaster{TriangleMesh{}}, InputError);
  TriangleMesh bad = OneTriangle();
  bad.triangles[0][2] = 3;
  EXPECT_THROW(RayCaster{bad}, InputError);
}

}  // namespace
}  // namespace omni
