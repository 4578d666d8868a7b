// GtKeyframeOptions::frame_rays on the short drive: the same points as without, each with its
// keyframes' rays and more, from the drive frames between its keyframes, each of which sees its
// point unoccluded.

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

}  // namespace
}  // namespace omni
