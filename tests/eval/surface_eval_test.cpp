#include "eval/surface_eval.h"

#include <gtest/gtest.h>

#include <cmath>

#include "calib/error.h"
#include "eval/primitives.h"
#include "raycast/raycast.h"

namespace omni {
namespace {

// Four 90° pinhole cameras looking along ±x and ±y of the rig (z up), 10 cm off its origin.
Rig MakeRingRig() {
  Rig rig;
  rig.name = "ring";
  for (int k = 0; k < 4; ++k) {
    Camera camera;
    camera.name = "cam" + std::to_string(k);
    camera.width = 64;
    camera.height = 48;
    camera.model = CameraModel::kPinhole;
    camera.params = {32.0, 32.0, 31.5, 23.5};
    Eigen::Matrix3d rig_from_cam;
    rig_from_cam.col(0) = Eigen::Vector3d(0, -1, 0);
    rig_from_cam.col(1) = Eigen::Vector3d(0, 0, -1);
    rig_from_cam.col(2) = Eigen::Vector3d(1, 0, 0);
    rig_from_cam = Eigen::AngleAxisd(k * M_PI / 2, Eigen::Vector3d::UnitZ()) * rig_from_cam;
    const Eigen::Vector3d center_in_rig = 0.1 * rig_from_cam.col(2);
    camera.cam_from_rig.rotation = Eigen::Quaterniond(rig_from_cam.transpose());
    camera.cam_from_rig.translation = -(rig_from_cam.transpose() * center_in_rig);
    rig.cameras.push_back(camera);
  }
  return rig;
}

std::vector<Rigid3d> MakePoses() {
  std::vector<Rigid3d> poses;
  for (int i = 0; i < 5; ++i) {
    poses.emplace_back(Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * i, Eigen::Vector3d::UnitZ())),
                       Eigen::Vector3d(-4.0 + 2.0 * i, 0.5 * i, 1.5));
  }
  return poses;
}

// A closed room seen from inside (triangles face the free space).
TriangleMesh MakeRoom(double inset) {
  return FlipOrientation(MakeBox(Eigen::Vector3d(-10, -8, 0) + Eigen::Vector3d::Constant(inset),
                                 Eigen::Vector3d(10, 8, 4) - Eigen::Vector3d::Constant(inset)));
}

std::vector<KeyframePoses> SamePoses() {
  std::vector<KeyframePoses> keyframes;
  for (const Rigid3d& pose : MakePoses()) keyframes.push_back({pose, pose});
  return keyframes;
}

TEST(RayCaster, HitsBoxAtExactDistance) {
  const RayCaster caster(MakeBox({1, -1, -1}, {3, 1, 1}));
  const RayHit hit = caster.Cast({Eigen::Vector3d(0, 0.2, 0.3), Eigen::Vector3d::UnitX()});
  ASSERT_TRUE(hit.Hit());
  EXPECT_NEAR(hit.distance, 1.0, 1e-6);
  EXPECT_NEAR(caster.TriangleNormal(hit.triangle).x(), -1.0, 1e-12);
  Ray short_ray{Eigen::Vector3d(0, 0.2, 0.3), Eigen::Vector3d::UnitX(), 0.9};
  EXPECT_FALSE(caster.Cast(short_ray).Hit());
  EXPECT_FALSE(caster.Cast({Eigen::Vector3d(0, 0, 0), -Eigen::Vector3d::UnitX()}).Hit());
}

TEST(RayCaster, ManyEqualsOne) {
  const RayCaster caster(MakeIcosphere({1000.0, 2000.0, 30.0}, 5.0, 3));
  std::vector<Ray> rays;
  for (int i = 0; i < 500; ++i) {
    const double a = 0.1 * i, b = 0.037 * i;
    rays.push_back(
        {Eigen::Vector3d(1000.0, 2000.0, 30.0),
         Eigen::Vector3d(std::cos(a) * std::cos(b), std::sin(a) * std::cos(b), std::sin(b))});
  }
  const std::vector<RayHit> hits = caster.CastMany(rays);
  for (size_t i = 0; i < rays.size(); ++i) {
    const RayHit one = caster.Cast(rays[i]);
    ASSERT_TRUE(hits[i].Hit());
    EXPECT_EQ(hits[i].triangle, one.triangle);
    EXPECT_NEAR(hits[i].distance, 5.0, 0.05);  // chords of the subdivided sphere
  }
}

