#include "sfm/triangulation.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>

namespace omni {
namespace {

WorldRay RayTowards(const Eigen::Vector3d& center, const Eigen::Vector3d& point) {
  return WorldRay{center, (point - center).normalized()};
}

TEST(Triangulation, RecoversPointFromNoisyRays) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.0005);
  const Eigen::Vector3d truth(1.0, -2.0, 8.0);
  std::vector<WorldRay> rays;
  for (int i = 0; i < 4; ++i) {
    WorldRay ray = RayTowards(Eigen::Vector3d(0.5 * i, 0.1 * i, 0.0), truth);
    ray.direction =
        (ray.direction + Eigen::Vector3d(noise(rng), noise(rng), noise(rng))).normalized();
    rays.push_back(ray);
  }
  Eigen::Vector3d point;
  ASSERT_EQ(TriangulatePoint(rays, TriangulationOptions(), &point), TriangulationStatus::kOk);
  // 0.5 mrad of noise at 8 m with a 1.5 m baseline: a few centimetres.
  EXPECT_LT((point - truth).norm(), 0.1);
}

TEST(Triangulation, ExactRaysGiveTheExactPoint) {
  const Eigen::Vector3d truth(-3.0, 0.5, 4.0);
  const std::vector<WorldRay> rays = {RayTowards(Eigen::Vector3d(0, 0, 0), truth),
                                      RayTowards(Eigen::Vector3d(1, 0, 0), truth),
                                      RayTowards(Eigen::Vector3d(0, 1, 0.5), truth)};
  Eigen::Vector3d point;
  ASSERT_EQ(TriangulatePoint(rays, TriangulationOptions(), &point), TriangulationStatus::kOk);
  EXPECT_LT((point - truth).norm(), 1e-9);
}

TEST(Triangulation, RejectsBadGeometry) {
  const Eigen::Vector3d truth(0.0, 0.0, 10.0);
  Eigen::Vector3d point;
  TriangulationOptions options;

  EXPECT_EQ(TriangulatePoint({RayTowards(Eigen::Vector3d::Zero(), truth)}, options, &point),
            TriangulationStatus::kTooFewRays);

  const WorldRay parallel1{Eigen::Vector3d(0, 0, 0), Eigen::Vector3d::UnitZ()};
  const WorldRay parallel2{Eigen::Vector3d(1, 0, 0), Eigen::Vector3d::UnitZ()};
  EXPECT_EQ(TriangulatePoint({parallel1, parallel2}, options, &point),
            TriangulationStatus::kDegenerate);

  // A 5 cm baseline at 10 m: 0.3°, below the 2° minimum.
  EXPECT_EQ(TriangulatePoint({RayTowards(Eigen::Vector3d(0, 0, 0), truth),
                              RayTowards(Eigen::Vector3d(0.05, 0, 0), truth)},
                             options, &point),
            TriangulationStatus::kSmallAngle);
  options.min_ray_angle = 0.001;
  EXPECT_EQ(TriangulatePoint({RayTowards(Eigen::Vector3d(0, 0, 0), truth),
                              RayTowards(Eigen::Vector3d(0.05, 0, 0), truth)},
                             options, &point),
            TriangulationStatus::kOk);
  options = TriangulationOptions();

  // Both rays point away from the point they meet at.
  WorldRay away1 = RayTowards(Eigen::Vector3d(0, 0, 0), truth);
  WorldRay away2 = RayTowards(Eigen::Vector3d(4, 0, 0), truth);
  away1.direction = -away1.direction;
  away2.direction = -away2.direction;
  EXPECT_EQ(TriangulatePoint({away1, away2}, options, &point), TriangulationStatus::kBehind);

  // Three consistent rays and one 3° off.
  std::vector<WorldRay> rays = {RayTowards(Eigen::Vector3d(0, 0, 0), truth),
                                RayTowards(Eigen::Vector3d(3, 0, 0), truth),
                                RayTowards(Eigen::Vector3d(0, 3, 0), truth)};
  WorldRay wrong = RayTowards(Eigen::Vector3d(-3, 0, 0), truth);
  wrong.direction = Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitY()) * wrong.direction;
  rays.push_back(wrong);
  EXPECT_EQ(TriangulatePoint(rays, options, &point), TriangulationStatus::kLargeError);
}

}  // namespace
}  // namespace omni
