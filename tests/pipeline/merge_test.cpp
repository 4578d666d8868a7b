// MergeSegments (pipeline/merge.h) on segments made in memory from one known trajectory: the
// similarity between two segments is recovered from their shared frames, their images and
// frames appear once, the points seen at one corner of a shared image are fused, each frame's
// frame rays come from one segment, and a segment whose shared frames disagree is refused and
// left out. These segments have no images on disk:
// the revisit search (tested on a real drive in tests/apps/merge_command_test.cpp) and the
// global adjustment are off.

#include "pipeline/merge.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <map>

namespace omni {
namespace {
MergeOptions InMemoryOptions() {
  MergeOptions options;
  options.revisits.enabled = false;
  options.global_bundle_adjustment = false;
  return options;
}

// A curved drive: frame f at (f, 0.05 f², 0), turning about z.
Rigid3d TrueWorldFromRig(size_t f) {
  const double t = static_cast<double>(f);
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * t, Eigen::Vector3d::UnitZ())),
                 Eigen::Vector3d(t, 0.05 * t * t, 0.3 * std::sin(t)));
}

std::string FrameName(size_t f) {
  char name[16];
  std::snprintf(name, sizeof(name), "%06zu", f);
  return name;
}

// Frames first..last of the true drive, in a world `segment_from_true`: every frame a
// keyframe with one camera image; one point per frame seen in its image at pixel (f, f) and in
// the next frame's at (f + 0.5, f).
MergeSegment MakeSegment(size_t first, size_t last, const Sim3d& segment_from_true,
                         const std::string& name) {
  MergeSegment segment;
  segment.folder = name;
  segment.drive = "/drives/one";
  segment.first_frame = first;
  segment.last_frame = last;
  segment.mode = "central";
  for (size_t f = 0; f < 40; ++f) segment.frame_of_name[FrameName(f)] = f;
  segment.model.cameras.push_back({1, "PINHOLE", 640, 480, {500, 500, 320, 240}});
  for (size_t f = first; f <= last; ++f) {
    const Rigid3d pose = TransformPose(segment_from_true, TrueWorldFromRig(f));
    segment.frame_poses[f] = {f / 15.0, pose};
    segment.keyframe_poses[f] = {f / 15.0, pose};
    ColmapImage image;
    image.id = static_cast<uint32_t>(f - first + 1);
    image.camera_id = 1;
    image.name = "images/cam0/" + FrameName(f) + ".png";
    image.cam_from_world = pose.Inverse();
    segment.model.images.push_back(image);
  }
  for (size_t f = first; f <= last; ++f) {
    ColmapPoint3D point;
    point.id = static_cast<uint32_t>(f + 100);
    point.xyz = segment_from_true * Eigen::Vector3d(f, 10.0, 1.0);
    ColmapImage& here = segment.model.images[f - first];
    here.points2d.push_back({Eigen::Vector2d(f, f), point.id});
    point.track.push_back({here.id, static_cast<uint32_t>(here.points2d.size() - 1)});
    if (f < last) {
      ColmapImage& next = segment.model.images[f - first + 1];
      next.points2d.push_back({Eigen::Vector2d(f + 0.5, f), point.id});
      point.track.push_back({next.id, static_cast<uint32_t>(next.points2d.size() - 1)});
    }
    segment.model.points.push_back(point);
  }
  return segment;
}

