// `surface --colmap` in any world frame and at any keyframe spacing: the short drive's ground
// truth at Harris corners (pipeline/gt_keyframes.h) written as a COLMAP text model of its six
// cameras, as is and moved by a similarity (a COLMAP world has no up axis nor metres), read back
// by the loader with its up direction from the cameras (pipeline/world_up.h), sculpted, and the
// observed surface scored by its pixels against the ground truth; and a model of keyframes
// 0.4 m apart whose points reach 28 m, whose points the ray-length bound must not drop.

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "calib/mesh_check.h"
#include "calib/pose.h"
#include "calib/rig_io.h"
#include "eval/surface_eval.h"
#include "pipeline/colmap_keyframes.h"
#include "pipeline/gt_keyframes.h"
#include "raycast/raycast.h"
#include "surface/sculptor.h"
#include "tests/apps/short_drive.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

fs::path TempFolder(const std::string& name) {
  const fs::path path = fs::temp_directory_path() / ("omni_surface_colmap_drive_test_" + name +
                                                     "_" + std::to_string(::getpid()));
  fs::remove_all(path);
  return path;
}

// Writes a central stream as a COLMAP model in the world new_from_old: one image per keyframe and
// camera ("cam<c>/<keyframe>.png"), oriented as the rig's camera at the keyframe's pose, centred
// at the keyframe centre (the rays' origin of the ground-truth stream, whatever rig.json's
// `central` says); each point's track names camera 0 of each keyframe of its rays.
void WriteColmapModel(const fs::path& folder, const std::vector<SurfaceKeyframe>& stream,
                      const std::vector<StampedPose>& poses, const Rig& rig,
                      const Sim3d& new_from_old) {
  fs::create_directories(folder);
  std::ofstream cameras(folder / "cameras.txt");
  cameras << "1 SIMPLE_PINHOLE 640 480 500 320 240\n";
  std::ofstream images(folder / "images.txt");
  images.precision(17);
  const size_t num_cameras = rig.cameras.size();
  std::unordered_map<uint32_t, size_t> index_of;  // keyframe id -> index in stream
  for (size_t k = 0; k < stream.size(); ++k) {
    index_of[stream[k].id.value] = k;
    const Eigen::Vector3d centre = new_from_old * stream[k].centre;
    for (size_t c = 0; c < num_cameras; ++c) {
      const Eigen::Quaterniond world_from_cam =
          new_from_old.rotation *
          (poses[k].world_from_rig * rig.cameras[c].cam_from_rig.Inverse()).rotation;
      const Eigen::Quaterniond cam_from_world = world_from_cam.conjugate();
      const Eigen::Vector3d t = -(cam_from_world * centre);
      char name[64];
      std::snprintf(name, sizeof(name), "cam%zu/%06zu.png", c, k);
      images << 1 + k * num_cameras + c << " " << cam_from_world.w() << " " << cam_from_world.x()
             << " " << cam_from_world.y() << " " << cam_from_world.z() << " " << t.x() << " "
             << t.y() << " " << t.z() << " 1 " << name << "\n\n";
    }
  }
  std::ofstream points(folder / "points3D.txt");
  points.precision(17);
  for (const SurfaceKeyframe& kf : stream) {
    for (const SurfacePoint& p : kf.points) {
      const Eigen::Vector3d x = new_from_old * p.position;
      points << p.id.value << " " << x.x() << " " << x.y() << " " << x.z() << " 128 128 128 0.5";
      for (const SurfaceRay& ray : p.rays) {
        points << " " << 1 + index_of.at(ray.keyframe.value) * num_cameras << " 0";
      }
      points << "\n";
    }
  }
}

struct Sculpted {
  PixelScores pixel;
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  size_t points_in = 0, too_far = 0, below_ground = 0;
  double scale = 0.0;
};