TEST(RayCaster, ClosestPointDistance) {
  const RayCaster caster(MakeBox({0, 0, 0}, {2, 2, 2}));
  EXPECT_NEAR(caster.Closest({1.0, 1.0, 2.5}).distance, 0.5, 1e-9);
  EXPECT_NEAR(caster.Closest({3.0, 3.0, 1.0}).distance, std::sqrt(2.0), 1e-9);
  EXPECT_NEAR(caster.Closest({1.0, 0.7, 1.0}).distance, 0.7, 1e-9);  // inside
  EXPECT_FALSE(caster.Closest({10.0, 1.0, 1.0}, 5.0).Hit());
  const auto distances = caster.DistancesTo({{1.0, 1.0, 2.5}, {-1.0, 1.0, 1.0}});
  EXPECT_NEAR(distances[0], 0.5, 1e-9);
  EXPECT_NEAR(distances[1], 1.0, 1e-9);
}

TEST(RayCaster, EmptyMeshIsInputError) {
  try {
    RayCaster caster{TriangleMesh{}};
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("no triangle"), std::string::npos);
  }
}

TEST(SurfaceEval, GroundTruthAgainstItselfHasZeroError) {
  const Rig rig = MakeRingRig();
  const TriangleMesh room = MakeRoom(0.0);
  const RayCaster caster(room);
  RayErrorOptions options;
  options.pixels = 20000;
  const RayErrorResult result = EvaluateRayErrors(rig, SamePoses(), caster, caster, options);
  EXPECT_EQ(result.sampled_pixels, 20000);
  EXPECT_EQ(result.rays, 20000);
  EXPECT_DOUBLE_EQ(result.share_gt_hit, 1.0);
  EXPECT_DOUBLE_EQ(result.share_estimated_hit, 1.0);
  EXPECT_DOUBLE_EQ(result.share_both_hit, 1.0);
  EXPECT_LT(result.errors.max, 1e-9);
  EXPECT_EQ(result.share_above_large, 0.0);

  SurfaceCompareOptions compare;
  compare.samples = 20000;
  compare.visibility_rays = 100000;
  const SurfaceCompareResult surfaces =
      CompareSurfaces(room, caster, room, caster, rig, MakePoses(), compare);
  EXPECT_LT(surfaces.accuracy.max, 1e-5);
  EXPECT_LT(surfaces.completeness.max, 1e-5);
  EXPECT_GT(surfaces.gt_samples_seen, 0.95 * surfaces.gt_samples);
  for (const PrecisionRecall& pr : surfaces.precision_recall) {
    EXPECT_DOUBLE_EQ(pr.precision, 1.0);
    EXPECT_DOUBLE_EQ(pr.recall, 1.0);
    EXPECT_DOUBLE_EQ(pr.f_score, 1.0);
  }
}

