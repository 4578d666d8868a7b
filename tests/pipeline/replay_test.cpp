// The surface after a loop closure in `omnisculpt reconstruct`: the corrected map is
// re-sculpted in one batch at the scale s of the first sculpting (LoopReplay::kBatch), or one by
// one from scratch (kIncremental), and either way δO is an oriented 2-manifold; the final batch
// of `merge` is the same surface with or without the keyframe-by-keyframe sculpting before it.

#include <gtest/gtest.h>

#include <Eigen/Geometry>

#include "calib/mesh_check.h"
#include "pipeline/reconstruction.h"
#include "surface/sculptor.h"
#include "tests/surface/step6_scenes.h"

namespace omni {
namespace {

TEST(PipelineReplay, OptionsOfTheReplayingSculptor) {
  SculptorOptions base;
  base.init_keyframes = 12;
  const SculptorOptions incremental =
      ReplaySculptorOptions(base, LoopReplay::kIncremental, 2.5, 300);
  EXPECT_EQ(incremental.scale, 0.0);  // measured again
  EXPECT_EQ(incremental.init_keyframes, 12);
  EXPECT_FALSE(incremental.batch_with_known_scale);

  const SculptorOptions batch = ReplaySculptorOptions(base, LoopReplay::kBatch, 2.5, 300);
  EXPECT_EQ(batch.scale, 2.5);
  EXPECT_EQ(batch.init_keyframes, 300);
  EXPECT_TRUE(batch.batch_init);
  EXPECT_TRUE(batch.batch_with_known_scale);
  EXPECT_TRUE(batch.Check().empty()) << batch.Check();

  // s not measured yet (a closure before the first batch): the base options, buffering again.
  const SculptorOptions early = ReplaySculptorOptions(base, LoopReplay::kBatch, 0.0, 8);
  EXPECT_EQ(early.scale, 0.0);
  EXPECT_EQ(early.init_keyframes, 12);
  EXPECT_FALSE(early.batch_with_known_scale);
}

// The street of step6_scenes.h moved by a similarity, as a loop correction moves a map
// (central mode: its scale changes too).
std::vector<SurfaceKeyframe> Corrected(std::vector<SurfaceKeyframe> keyframes, double scale) {
  const Eigen::Matrix3d rotation =
      Eigen::AngleAxisd(0.02, Eigen::Vector3d(0.1, 0.2, 1.0).normalized()).toRotationMatrix();
  const Eigen::Vector3d shift(0.3, -0.2, 0.1);
  auto move = [&](const Eigen::Vector3d& p) -> Eigen::Vector3d {
    return scale * (rotation * p) + shift;
  };
  for (SurfaceKeyframe& keyframe : keyframes) {
    keyframe.centre = move(keyframe.centre);
    for (SurfacePoint& point : keyframe.points) {
      point.position = move(point.position);
      for (SurfaceRay& ray : point.rays) ray.origin = move(ray.origin);
    }
  }
  return keyframes;
}

struct Replayed {
  std::vector<KeyframeStats> rows;
  double scale = 0.0;
  TriangleMesh mesh;
  std::string invariants;
};

// The first sculptor takes `first` keyframes, then a replay of the corrected map takes them
// again and the rest of the drive after them.
Replayed RunWithReplay(LoopReplay mode, const std::vector<SurfaceKeyframe>& drive, size_t first,
                       double correction_scale, double* first_scale) {
  SculptorOptions options;
  options.init_keyframes = 10;
  IncrementalSculptor sculptor(options);
  for (size_t k = 0; k < first; ++k) sculptor.AddKeyframe(drive[k]);
  *first_scale = sculptor.scale();
  const std::vector<SurfaceKeyframe> corrected = Corrected(drive, correction_scale);
  IncrementalSculptor replay(ReplaySculptorOptions(options, mode, sculptor.scale(), first));
  Replayed out;
  for (const SurfaceKeyframe& keyframe : corrected)
    for (const KeyframeStats& row : replay.AddKeyframe(keyframe)) out.rows.push_back(row);
  for (const KeyframeStats& row : replay.Finish()) out.rows.push_back(row);
  out.scale = replay.scale();
  out.mesh = replay.ExtractMesh();
  out.invariants = replay.CheckInvariants(true);
  return out;
}

TEST(PipelineReplay, ABatchReplayKeepsTheFirstScaleAndGivesAManifold) {
  constexpr int kKeyframes = 36;
  constexpr size_t kFirst = 30;
  constexpr double kCorrectionScale = 1.07;
  const std::vector<SurfaceKeyframe> drive = testing::NoisyStreet(kKeyframes, 120, 0.02, 7);
  size_t points = 0;
  for (size_t k = 0; k < kFirst; ++k) points += drive[k].points.size();

  double first_scale = 0.0;
  const Replayed batch =
      RunWithReplay(LoopReplay::kBatch, drive, kFirst, kCorrectionScale, &first_scale);
  EXPECT_NEAR(first_scale, 1.0, 1e-9);  // the street's keyframes are 1 m apart
  // The first sculpting's s, not the corrected map's 1.07.
  EXPECT_EQ(batch.scale, first_scale);
  // One batch row for the 30 replayed keyframes, then one row per later keyframe.
  ASSERT_EQ(batch.rows.size(), 1 + kKeyframes - kFirst);
  EXPECT_TRUE(batch.rows[0].batch);
  EXPECT_EQ(batch.rows[0].points_in, points);
  for (size_t r = 1; r < batch.rows.size(); ++r) {
    EXPECT_FALSE(batch.rows[r].batch);
    EXPECT_EQ(batch.rows[r].keyframe, KeyframeId(static_cast<uint32_t>(kFirst + r - 1)));
  }
  EXPECT_TRUE(batch.invariants.empty()) << batch.invariants;
  const MeshCheckReport report = CheckMesh(batch.mesh);
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_GT(batch.mesh.triangles.size(), 500u);
  EXPECT_EQ(batch.mesh.triangles.size(), batch.rows.back().triangles);

  // The incremental replay measures s again on the corrected map, and sculpts its first 10
  // keyframes in a batch, the others one by one.
  const Replayed incremental =
      RunWithReplay(LoopReplay::kIncremental, drive, kFirst, kCorrectionScale, &first_scale);
  EXPECT_NEAR(incremental.scale, kCorrectionScale, 1e-9);
  EXPECT_EQ(incremental.rows.size(), 1 + kKeyframes - 10u);
  EXPECT_TRUE(incremental.invariants.empty()) << incremental.invariants;
  EXPECT_TRUE(CheckMesh(incremental.mesh).ok);
}

// A correction that rescales the map (an SfM whose scale jumped, by thousands on one drive of
// the quality set): the replay's s follows the keyframes' spacing, so the replay of the map ten
// times larger keeps the same points as the replay of the map as it was; at the first s it
// would drop most of them as too far. A loop closure's usual correction (7 %) keeps s.
TEST(PipelineReplay, AReplayFollowsAMapThatWasRescaled) {
  const std::vector<SurfaceKeyframe> drive = testing::NoisyStreet(36, 120, 0.02, 7);
  SculptorOptions options;
  options.init_keyframes = 10;
  IncrementalSculptor first(options);
  for (size_t k = 0; k < 30; ++k) first.AddKeyframe(drive[k]);
  ASSERT_NEAR(first.scale(), 1.0, 1e-9);
  ASSERT_NEAR(first.keyframe_spacing(), 1.0, 1e-9);
  const size_t count = static_cast<size_t>(options.init_keyframes);
  double spacing = 0.0;
  EXPECT_EQ(ReplayScale(first.scale(), first.keyframe_spacing(), Corrected(drive, 1.07), count,
                        1.25, &spacing),
            first.scale());
  EXPECT_NEAR(spacing, 1.07, 1e-9);
  const std::vector<SurfaceKeyframe> larger = Corrected(drive, 10.0);
  const double rescaled = ReplayScale(first.scale(), first.keyframe_spacing(), larger, count);
  EXPECT_NEAR(rescaled, 10.0, 1e-9);
  EXPECT_NEAR(ReplayScale(first.scale(), first.keyframe_spacing(), Corrected(drive, 0.002), count),
              0.002, 1e-12);
  EXPECT_EQ(ReplayScale(0.0, first.keyframe_spacing(), larger, count), 0.0);  // s not known yet
  EXPECT_EQ(ReplayScale(first.scale(), 0.0, larger, count), first.scale());   // no reference

  // The points the replay inserts; its surface checked where s fits the map.
  auto added = [&](const std::vector<SurfaceKeyframe>& map, double scale, bool check) {
    IncrementalSculptor replay(ReplaySculptorOptions(options, LoopReplay::kBatch, scale, 30));
    size_t points = 0;
    for (size_t k = 0; k < 30; ++k)
      for (const KeyframeStats& row : replay.AddKeyframe(map[k])) points += row.points_added;
    for (const KeyframeStats& row : replay.Finish()) points += row.points_added;
    if (check) {
      EXPECT_EQ(replay.CheckInvariants(), "");
      EXPECT_TRUE(CheckMesh(replay.ExtractMesh()).ok);
    }
    return points;
  };
  const size_t as_it_was = added(Corrected(drive, 1.0), first.scale(), true);
  EXPECT_GT(as_it_was, 1000u);
  EXPECT_EQ(added(larger, rescaled, true), as_it_was);
  EXPECT_LT(added(larger, first.scale(), false), as_it_was / 2);
}

// `merge`'s final batch without the keyframe-by-keyframe sculpting before it: the s the stream's
// sculptor measures (by the keyframe spacing, or by the points' reach when r = 2 s), the same
// surface, and nothing when the keyframes fit in the first batch (nor after the stream).
TEST(PipelineFinalBatch, TheBatchAloneIsTheBatchAfterTheStream) {
  const std::vector<SurfaceKeyframe> drive = testing::NoisyStreet(30, 120, 0.02, 11);
  for (const double ray_length_factor : {15.0, 2.0}) {
    SculptorOptions options;
    options.init_keyframes = 10;
    options.max_ray_length_factor = ray_length_factor;
    IncrementalSculptor streamed(options);
    std::vector<KeyframeStats> stats;
    for (const SurfaceKeyframe& keyframe : drive)
      for (const KeyframeStats& row : streamed.AddKeyframe(keyframe)) stats.push_back(row);
    for (const KeyframeStats& row : streamed.Finish()) stats.push_back(row);
    EXPECT_EQ(MeasureScale(options, drive), streamed.scale()) << ray_length_factor;
    if (ray_length_factor == 2.0) {
      EXPECT_GT(streamed.scale(), 1.5);  // the reach, not the 1 m keyframe spacing
    }

    const FinalBatch after = SculptFinalBatch(options, streamed, stats, drive);
    const FinalBatch alone = SculptBatchOnly(options, drive);
    ASSERT_TRUE(after.sculptor && alone.sculptor);
    EXPECT_EQ(alone.sculptor->scale(), after.sculptor->scale());
    EXPECT_EQ(alone.keyframe_spacing, streamed.keyframe_spacing());
    EXPECT_EQ(after.keyframe_spacing, streamed.keyframe_spacing());
    std::vector<PointId> after_points, alone_points;
    const TriangleMesh after_mesh = after.sculptor->ExtractObservedMesh(&after_points);
    const TriangleMesh alone_mesh = alone.sculptor->ExtractObservedMesh(&alone_points);
    EXPECT_GT(after_mesh.triangles.size(), 100u);
    EXPECT_EQ(alone_mesh.triangles, after_mesh.triangles);
    EXPECT_EQ(alone_mesh.vertices, after_mesh.vertices);
    EXPECT_EQ(alone_points, after_points);
    EXPECT_EQ(alone.stats.size(), after.stats.size());

    options.init_keyframes = 30;
    EXPECT_FALSE(SculptBatchOnly(options, drive).sculptor);
  }
}

}  // namespace
}  // namespace omni
