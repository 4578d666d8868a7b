// GtKeyframeOptions::frame_rays on the short drive: the same points as without, each with its
// keyframes' rays and more, from the drive frames between its keyframes, each of which sees its
// point unoccluded; sky_rays_per_camera: free rays that see nothing.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "pipeline/gt_keyframes.h"
#include "raycast/raycast.h"
#include "tests/apps/short_drive.h"

namespace omni {
namespace {

TEST(GtFrameRaysShortDrive, EveryTrackedFrameAddsARayToThePointsItSees) {
  std::string error;
  const std::filesystem::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  GtKeyframeOptions options;
  options.max_keyframes = 8;
  TriangleMesh mesh;
  std::vector<size_t> frames;
  const std::vector<SurfaceKeyframe> keyframe_rays =
      LoadGtKeyframes(drive, options, &mesh, nullptr, &frames);
  options.frame_rays = true;
  const std::vector<SurfaceKeyframe> frame_rays = LoadGtKeyframes(drive, options);
  ASSERT_EQ(frame_rays.size(), keyframe_rays.size());
  ASSERT_GT(frames.size(), 2u);
  ASSERT_GT(frames[1], frames[0] + 1) << "no frame between the first two keyframes";

  const Rig rig = ReadRigJson(drive / "rig.json");
  std::vector<Eigen::Vector3d> centres;
  for (const StampedPose& pose : ReadTum(drive / "gt" / "poses.tum"))
    centres.push_back(pose.world_from_rig * rig.CentralCenterInRig());
  const RayCaster caster(mesh);
  size_t before = 0, after = 0, extra = 0;
  for (size_t t = 0; t < frame_rays.size(); ++t) {
    ASSERT_EQ(frame_rays[t].points.size(), keyframe_rays[t].points.size());
    for (size_t i = 0; i < frame_rays[t].points.size(); ++i) {
      const SurfacePoint& a = keyframe_rays[t].points[i];
      const SurfacePoint& b = frame_rays[t].points[i];
      ASSERT_EQ(a.id, b.id);
      ASSERT_EQ(a.position, b.position);
      ASSERT_GE(b.rays.size(), a.rays.size());
      before += a.rays.size();
      after += b.rays.size();
      for (size_t k = 0; k < a.rays.size(); ++k) EXPECT_EQ(b.rays[k].origin, a.rays[k].origin);
      for (size_t k = a.rays.size(); k < b.rays.size(); ++k) {
        const SurfaceRay& ray = b.rays[k];
        // From a frame strictly between keyframe ray.keyframe and the next, not after t.
        const size_t kf = ray.keyframe.value;
        ASSERT_LT(kf, t);
        bool between = false;
        for (size_t f = frames[kf] + 1; f < frames[kf + 1]; ++f)
          between = between || (centres[f] - ray.origin).norm() < 1e-9;
        EXPECT_TRUE(between) << "point " << b.id.value;
        const Eigen::Vector3d to = b.position - ray.origin;
        Ray cast;
        cast.origin = ray.origin;
        cast.direction = to.normalized();
        cast.max_distance = to.norm() * 1.01 + 1e-3;
        EXPECT_GE(caster.Cast(cast).distance, to.norm() * (1.0 - 1e-3) - 1e-3) << "occluded";
        ++extra;
      }
    }
  }
  EXPECT_GT(extra, before / 2) << before << " keyframe rays, " << after << " with the frames'";
}

// GtKeyframeOptions::sky_rays_per_camera: the free rays are the grid pixels that see nothing.
TEST(GtSkyRaysShortDrive, FreeRaysAreTheDirectionsThatSeeNoTriangle) {
  std::string error;
  const std::filesystem::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  GtKeyframeOptions options;
  options.max_keyframes = 4;
  TriangleMesh mesh;
  EXPECT_TRUE(LoadGtKeyframes(drive, options).front().free_rays.empty());
  options.sky_rays_per_camera = 200;
  const std::vector<SurfaceKeyframe> stream = LoadGtKeyframes(drive, options, &mesh);
  const RayCaster caster(mesh);
  const Rig rig = ReadRigJson(drive / "rig.json");
  for (const SurfaceKeyframe& kf : stream) {
    // The upper camera sees mostly sky, the side ones some: between a sixth of the grid and
    // all of it.
    EXPECT_GT(kf.free_rays.size(), 200u);
    EXPECT_LT(kf.free_rays.size(), 200u * rig.NumCameras() * 11 / 10);
    size_t hit = 0, up = 0;
    for (const SurfaceFreeRay& ray : kf.free_rays) {
      EXPECT_EQ(ray.origin, kf.centre);
      EXPECT_NEAR(ray.direction.norm(), 1.0, 1e-9);
      Ray cast;
      cast.origin = ray.origin;
      cast.direction = ray.direction;
      hit += std::isfinite(caster.Cast(cast).distance) ? 1 : 0;
      up += ray.direction.z() > 0.0 ? 1 : 0;
    }
    // Cast from the keyframe centre, not the camera's (a few centimetres away): a graze may hit.
    EXPECT_LT(hit, kf.free_rays.size() / 50 + 1);
    EXPECT_EQ(up, kf.free_rays.size());
  }
}

}  // namespace
}  // namespace omni
