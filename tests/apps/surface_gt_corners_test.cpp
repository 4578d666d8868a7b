// --from-gt's corner mode (pipeline/gt_keyframes.h): on a tiny synthetic drive with
// images, the points of a keyframe lie on the ground-truth mesh, project within a pixel of a
// Harris corner detected (independently, here) in one of the keyframe's images, number as many
// as asked, keep the rules of the simulated SfM (rays from earlier keyframes, no two points of
// one track); a drive without images falls back to the uniform sampling.

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <opencv2/core.hpp>

#include "apps/default_rig.h"
#include "pipeline/gt_keyframes.h"
#include "calib/drive.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "raycast/raycast.h"
#include "sfm/harris.h"
#include "synth/drive_writer.h"
#include "synth/synth_options.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

class GtCornersTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    folder_ = new fs::path(fs::temp_directory_path() /
                           ("surface_gt_corners_test_" + std::to_string(::getpid())));
    fs::remove_all(*folder_);
    SynthOptions options = SynthPresetOptions("tiny");
    options.trajectory.num_frames = 8;
    synth::SynthWriteOptions write;
    write.progress = false;
    synth::WriteSyntheticDrive(options, DefaultRig(), *folder_ / "drive", write);
  }
  static void TearDownTestSuite() {
    fs::remove_all(*folder_);
    delete folder_;
  }
  static fs::path Drive() { return *folder_ / "drive"; }
  static fs::path* folder_;
};
fs::path* GtCornersTest::folder_ = nullptr;

TEST_F(GtCornersTest, PointsLieOnTheMeshAtDetectedCornersAsManyAsAsked) {
  GtKeyframeOptions options;
  options.points_per_keyframe = 120;
  TriangleMesh mesh;
  std::vector<StampedPose> keyframe_poses;
  const std::vector<SurfaceKeyframe> stream =
      LoadGtKeyframes(Drive(), options, &mesh, &keyframe_poses);
  ASSERT_GE(stream.size(), 5u);
  ASSERT_EQ(keyframe_poses.size(), stream.size());

  // The frames of the keyframes, as the loader chooses them.
  const omni::Drive drive = omni::Drive::Open(Drive());
  const Rig& rig = drive.rig();
  const std::vector<StampedPose> poses = ReadTum(Drive() / "gt" / "poses.tum");
  std::vector<Eigen::Vector3d> centres;
  for (const StampedPose& pose : poses)
    centres.push_back(pose.world_from_rig * rig.CentralCenterInRig());
  const std::vector<size_t> frames = SelectKeyframeFrames(centres, options.keyframe_spacing);
  ASSERT_EQ(frames.size(), stream.size());

  const RayCaster mesh_caster(mesh);
  size_t checked = 0;
  for (size_t t = 0; t < stream.size(); ++t) {
    const SurfaceKeyframe& kf = stream[t];
    // The first keyframe has no earlier one to give a point its second ray (min_rays = 2).
    if (t == 0) {
      EXPECT_TRUE(kf.points.empty());
      continue;
    }
    EXPECT_EQ(static_cast<int>(kf.points.size()), options.points_per_keyframe) << "keyframe " << t;
    std::vector<Eigen::Vector3d> positions;
    for (const SurfacePoint& point : kf.points) positions.push_back(point.position);
    const std::vector<double> distances = mesh_caster.DistancesTo(positions, 1.0);
    for (size_t i = 0; i < distances.size(); ++i)
      EXPECT_LT(distances[i], 1e-4) << "keyframe " << t << " point " << i;

    // Harris corners of each camera's image of the keyframe (input pixels).
    std::vector<std::vector<Eigen::Vector2d>> corners(rig.NumCameras());
    for (size_t c = 0; c < rig.NumCameras(); ++c) {
      const cv::Mat prepared = PrepareImage(drive.LoadGray(frames[t], c), options.harris);
      for (const Corner& corner : DetectHarrisCorners(prepared, options.harris))
        corners[c].push_back(PreparedToInputPixel(corner.pixel, options.harris.downscale));
    }
    const Rigid3d rig_from_world = poses[frames[t]].world_from_rig.Inverse();
    for (const SurfacePoint& point : kf.points) {
      double nearest = std::numeric_limits<double>::infinity();
      for (size_t c = 0; c < rig.NumCameras(); ++c) {
        const Camera& camera = rig.cameras[c];
        Eigen::Vector2d pixel;
        if (!camera.Project(camera.cam_from_rig * (rig_from_world * point.position), &pixel) ||
            !camera.IsInImage(pixel))
          continue;
        for (const Eigen::Vector2d& corner : corners[c])
          nearest = std::min(nearest, (corner - pixel).norm());
      }
      EXPECT_LT(nearest, 1.0) << "keyframe " << t;
      ++checked;

      // The rules of the simulated SfM: rays from this or earlier keyframes, at least min_rays.
      EXPECT_GE(static_cast<int>(point.rays.size()), options.min_rays);
      for (const SurfaceRay& ray : point.rays) {
        EXPECT_LE(ray.keyframe.value, t);
        EXPECT_EQ(ray.origin, stream[ray.keyframe.value].centre);
      }
    }
  }
  EXPECT_GE(checked, 4u * options.points_per_keyframe);

  // One point per track: no two points closer than the merge distance.
  std::vector<Eigen::Vector3d> all;
  for (const SurfaceKeyframe& kf : stream)
    for (const SurfacePoint& point : kf.points) all.push_back(point.position);
  for (size_t i = 0; i < all.size(); ++i)
    for (size_t j = i + 1; j < all.size(); ++j)
      ASSERT_GE((all[i] - all[j]).norm(), options.corner_merge_distance);
}