// Reads the model, sculpts it with the up direction from its cameras and scores surface.ply
// (moved back by old_from_new) against the ground truth.
// keep_up: the ground filter's up stays options.up (the world's z, as before the up direction
// was found from the cameras).
Sculpted SculptModel(const fs::path& model, const Sim3d& old_from_new, const Rig& rig,
                     const std::vector<KeyframePoses>& keyframes, const RayCaster& gt_caster,
                     SculptorOptions options, bool keep_up = false) {
  Sculpted out;
  const std::vector<SurfaceKeyframe> stream = LoadColmapKeyframes(model, nullptr, &out.up);
  if (!keep_up) options.up = out.up;
  IncrementalSculptor sculptor(options);
  auto count = [&out](const std::vector<KeyframeStats>& rows) {
    for (const KeyframeStats& row : rows) {
      out.points_in += row.points_in;
      out.too_far += row.points_filtered_length;
      out.below_ground += row.points_filtered_ground;
    }
  };
  for (const SurfaceKeyframe& kf : stream) count(sculptor.AddKeyframe(kf));
  count(sculptor.Finish());
  out.scale = sculptor.scale();
  TriangleMesh observed = sculptor.ExtractObservedMesh();
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  const MeshCheckReport report = CheckMesh(observed, bounded);
  EXPECT_TRUE(report.ok) << model << ": " << report.Summary();
  EXPECT_TRUE(CheckMesh(sculptor.ExtractMesh()).ok) << model;
  for (Eigen::Vector3d& v : observed.vertices) v = old_from_new * v;
  RayErrorOptions scoring;
  scoring.pixels = 200000;
  out.pixel = EvaluateRayErrors(rig, keyframes, RayCaster(observed), gt_caster, scoring).pixel;
  if (out.pixel.precision_recall.size() == 2) {  // the figures of docs/figures.md
    std::printf(
        "%s: s %.3f, %zu points, %zu below the ground, %zu too far; pixel F %.3f / %.3f, "
        "tail %.1f %% (%.1f / %.1f)\n",
        model.filename().c_str(), out.scale, out.points_in, out.below_ground, out.too_far,
        out.pixel.precision_recall[0].f_score, out.pixel.precision_recall[1].f_score,
        100.0 * out.pixel.tail, 100.0 * out.pixel.tail_front, 100.0 * out.pixel.tail_behind);
  }
  return out;
}

struct Drive {
  Rig rig;
  std::vector<SurfaceKeyframe> stream;
  std::vector<StampedPose> poses;
  std::vector<KeyframePoses> keyframes;
  TriangleMesh gt_mesh;
};

Drive LoadDrive(const fs::path& drive, const GtKeyframeOptions& gt) {
  Drive d;
  d.stream = LoadGtKeyframes(drive, gt, &d.gt_mesh, &d.poses);
  d.rig = ReadRigJson(drive / "rig.json");
  for (const StampedPose& pose : d.poses)
    d.keyframes.push_back({pose.world_from_rig, pose.world_from_rig});
  return d;
}