TEST(MergeSegments, RecoversTheSimilarityAndFusesTheSharedCorners) {
  const Sim3d a_from_true;  // segment a's world is the true one
  const Sim3d b_from_true(
      0.7, Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(4, -2, 7));
  std::vector<MergeSegment> segments = {MakeSegment(0, 14, a_from_true, "a"),
                                        MakeSegment(8, 25, b_from_true, "b")};
  // b has more keyframes: it is the fixed one, the city is b's world.
  const MergeResult result = MergeSegments(segments, InMemoryOptions());
  ASSERT_EQ(result.overlaps.size(), 1u);
  const MergeOverlap& overlap = result.overlaps[0];
  EXPECT_TRUE(overlap.verified) << overlap.refusal;
  EXPECT_EQ(overlap.shared_frames, 7);
  EXPECT_EQ(overlap.inliers, 7);
  const Sim3d expected_a_from_b = a_from_true * b_from_true.Inverse();
  EXPECT_NEAR(overlap.a_from_b.scale, expected_a_from_b.scale, 1e-9);
  EXPECT_LT(overlap.a_from_b.rotation.angularDistance(expected_a_from_b.rotation), 1e-9);
  EXPECT_LT((overlap.a_from_b.translation - expected_a_from_b.translation).norm(), 1e-8);
  EXPECT_EQ(result.fixed_segment, 1);
  ASSERT_TRUE(result.merged[0] && result.merged[1]);

  // Every frame 0..25 once, in order, at its true pose in b's world.
  ASSERT_EQ(result.drives.size(), 1u);
  const MergedDrive& drive = result.drives[0];
  ASSERT_EQ(drive.frames.size(), 26u);
  for (size_t f = 0; f < 26; ++f) {
    EXPECT_EQ(drive.frame_frames[f], f);
    const Rigid3d expected = TransformPose(b_from_true, TrueWorldFromRig(f));
    EXPECT_LT((drive.frames[f].world_from_rig.translation - expected.translation).norm(), 1e-8)
        << f;
    EXPECT_LT(drive.frames[f].world_from_rig.rotation.angularDistance(expected.rotation), 1e-9);
  }
  // One image per frame; the 7 shared ones posed by the segment in which they are most central
  // (frames 8-11 by a, 12-14 by b), all at the true pose.
  ASSERT_EQ(result.model.images.size(), 26u);
  EXPECT_EQ(result.shared_images, 7u);
  for (const ColmapImage& image : result.model.images) {
    const size_t f = std::stoul(image.name.substr(12, 6));
    const Rigid3d expected = TransformPose(b_from_true, TrueWorldFromRig(f)).Inverse();
    EXPECT_LT((image.cam_from_world.Center() - expected.Center()).norm(), 1e-8) << image.name;
  }
  // Points of frames 8..14 exist in both segments (a's point of frame 14 is seen in one image
  // only but shares its corner with b's): fused, 26 points from 15 + 18.
  EXPECT_EQ(result.input_points, 33u);
  EXPECT_EQ(result.model.points.size(), 26u);
  EXPECT_EQ(result.fused_points, 7u);
  // Each at its true place in b's world, seen in one or two images.
  for (const ColmapPoint3D& point : result.model.points) {
    double nearest = 1e9;
    for (size_t f = 0; f < 26; ++f)
      nearest = std::min(nearest, (point.xyz - b_from_true * Eigen::Vector3d(f, 10.0, 1.0)).norm());
    EXPECT_LT(nearest, 1e-8) << point.id;
    EXPECT_GE(point.track.size(), 1u);
    EXPECT_LE(point.track.size(), 2u);
  }
}

// A ray's optical centre in the rig (true metres).
const Eigen::Vector3d kCentreInRig(0.2, -0.1, 0.05);

// The segment's frame rays, in its world: for each frame f, a frame point at (f, -10, 1) seen
// from frames f and f + 1 (within the segment), and a ray of frame f + 2 for the point of frame f.
void AddFrameRays(const Sim3d& segment_from_true, MergeSegment* segment) {
  const auto ray = [&](size_t f) {
    return ColmapFrameRay{"images/cam0/" + FrameName(f) + ".png",
                          segment_from_true * (TrueWorldFromRig(f) * kCentreInRig)};
  };
  for (size_t f = segment->first_frame; f <= segment->last_frame; ++f) {
    ColmapFrameRayPoint frame_point;
    frame_point.xyz = segment_from_true * Eigen::Vector3d(f, -10.0, 1.0);
    frame_point.color = Rgb8(static_cast<uint8_t>(f), 0, 0);
    frame_point.rays.push_back(ray(f));
    if (f < segment->last_frame) frame_point.rays.push_back(ray(f + 1));
    segment->model.frame_rays.push_back(frame_point);
    if (f + 2 > segment->last_frame) continue;
    ColmapFrameRayPoint map_point;
    map_point.point3d_id = static_cast<uint32_t>(f + 100);
    map_point.xyz = segment_from_true * Eigen::Vector3d(f, 10.0, 1.0);
    map_point.rays.push_back(ray(f + 2));
    segment->model.frame_rays.push_back(map_point);
  }
}