TEST_F(GtCornersTest, DriveWithoutImagesFallsBackToUniformSampling) {
  // The same drive without its images: ground truth only.
  const fs::path gt_only = *folder_ / "gt_only";
  fs::create_directories(gt_only / "gt");
  fs::copy_file(Drive() / "rig.json", gt_only / "rig.json", fs::copy_options::overwrite_existing);
  for (const char* name : {"poses.tum", "mesh.ply"})
    fs::copy_file(Drive() / "gt" / name, gt_only / "gt" / name,
                  fs::copy_options::overwrite_existing);
  GtKeyframeOptions options;
  options.points_per_keyframe = 60;
  TriangleMesh mesh;
  const std::vector<SurfaceKeyframe> fallback = LoadGtKeyframes(gt_only, options, &mesh);

  // ... is MakeGtKeyframes over the keyframe centres, as is the corner mode switched off.
  const Rig rig = ReadRigJson(gt_only / "rig.json");
  std::vector<Eigen::Vector3d> centres;
  for (const StampedPose& pose : ReadTum(gt_only / "gt" / "poses.tum"))
    centres.push_back(pose.world_from_rig * rig.CentralCenterInRig());
  std::vector<Eigen::Vector3d> keyframe_centres;
  for (size_t frame : SelectKeyframeFrames(centres, options.keyframe_spacing))
    keyframe_centres.push_back(centres[frame]);
  const std::vector<SurfaceKeyframe> uniform = MakeGtKeyframes(mesh, keyframe_centres, options);
  GtKeyframeOptions switched_off = options;
  switched_off.corner_points = false;
  const std::vector<SurfaceKeyframe> off = LoadGtKeyframes(Drive(), switched_off);
  ASSERT_EQ(fallback.size(), uniform.size());
  ASSERT_EQ(off.size(), uniform.size());
  size_t points = 0;
  for (size_t t = 0; t < uniform.size(); ++t) {
    ASSERT_EQ(fallback[t].points.size(), uniform[t].points.size());
    ASSERT_EQ(off[t].points.size(), uniform[t].points.size());
    for (size_t i = 0; i < uniform[t].points.size(); ++i) {
      EXPECT_EQ(fallback[t].points[i].position, uniform[t].points[i].position);
      EXPECT_EQ(off[t].points[i].position, uniform[t].points[i].position);
    }
    points += uniform[t].points.size();
  }
  EXPECT_GT(points, 0u);
}

TEST_F(GtCornersTest, FlatImagesGiveNoPointsAndBadOptionsAreRejected) {
  const omni::Drive drive = omni::Drive::Open(Drive());
  const Rig& rig = drive.rig();
  const std::vector<StampedPose> poses = ReadTum(Drive() / "gt" / "poses.tum");
  std::vector<Rigid3d> world_from_rig;
  for (size_t f = 0; f < 4; ++f) world_from_rig.push_back(poses[f].world_from_rig);
  TriangleMesh mesh;
  LoadGtKeyframes(Drive(), GtKeyframeOptions(), &mesh);
  GtKeyframeOptions options;
  const auto flat = [&rig](size_t) {
    std::vector<cv::Mat> images;
    for (const Camera& camera : rig.cameras)
      images.emplace_back(camera.height, camera.width, CV_8UC1, cv::Scalar(100));
    return images;
  };
  const std::vector<SurfaceKeyframe> stream =
      MakeGtKeyframesAtCorners(mesh, rig, world_from_rig, flat, options);
  ASSERT_EQ(stream.size(), 4u);
  for (const SurfaceKeyframe& kf : stream) EXPECT_TRUE(kf.points.empty());

  options.corner_merge_distance = 0.0;
  EXPECT_NE(options.Check(), "");
  options = GtKeyframeOptions();
  options.harris.max_corners = 0;
  EXPECT_NE(options.Check(), "");
}

}  // namespace
}  // namespace omni