TEST(SurfaceColmapShortDrive, AModelMovedByASimilaritySculptsTheSameSurface) {
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  GtKeyframeOptions gt;
  gt.max_keyframes = 20;
  const Drive d = LoadDrive(drive, gt);
  ASSERT_EQ(d.stream.size(), 20u);
  const RayCaster gt_caster(d.gt_mesh);
  const fs::path dir = TempFolder("similarity");
  // A rotation far from any axis, the scale of a COLMAP world (no metres), a far origin.
  const Sim3d moved(
      0.37,
      Eigen::Quaterniond(Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized())),
      Eigen::Vector3d(41.0, -7.5, 12.25));
  WriteColmapModel(dir / "as_is", d.stream, d.poses, d.rig, Sim3d());
  WriteColmapModel(dir / "moved", d.stream, d.poses, d.rig, moved);
  SculptorOptions options;
  options.init_keyframes = 10;  // a batch of 10, then 10 keyframes one by one
  const Sculpted as_is =
      SculptModel(dir / "as_is", Sim3d(), d.rig, d.keyframes, gt_caster, options);
  const Sculpted after =
      SculptModel(dir / "moved", moved.Inverse(), d.rig, d.keyframes, gt_caster, options);
  // As before: the world's z as up, the ground 3 s below the keyframes.
  SculptorOptions before = options;
  before.reach_quantile = 0.0;
  before.ground_quantile = 0.0;
  const Sculpted z_up =
      SculptModel(dir / "moved", moved.Inverse(), d.rig, d.keyframes, gt_caster, before, true);
  fs::remove_all(dir);
  // With the world's z as up in the moved world, the ground filter drops points at random.
  EXPECT_GT(z_up.below_ground, as_is.below_ground + as_is.points_in / 20);

  // The up direction found from the cameras is the drive's z, moved.
  EXPECT_GT(as_is.up.dot(Eigen::Vector3d::UnitZ()), std::cos(2.0 * M_PI / 180.0)) << as_is.up;
  EXPECT_GT(after.up.dot(moved.rotation * Eigen::Vector3d::UnitZ()), std::cos(2.0 * M_PI / 180.0))
      << after.up;
  EXPECT_NEAR(after.scale, moved.scale * as_is.scale, 1e-6 * as_is.scale);
  EXPECT_EQ(after.below_ground, as_is.below_ground);
  EXPECT_EQ(after.too_far, as_is.too_far);
  // The same surface quality (the Steiner grid's cells differ, so not the same triangles).
  ASSERT_EQ(as_is.pixel.precision_recall.size(), 2u);
  ASSERT_EQ(after.pixel.precision_recall.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_NEAR(after.pixel.precision_recall[i].f_score, as_is.pixel.precision_recall[i].f_score,
                0.02)
        << "at " << as_is.pixel.precision_recall[i].threshold << " m";
  }
  EXPECT_GT(as_is.pixel.precision_recall[1].f_score, 0.7);
  EXPECT_NEAR(after.pixel.tail, as_is.pixel.tail, 0.01);
}

TEST(SurfaceColmapShortDrive, KeyframesDenserThanThePointsReachDropFewPointsAsTooFar) {
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  // Every frame a keyframe, 0.4 m apart, with points up to 28 m away, as a COLMAP model of a
  // drive's every frame has them.
  GtKeyframeOptions gt;
  gt.keyframe_spacing = 0.4;
  gt.max_distance_factor = 70.0;
  gt.max_keyframes = 24;
  const Drive d = LoadDrive(drive, gt);
  ASSERT_EQ(d.stream.size(), 24u);
  const RayCaster gt_caster(d.gt_mesh);
  const fs::path dir = TempFolder("dense");
  WriteColmapModel(dir / "model", d.stream, d.poses, d.rig, Sim3d());
  SculptorOptions options;
  options.init_keyframes = 12;
  const Sculpted reach =
      SculptModel(dir / "model", Sim3d(), d.rig, d.keyframes, gt_caster, options);
  // The paper's bounds, in units of the keyframe spacing: r = 15 s, the ground 3 s below.
  options.reach_quantile = 0.0;
  options.ground_quantile = 0.0;
  const Sculpted paper =
      SculptModel(dir / "model", Sim3d(), d.rig, d.keyframes, gt_caster, options);
  fs::remove_all(dir);

  ASSERT_GT(reach.points_in, 1000u);
  EXPECT_LT(paper.scale, 0.8);  // every frame a keyframe
  EXPECT_GT(reach.scale, 1.5 * paper.scale);
  const size_t paper_dropped = paper.too_far + paper.below_ground;
  const size_t reach_dropped = reach.too_far + reach.below_ground;
  EXPECT_GT(paper_dropped, reach.points_in / 2) << "the paper's bounds drop most points";
  EXPECT_LT(reach_dropped, reach.points_in / 5) << reach_dropped << " of " << reach.points_in;
  ASSERT_EQ(reach.pixel.precision_recall.size(), 2u);
  EXPECT_GT(reach.pixel.precision_recall[1].f_score, paper.pixel.precision_recall[1].f_score + 0.1);
}

}  // namespace
}  // namespace omni