// The frame rays of two segments in the city: every frame's rays once (from the segment that
// poses the frame), each frame point once, all at their true places.
TEST(MergeSegments, TheFrameRaysOfEachFrameComeFromTheSegmentThatPosesIt) {
  const Sim3d a_from_true;
  const Sim3d b_from_true(
      0.7, Eigen::Quaterniond(Eigen::AngleAxisd(0.5, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(4, -2, 7));
  std::vector<MergeSegment> segments = {MakeSegment(0, 14, a_from_true, "a"),
                                        MakeSegment(8, 25, b_from_true, "b")};
  AddFrameRays(a_from_true, &segments[0]);
  AddFrameRays(b_from_true, &segments[1]);
  const MergeResult result = MergeSegments(segments, InMemoryOptions());
  ASSERT_TRUE(result.merged[0] && result.merged[1]);
  // Frames 8-11 are posed by a, 12-25 by b: a keeps its frame points whose last frame is at
  // most 11 (those of frames 0-10), b those of frames 11-25; a keeps the rays of frames up to
  // 11 (points 0-9), b those of frames 12 and after (points 10-23).
  std::map<size_t, int> frame_points;  // true frame -> count
  std::map<size_t, int> map_point_rays;
  for (const ColmapFrameRayPoint& line : result.model.frame_rays) {
    std::vector<size_t> frames;
    for (const ColmapFrameRay& ray : line.rays) {
      const size_t f = std::stoul(ray.image_name.substr(12, 6));
      frames.push_back(f);
      const Eigen::Vector3d expected = b_from_true * (TrueWorldFromRig(f) * kCentreInRig);
      EXPECT_LT((ray.centre - expected).norm(), 1e-8) << ray.image_name;
    }
    if (line.point3d_id == 0) {
      const size_t f = frames.front();
      ++frame_points[f];
      EXPECT_LT((line.xyz - b_from_true * Eigen::Vector3d(f, -10.0, 1.0)).norm(), 1e-8) << f;
      EXPECT_EQ(line.color, Rgb8(static_cast<uint8_t>(f), 0, 0));
      EXPECT_EQ(frames.size(), f < 25 ? 2u : 1u) << f;
    } else {
      ASSERT_EQ(frames.size(), 1u);
      const size_t f = frames.front() - 2;
      ++map_point_rays[f];
      const ColmapPoint3D& point = result.model.points.at(line.point3d_id - 1);
      EXPECT_EQ(point.id, line.point3d_id);
      EXPECT_LT((point.xyz - b_from_true * Eigen::Vector3d(f, 10.0, 1.0)).norm(), 1e-8) << f;
    }
  }
  ASSERT_EQ(frame_points.size(), 26u);
  for (const auto& [f, count] : frame_points) EXPECT_EQ(count, 1) << f;
  ASSERT_EQ(map_point_rays.size(), 24u);
  for (const auto& [f, count] : map_point_rays) EXPECT_EQ(count, 1) << f;
  EXPECT_EQ(map_point_rays.rbegin()->first, 23u);
}

TEST(MergeSegments, ASegmentWhoseSharedFramesDisagreeIsLeftOut) {
  std::vector<MergeSegment> segments = {MakeSegment(0, 14, Sim3d(), "a"),
                                        MakeSegment(10, 14, Sim3d(), "c")};
  // c's shared frames scattered: no similarity fits 5 of them.
  for (auto& [frame, pose] : segments[1].frame_poses)
    pose.world_from_rig.translation += Eigen::Vector3d(0, 0, (frame % 2 ? 1.0 : -1.0) * frame);
  const MergeResult result = MergeSegments(segments, InMemoryOptions());
  ASSERT_EQ(result.overlaps.size(), 1u);
  EXPECT_FALSE(result.overlaps[0].verified);
  EXPECT_NE(result.overlaps[0].refusal.find("agree with one similarity"), std::string::npos)
      << result.overlaps[0].refusal;
  EXPECT_TRUE(result.merged[0]);
  EXPECT_FALSE(result.merged[1]);
  EXPECT_NE(result.not_merged_why[1].find("agree with one similarity"), std::string::npos)
      << result.not_merged_why[1];
  EXPECT_EQ(result.model.images.size(), 15u);
}

}  // namespace
}  // namespace omni
