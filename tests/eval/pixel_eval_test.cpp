// The pixel precision / recall / F-score and the error tail of EvaluateRayErrors on hand-made
// scenes seen by narrow pinhole cameras (about 11° × 9°), so every ray meets a wall nearly
// square and an offset of a wall is the error of every pixel within a few per cent.

#include <gtest/gtest.h>

#include <cmath>

#include "eval/primitives.h"
#include "eval/surface_eval.h"
#include "raycast/raycast.h"

namespace omni {
namespace {

// A 40 × 30 pinhole camera (f = 200 px) at the rig origin looking along `forward` (horizontal),
// image x to the right and y down, z up in the world.
Camera NarrowCamera(const std::string& name, const Eigen::Vector3d& forward) {
  Camera camera;
  camera.name = name;
  camera.width = 40;
  camera.height = 30;
  camera.model = CameraModel::kPinhole;
  camera.params = {200.0, 200.0, 19.5, 14.5};
  Eigen::Matrix3d rig_from_cam;
  rig_from_cam.col(2) = forward.normalized();
  rig_from_cam.col(0) = rig_from_cam.col(2).cross(Eigen::Vector3d::UnitZ()).normalized();
  rig_from_cam.col(1) = rig_from_cam.col(2).cross(rig_from_cam.col(0));
  camera.cam_from_rig.rotation = Eigen::Quaterniond(rig_from_cam.transpose());
  camera.cam_from_rig.translation = Eigen::Vector3d::Zero();
  return camera;
}

Rig OneCameraRig() {
  Rig rig;
  rig.name = "narrow";
  rig.cameras.push_back(NarrowCamera("front", Eigen::Vector3d::UnitX()));
  return rig;
}

// Three keyframes at `height`, a little apart and turned a little, estimated = true.
std::vector<KeyframePoses> Keyframes(double height = 0.0) {
  std::vector<KeyframePoses> keyframes;
  for (int i = 0; i < 3; ++i) {
    const Rigid3d pose(
        Eigen::Quaterniond(Eigen::AngleAxisd(0.01 * (i - 1), Eigen::Vector3d::UnitZ())),
        Eigen::Vector3d(0.0, 0.2 * (i - 1), height));
    keyframes.push_back({pose, pose});
  }
  return keyframes;
}

// A wall across the x axis whose face towards the origin is at x = `at` (1 m thick, 100 m wide).
TriangleMesh WallAtX(double at) { return MakeBox({at, -50, -50}, {at + 1, 50, 50}); }

RayErrorOptions Options() {
  RayErrorOptions options;
  options.pixels = 5000;
  return options;
}

const PixelPrecisionRecall& At(const PixelScores& scores, size_t threshold) {
  return scores.precision_recall.at(threshold);
}

TEST(PixelEval, DefaultThresholdsAreTwentyAndFiftyCentimetres) {
  const RayErrorOptions options;
  ASSERT_EQ(options.pixel_thresholds.size(), 2u);
  EXPECT_DOUBLE_EQ(options.pixel_thresholds[0], 0.2);
  EXPECT_DOUBLE_EQ(options.pixel_thresholds[1], 0.5);
  EXPECT_DOUBLE_EQ(options.pixel_tail_error, 1.0);
  RayErrorOptions bad;
  bad.pixel_thresholds = {0.2, 0.0};
  EXPECT_FALSE(bad.Check().empty());
  bad.pixel_thresholds = {0.2};
  bad.pixel_tail_error = -1.0;
  EXPECT_FALSE(bad.Check().empty());
}

TEST(PixelEval, WallShiftedThirtyCentimetresFailsAtTwentyAndPassesAtFifty) {
  const Rig rig = OneCameraRig();
  const RayCaster gt(WallAtX(10.0));
  for (const double shift : {-0.3, 0.3}) {  // towards the camera, away from it
    SCOPED_TRACE(shift);
    const RayCaster estimated(WallAtX(10.0 + shift));
    const RayErrorResult result = EvaluateRayErrors(rig, Keyframes(), estimated, gt, Options());
    const PixelScores& p = result.pixel;
    EXPECT_EQ(p.rays, 5000);
    EXPECT_EQ(p.estimated_hits, 5000);
    EXPECT_EQ(p.gt_hits, 5000);
    EXPECT_EQ(p.both_hits, 5000);
    ASSERT_EQ(p.precision_recall.size(), 2u);
    EXPECT_DOUBLE_EQ(At(p, 0).threshold, 0.2);
    EXPECT_EQ(At(p, 0).within, 0);
    EXPECT_DOUBLE_EQ(At(p, 0).precision, 0.0);
    EXPECT_DOUBLE_EQ(At(p, 0).recall, 0.0);
    EXPECT_DOUBLE_EQ(At(p, 0).f_score, 0.0);
    EXPECT_EQ(At(p, 1).within, 5000);
    EXPECT_DOUBLE_EQ(At(p, 1).precision, 1.0);
    EXPECT_DOUBLE_EQ(At(p, 1).recall, 1.0);
    EXPECT_DOUBLE_EQ(At(p, 1).f_score, 1.0);
    EXPECT_EQ(p.tail_count, 0);
    EXPECT_DOUBLE_EQ(p.tail, 0.0);
  }
}

TEST(PixelEval, TailIsInFrontWhenTheEstimateIsNearerTheCamera) {
  const Rig rig = OneCameraRig();
  const RayCaster gt(WallAtX(10.0));
  const RayCaster nearer(WallAtX(8.5)), farther(WallAtX(11.5));
  const RayErrorResult front = EvaluateRayErrors(rig, Keyframes(), nearer, gt, Options());
  EXPECT_EQ(front.pixel.tail_count, 5000);
  EXPECT_EQ(front.pixel.tail_front_count, 5000);
  EXPECT_EQ(front.pixel.tail_behind_count, 0);
  EXPECT_DOUBLE_EQ(front.pixel.tail, 1.0);
  EXPECT_DOUBLE_EQ(front.pixel.tail_front, 1.0);
  EXPECT_DOUBLE_EQ(front.pixel.tail_behind, 0.0);
  EXPECT_DOUBLE_EQ(At(front.pixel, 1).f_score, 0.0);

  const RayErrorResult behind = EvaluateRayErrors(rig, Keyframes(), farther, gt, Options());
  EXPECT_EQ(behind.pixel.tail_count, 5000);
  EXPECT_EQ(behind.pixel.tail_front_count, 0);
  EXPECT_EQ(behind.pixel.tail_behind_count, 5000);
  EXPECT_DOUBLE_EQ(behind.pixel.tail_behind, 1.0);
  EXPECT_DOUBLE_EQ(behind.pixel.tail_front, 0.0);
}

TEST(PixelEval, InFrontIsMeasuredFromTheCameraOfEachPose) {
  // The estimated pose is 2 m behind the true one and its wall 1.5 m nearer the true camera
  // than the true wall: in the world the estimated hit is nearer the true camera, but it is
  // 10.5 m from its own camera against 10 m: behind.
  const Rig rig = OneCameraRig();
  std::vector<KeyframePoses> keyframes = Keyframes();
  for (KeyframePoses& k : keyframes) k.estimated_world_from_rig.translation.x() -= 2.0;
  const RayCaster gt(WallAtX(10.0)), estimated(WallAtX(8.5));
  const RayErrorResult result = EvaluateRayErrors(rig, keyframes, estimated, gt, Options());
  EXPECT_EQ(result.pixel.tail_count, 5000);
  EXPECT_EQ(result.pixel.tail_behind_count, 5000);
  EXPECT_EQ(result.pixel.tail_front_count, 0);
}

TEST(PixelEval, PlateInFrontOfHalfTheViewIsTheFrontTail) {
  // A plate 5 m from the camera hides the left half of the view (y > 0) of the wall at 10 m.
  const Rig rig = OneCameraRig();
  TriangleMesh scene = WallAtX(10.0);
  AppendMesh(MakeBox({5.0, 0.0, -50}, {5.1, 50, 50}), &scene);
  const RayCaster gt(WallAtX(10.0)), estimated(scene);
  std::vector<KeyframePoses> keyframes;
  const Rigid3d pose = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero());
  keyframes.push_back({pose, pose});
  const RayErrorResult result = EvaluateRayErrors(rig, keyframes, estimated, gt, Options());
  const PixelScores& p = result.pixel;
  EXPECT_EQ(p.both_hits, 5000);
  EXPECT_NEAR(p.tail, 0.5, 0.05);
  EXPECT_DOUBLE_EQ(p.tail_front, p.tail);
  EXPECT_EQ(p.tail_behind_count, 0);
  EXPECT_EQ(At(p, 1).within + p.tail_count, 5000);
  EXPECT_NEAR(At(p, 1).precision, 0.5, 0.05);
  EXPECT_NEAR(At(p, 1).recall, 0.5, 0.05);
}

TEST(PixelEval, CeilingOverTheStreetLowersPrecisionNotRecall) {
  // The street: the ground and a building across its end, 30 m ahead and 2.5 m high; above the
  // building the camera (1.5 m above the ground) sees the sky. The estimate closes the sky with a
  // ceiling at 4 m: the sky pixels get an estimated hit and no ground-truth one.
  const Rig rig = OneCameraRig();
  TriangleMesh street = MakeBox({-10, -50, -1}, {200, 50, 0});
  AppendMesh(MakeBox({30, -50, -1}, {31, 50, 2.5}), &street);
  TriangleMesh closed = street;
  AppendMesh(MakeBox({-10, -50, 4}, {200, 50, 5}), &closed);
  const RayCaster gt(street), estimated(closed);

  const RayErrorResult same = EvaluateRayErrors(rig, Keyframes(1.5), gt, gt, Options());
  ASSERT_GT(same.pixel.gt_hits, 0);
  EXPECT_LT(same.pixel.gt_hits, 5000);  // the sky
  for (const PixelPrecisionRecall& pr : same.pixel.precision_recall) {
    EXPECT_DOUBLE_EQ(pr.precision, 1.0);
    EXPECT_DOUBLE_EQ(pr.recall, 1.0);
  }

  const RayErrorResult result = EvaluateRayErrors(rig, Keyframes(1.5), estimated, gt, Options());
  const PixelScores& p = result.pixel;
  EXPECT_EQ(p.estimated_hits, 5000);
  EXPECT_EQ(p.gt_hits, same.pixel.gt_hits);
  EXPECT_EQ(p.both_hits, p.gt_hits);
  for (const PixelPrecisionRecall& pr : p.precision_recall) {
    SCOPED_TRACE(pr.threshold);
    EXPECT_EQ(pr.within, p.gt_hits);
    EXPECT_DOUBLE_EQ(pr.recall, 1.0);
    EXPECT_DOUBLE_EQ(pr.precision, static_cast<double>(p.gt_hits) / p.estimated_hits);
    EXPECT_LT(pr.precision, 0.85);
    EXPECT_LT(pr.f_score, 1.0);
  }
  EXPECT_EQ(p.tail_count, 0);
}

TEST(PixelEval, CamerasAddUpToTheTotal) {
  // "front" sees a wall estimated 30 cm too near, "back" an estimated wall where the truth has
  // nothing, "left" a wall estimated 1.5 m too far.
  Rig rig;
  rig.name = "three";
  rig.cameras.push_back(NarrowCamera("front", Eigen::Vector3d::UnitX()));
  rig.cameras.push_back(NarrowCamera("back", -Eigen::Vector3d::UnitX()));
  rig.cameras.push_back(NarrowCamera("left", Eigen::Vector3d::UnitY()));
  TriangleMesh truth = WallAtX(10.0);
  AppendMesh(MakeBox({-50, 10, -50}, {50, 11, 50}), &truth);
  TriangleMesh estimate = WallAtX(9.7);
  AppendMesh(MakeBox({-50, 11.5, -50}, {50, 12.5, 50}), &estimate);
  AppendMesh(MakeBox({-11, -50, -50}, {-10, 50, 50}), &estimate);
  const RayCaster gt(truth), estimated(estimate);
  RayErrorOptions options = Options();
  options.pixels = 6000;
  const RayErrorResult result = EvaluateRayErrors(rig, Keyframes(), estimated, gt, options);

  ASSERT_EQ(result.pixel_cameras.size(), 3u);
  EXPECT_EQ(result.pixel_cameras[0].camera, "front");
  EXPECT_EQ(result.pixel_cameras[1].camera, "back");
  EXPECT_EQ(result.pixel_cameras[2].camera, "left");
  EXPECT_TRUE(result.pixel.camera.empty());
  PixelScores sum;
  std::vector<long> within(options.pixel_thresholds.size(), 0);
  for (const PixelScores& c : result.pixel_cameras) {
    EXPECT_GT(c.rays, 0) << c.camera;
    sum.rays += c.rays;
    sum.estimated_hits += c.estimated_hits;
    sum.gt_hits += c.gt_hits;
    sum.both_hits += c.both_hits;
    sum.tail_count += c.tail_count;
    sum.tail_front_count += c.tail_front_count;
    sum.tail_behind_count += c.tail_behind_count;
    ASSERT_EQ(c.precision_recall.size(), within.size());
    for (size_t t = 0; t < within.size(); ++t) within[t] += c.precision_recall[t].within;
  }
  const PixelScores& p = result.pixel;
  EXPECT_EQ(p.rays, 6000);
  EXPECT_EQ(sum.rays, p.rays);
  EXPECT_EQ(sum.estimated_hits, p.estimated_hits);
  EXPECT_EQ(sum.gt_hits, p.gt_hits);
  EXPECT_EQ(sum.both_hits, p.both_hits);
  EXPECT_EQ(sum.tail_count, p.tail_count);
  EXPECT_EQ(sum.tail_front_count, p.tail_front_count);
  EXPECT_EQ(sum.tail_behind_count, p.tail_behind_count);
  for (size_t t = 0; t < within.size(); ++t) EXPECT_EQ(within[t], p.precision_recall[t].within);
  EXPECT_EQ(p.rays, result.rays);
  EXPECT_EQ(p.estimated_hits, result.estimated_hits);
  EXPECT_EQ(p.gt_hits, result.gt_hits);
  EXPECT_EQ(p.both_hits, result.both_hits);

  const PixelScores &front = result.pixel_cameras[0], &back = result.pixel_cameras[1],
                    &left = result.pixel_cameras[2];
  EXPECT_DOUBLE_EQ(At(front, 1).f_score, 1.0);
  EXPECT_DOUBLE_EQ(At(front, 0).f_score, 0.0);
  EXPECT_EQ(back.gt_hits, 0);
  EXPECT_EQ(back.estimated_hits, back.rays);
  EXPECT_DOUBLE_EQ(At(back, 1).precision, 0.0);
  EXPECT_DOUBLE_EQ(At(back, 1).recall, 0.0);
  EXPECT_EQ(left.tail_behind_count, left.rays);
  EXPECT_DOUBLE_EQ(left.tail_behind, 1.0);
  // In total: right at 0.5 m only the front camera's pixels.
  EXPECT_EQ(At(p, 1).within, front.rays);
  EXPECT_EQ(p.estimated_hits, p.rays);
  EXPECT_DOUBLE_EQ(At(p, 1).precision, static_cast<double>(front.rays) / p.rays);
  EXPECT_DOUBLE_EQ(At(p, 1).recall, static_cast<double>(front.rays) / (front.rays + left.rays));
  EXPECT_DOUBLE_EQ(p.tail, static_cast<double>(left.rays) / (front.rays + left.rays));
  EXPECT_DOUBLE_EQ(p.tail_behind, p.tail);
}

TEST(PixelEval, ConfiguredThresholds) {
  const Rig rig = OneCameraRig();
  const RayCaster gt(WallAtX(10.0)), estimated(WallAtX(10.3));
  RayErrorOptions options = Options();
  options.pixel_thresholds = {0.1, 0.25, 0.35, 2.0};
  const RayErrorResult result = EvaluateRayErrors(rig, Keyframes(), estimated, gt, options);
  ASSERT_EQ(result.pixel.precision_recall.size(), 4u);
  EXPECT_DOUBLE_EQ(At(result.pixel, 0).f_score, 0.0);
  EXPECT_DOUBLE_EQ(At(result.pixel, 1).f_score, 0.0);
  EXPECT_DOUBLE_EQ(At(result.pixel, 2).f_score, 1.0);
  EXPECT_DOUBLE_EQ(At(result.pixel, 3).f_score, 1.0);
  EXPECT_DOUBLE_EQ(At(result.pixel, 3).threshold, 2.0);
}

// The primitives keep the labels one per triangle: appended when both meshes have them, kept by
// the welding, dropped when one part has none.
TEST(PixelEval, PrimitivesKeepTheLabelsOnePerTriangle) {
  TriangleMesh a = MakeBox({0, 0, 0}, {1, 1, 1}), b = MakeBox({1, 1, 1}, {2, 2, 2});
  a.labels.assign(a.triangles.size(), 4);
  b.labels.assign(b.triangles.size(), 9);
  TriangleMesh both;
  AppendMesh(a, &both);
  AppendMesh(b, &both);
  ASSERT_EQ(both.labels.size(), both.triangles.size());
  EXPECT_EQ(both.labels.front(), 4);
  EXPECT_EQ(both.labels.back(), 9);
  EXPECT_EQ(WeldVertices(both).labels, both.labels);
  AppendMesh(MakeBox({3, 3, 3}, {4, 4, 4}), &both);
  EXPECT_TRUE(both.labels.empty());
}

// The figures per label of the ground truth's triangles: a pole (a plate 5 m away over the left
// half of the view, y > 0) that the estimate lacks, in front of a wall at 10 m; a box at 7 m over
// the lower right quarter, in both. The pole's pixels are all behind the truth, the wall's and
// the box's all right; the labels add up to the total.
TEST(PixelEval, LabelsOfTheGroundTruthSplitThePixels) {
  const Rig rig = OneCameraRig();
  constexpr uint8_t kPole = 1, kWall = 3, kBox = 7;
  const TriangleMesh wall = WallAtX(10.0);
  const TriangleMesh pole = MakeBox({5.0, 0.0, -50}, {5.1, 50, 50});
  const TriangleMesh box = MakeBox({7.0, -50, -50}, {8.0, 0.0, 0.0});
  TriangleMesh truth = wall, estimate = wall;
  AppendMesh(pole, &truth);
  AppendMesh(box, &truth);
  AppendMesh(box, &estimate);
  GtLabels labels;
  labels.per_triangle.insert(labels.per_triangle.end(), wall.triangles.size(), kWall);
  labels.per_triangle.insert(labels.per_triangle.end(), pole.triangles.size(), kPole);
  labels.per_triangle.insert(labels.per_triangle.end(), box.triangles.size(), kBox);
  labels.names = {"road", "pole", "glass", "wall"};  // kBox has no name
  const RayCaster gt(truth), estimated(estimate);
  std::vector<KeyframePoses> keyframes;
  const Rigid3d pose(Eigen::Quaterniond::Identity(), Eigen::Vector3d::Zero());
  keyframes.push_back({pose, pose});
  const RayErrorResult result = EvaluateRayErrors(rig, keyframes, estimated, gt, Options(), labels);
  ASSERT_EQ(result.pixel_labels.size(), 5u);  // the four named, and the one met without a name
  const std::vector<std::string> names = {"road", "pole", "glass", "wall", "label 7"};
  for (size_t i = 0; i < names.size(); ++i) EXPECT_EQ(result.pixel_labels[i].label, names[i]);
  const PixelScores &road = result.pixel_labels[0], &pole_scores = result.pixel_labels[1],
                    &wall_scores = result.pixel_labels[3], &box_scores = result.pixel_labels[4];
  EXPECT_EQ(road.gt_hits, 0);
  EXPECT_EQ(road.tail, 0.0);
  EXPECT_NEAR(pole_scores.gt_hits, 2500, 150);
  EXPECT_NEAR(wall_scores.gt_hits, 1250, 150);
  EXPECT_NEAR(box_scores.gt_hits, 1250, 150);
  EXPECT_EQ(pole_scores.both_hits, pole_scores.gt_hits);
  EXPECT_DOUBLE_EQ(At(pole_scores, 1).recall, 0.0);
  EXPECT_DOUBLE_EQ(pole_scores.tail_behind, 1.0);
  EXPECT_EQ(pole_scores.tail_front_count, 0);
  for (const PixelScores* right : {&wall_scores, &box_scores}) {
    EXPECT_DOUBLE_EQ(At(*right, 0).recall, 1.0);
    EXPECT_DOUBLE_EQ(At(*right, 0).precision, 1.0);
    EXPECT_EQ(right->tail_count, 0);
  }
  long gt_hits = 0, behind = 0, within = 0;
  for (const PixelScores& p : result.pixel_labels) {
    gt_hits += p.gt_hits;
    behind += p.tail_behind_count;
    within += At(p, 1).within;
    EXPECT_EQ(p.camera, "");
  }
  EXPECT_EQ(gt_hits, result.pixel.gt_hits);
  EXPECT_EQ(behind, result.pixel.tail_behind_count);
  EXPECT_EQ(within, At(result.pixel, 1).within);

  // Without labels, no figures per label; a label list shorter than the triangles hit is a bug
  // of the caller.
  EXPECT_TRUE(EvaluateRayErrors(rig, keyframes, estimated, gt, Options()).pixel_labels.empty());
  labels.per_triangle.resize(wall.triangles.size());
  EXPECT_THROW(EvaluateRayErrors(rig, keyframes, estimated, gt, Options(), labels),
               std::invalid_argument);
}

}  // namespace
}  // namespace omni