TEST(SurfaceEval, WallsShiftedByTenCentimetres) {
  const Rig rig = MakeRingRig();
  const TriangleMesh gt_room = MakeRoom(0.0);
  const TriangleMesh estimated_room = MakeRoom(0.1);  // every wall 10 cm along its normal
  const RayCaster gt(gt_room), estimated(estimated_room);
  RayErrorOptions options;
  options.pixels = 20000;
  const RayErrorResult result = EvaluateRayErrors(rig, SamePoses(), estimated, gt, options);
  EXPECT_DOUBLE_EQ(result.share_both_hit, 1.0);
  // The estimated hit lies 10 cm inside every wall: the GT hit is at least that far, and
  // farther for oblique rays.
  EXPECT_GT(result.sorted_errors.front(), 0.1 - 1e-4);
  EXPECT_NEAR(result.quantiles[0], 0.1, 0.02);  // q10
  EXPECT_LT(result.quantiles[4], 0.3);          // median: the floor and ceiling are seen obliquely
  EXPECT_EQ(result.share_above_large, 0.0);

  SurfaceCompareOptions compare;
  compare.samples = 20000;
  compare.visibility_rays = 100000;
  const SurfaceCompareResult surfaces =
      CompareSurfaces(estimated_room, estimated, gt_room, gt, rig, MakePoses(), compare);
  EXPECT_NEAR(surfaces.accuracy.median, 0.1, 1e-4);
  EXPECT_NEAR(surfaces.accuracy.max, 0.1, 1e-4);
  EXPECT_NEAR(surfaces.completeness.median, 0.1, 1e-4);
  ASSERT_EQ(surfaces.precision_recall.size(), 2u);
  EXPECT_DOUBLE_EQ(surfaces.precision_recall[0].precision, 1.0);  // all within 0.2 m
  EXPECT_GT(surfaces.precision_recall[0].recall, 0.99);           // corners are farther

  // The same walls moved by 30 cm fail at 0.2 m and pass at 0.5 m.
  const TriangleMesh far_room = MakeRoom(0.3);
  const RayCaster far_caster(far_room);
  const SurfaceCompareResult far_surfaces =
      CompareSurfaces(far_room, far_caster, gt_room, gt, rig, MakePoses(), compare);
  EXPECT_DOUBLE_EQ(far_surfaces.precision_recall[0].precision, 0.0);
  EXPECT_DOUBLE_EQ(far_surfaces.precision_recall[1].precision, 1.0);
}

TEST(SurfaceEval, SphereShiftedAlongNormalsSeenFromItsCentre) {
  const Rig rig = MakeRingRig();
  const TriangleMesh gt_sphere = FlipOrientation(MakeIcosphere({5, 5, 1.5}, 10.0, 4));
  // The normals of the flipped sphere point inwards: 10 cm towards the centre.
  const TriangleMesh estimated_sphere = OffsetAlongNormals(gt_sphere, 0.1);
  const RayCaster gt(gt_sphere), estimated(estimated_sphere);
  std::vector<KeyframePoses> keyframes;
  for (int i = 0; i < 3; ++i) {
    const Rigid3d pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.5 * i, Eigen::Vector3d::UnitZ())),
                       Eigen::Vector3d(5, 5, 1.5));
    keyframes.push_back({pose, pose});
  }
  RayErrorOptions options;
  options.pixels = 20000;
  const RayErrorResult result = EvaluateRayErrors(rig, keyframes, estimated, gt, options);
  EXPECT_DOUBLE_EQ(result.share_both_hit, 1.0);
  EXPECT_NEAR(result.sorted_errors.front(), 0.1, 0.002);
  EXPECT_NEAR(result.sorted_errors.back(), 0.1, 0.002);
  for (double q : result.quantiles) EXPECT_NEAR(q, 0.1, 0.002);
}

TEST(SurfaceEval, VisibilityLimitsCompleteness) {
  const Rig rig = MakeRingRig();
  const TriangleMesh room = MakeRoom(0.0);
  const RayCaster caster(room);
  SurfaceCompareOptions compare;
  compare.samples = 20000;
  compare.visibility_rays = 100000;
  compare.max_ray_length = 5.0;  // the far walls are out of reach
  const SurfaceCompareResult surfaces =
      CompareSurfaces(room, caster, room, caster, rig, MakePoses(), compare);
  EXPECT_LT(surfaces.gt_samples_seen, 0.7 * surfaces.gt_samples);
  EXPECT_GT(surfaces.gt_samples_seen, 0);
}

TEST(SurfaceEval, PointDistancesToMesh) {
  const RayCaster caster(MakeRoom(0.0));
  const PointDistanceResult result =
      PointDistances({{0, 0, 1}, {0, 0, 2}, {0, 0, 3.5}, {9, 0, 2}}, caster);
  EXPECT_EQ(result.points, 4);
  EXPECT_NEAR(result.distances.median, 1.0, 1e-6);  // distances 1, 2, 0.5, 1
  EXPECT_NEAR(result.distances.max, 2.0, 1e-6);
}

TEST(SurfaceEval, NoKeyframeIsInputError) {
  const RayCaster caster(MakeRoom(0.0));
  EXPECT_THROW(EvaluateRayErrors(MakeRingRig(), {}, caster, caster), InputError);
}

}  // namespace
}  // namespace omni
