#include "sfm/keyframe_selection.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <set>

#include "sfm/synthetic.h"
#include "tests/calib/options_error_check.h"

namespace omni {
namespace {

TEST(KeyframeSelection, SyntheticDriveWithAStop) {
  // A rig driving along x at 0.1 m per frame, stopping for 15 frames half-way, along a street
  // of points 3–15 m away seeded from several positions.
  std::vector<Rigid3d> trajectory;
  double x = 0.0;
  for (int i = 0; i < 80; ++i) {
    if (i < 30 || i >= 45) x += 0.1;
    trajectory.emplace_back(Eigen::Quaterniond::Identity(), Eigen::Vector3d(x, 0.0, 0.0));
  }
  const Rig rig = MakeSyntheticRingRig(5, true, 0.05);
  SyntheticScene scene;
  std::vector<std::set<int>> seen(trajectory.size());
  std::vector<Eigen::Vector3d> points;
  for (int block = 0; block < 4; ++block) {
    // Points seeded from frames 0, 20, 50, 70 so that the street keeps having points.
    const int seed_frame = std::vector<int>{0, 20, 50, 70}[block];
    std::vector<Rigid3d> shifted(trajectory.begin() + seed_frame, trajectory.end());
    shifted.insert(shifted.end(), trajectory.begin(), trajectory.begin() + seed_frame);
    SyntheticSceneOptions options;
    options.num_points = 400;
    options.min_depth = 3.0;
    options.max_depth = 15.0;
    options.half_fov = 0.7;
    options.seed = 10 + block;
    const SyntheticScene part = MakeSyntheticScene(rig, shifted, options);
    for (const SyntheticObservation& observation : part.observations) {
      const int frame = (observation.frame + seed_frame) % static_cast<int>(trajectory.size());
      seen[frame].insert(static_cast<int>(points.size()) + observation.point);
    }
    points.insert(points.end(), part.points_in_world.begin(), part.points_in_world.end());
  }

  KeyframeSelectionOptions options;
  std::vector<int> keyframes = {0};
  for (int frame = 1; frame < static_cast<int>(trajectory.size()); ++frame) {
    const int last = keyframes.back();
    KeyframeCandidate candidate;
    candidate.last_keyframe_world_from_rig = trajectory[last];
    candidate.world_from_rig = trajectory[frame];
    candidate.last_keyframe_points = static_cast<int>(seen[last].size());
    std::vector<double> depths;
    for (int point : seen[last])
      if (seen[frame].count(point)) {
        ++candidate.tracked_points;
        depths.push_back((points[point] - trajectory[frame].translation).norm());
      }
    ASSERT_FALSE(depths.empty());
    std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
    candidate.median_depth = depths[depths.size() / 2];
    const KeyframeDecisionReason reason = DecideKeyframe(candidate, options);
    if (reason.decision == KeyframeDecision::kKeyframe) {
      keyframes.push_back(frame);
      // Consecutive keyframes still share most points, and have moved.
      EXPECT_GE(reason.baseline_ratio, options.min_baseline_ratio) << "frame " << frame;
      EXPECT_GT(reason.tracked_share, 0.15) << "frame " << frame;
    }
  }
  // Several keyframes along the 6.5 m drive (median depth about 9 m: at most 0.25 · 9 m
  // apart), none during the stop (frames 31–44 do not move from frame 30).
  EXPECT_GE(keyframes.size(), 3u);
  EXPECT_LE(keyframes.size(), 40u);
  int during_stop = 0;
  for (int keyframe : keyframes) during_stop += (keyframe > 30 && keyframe < 45) ? 1 : 0;
  EXPECT_LE(during_stop, 1);  // at most the first stopped frame, if the share ran out there
  EXPECT_GT(trajectory.back().translation.x() - trajectory[keyframes.back()].translation.x(),
            -1e-9);
  EXPECT_LT(trajectory.back().translation.x() - trajectory[keyframes.back()].translation.x(), 3.0);
  for (size_t i = 1; i < keyframes.size(); ++i) {
    const double baseline =
        (trajectory[keyframes[i]].translation - trajectory[keyframes[i - 1]].translation).norm();
    EXPECT_GT(baseline, 0.05) << "keyframes " << keyframes[i - 1] << ", " << keyframes[i];
    EXPECT_LT(baseline, 3.0) << "keyframes " << keyframes[i - 1] << ", " << keyframes[i];
  }
}

TEST(KeyframeSelection, DecisionRules) {
  KeyframeSelectionOptions options;
  KeyframeCandidate candidate;
  candidate.last_keyframe_points = 100;
  candidate.median_depth = 10.0;
  candidate.tracked_points = 90;
  candidate.inliers = 90;
  candidate.world_from_rig.translation = Eigen::Vector3d(0.1, 0, 0);  // ratio 0.01
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kSkip);
  candidate.tracked_points = 10;  // few tracked, but no parallax yet
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kSkip);
  candidate.world_from_rig.translation = Eigen::Vector3d(1.0, 0, 0);  // ratio 0.1
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kKeyframe);
  candidate.tracked_points = 90;
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kSkip);
  // The share holds, but few points are left in absolute terms: the map must grow.
  candidate.inliers = options.min_tracked_points - 1;
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kKeyframe);
  candidate.inliers = options.min_tracked_points;
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kSkip);
  candidate.world_from_rig.translation = Eigen::Vector3d(3.0, 0, 0);  // ratio 0.3
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kKeyframe);
  candidate.world_from_rig.translation = Eigen::Vector3d(0.1, 0, 0);
  candidate.world_from_rig.rotation = Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ());
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kKeyframe);
  options.min_tracked_share = 1.5;
  EXPECT_FALSE(options.Check().empty());
}

TEST(KeyframeSelection, FollowedTracksRule) {
  // The last keyframe's points are still tracked (far points), but most of its tracks ended.
  KeyframeSelectionOptions options;
  options.min_followed_track_share = 0.2;
  KeyframeCandidate candidate;
  candidate.last_keyframe_points = 100;
  candidate.tracked_points = 90;
  candidate.inliers = 90;
  candidate.median_depth = 10.0;
  candidate.last_keyframe_tracks = 1000;
  candidate.followed_tracks = 199;
  candidate.world_from_rig.translation = Eigen::Vector3d(1.0, 0, 0);  // ratio 0.1
  KeyframeDecisionReason reason = DecideKeyframe(candidate, options);
  EXPECT_EQ(reason.decision, KeyframeDecision::kKeyframe);
  EXPECT_STREQ(reason.reason, "few tracks followed");
  EXPECT_DOUBLE_EQ(reason.followed_track_share, 0.199);
  candidate.followed_tracks = 200;
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kSkip);
  // Without parallax the tracks' end does not make a keyframe: no point could be triangulated.
  candidate.followed_tracks = 10;
  candidate.world_from_rig.translation = Eigen::Vector3d(0.1, 0, 0);  // ratio 0.01
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kSkip);
  // Off (0): the point rule alone.
  candidate.world_from_rig.translation = Eigen::Vector3d(1.0, 0, 0);
  options.min_followed_track_share = 0.0;
  EXPECT_EQ(DecideKeyframe(candidate, options).decision, KeyframeDecision::kSkip);
  options.min_followed_track_share = 1.0;
  EXPECT_FALSE(options.Check().empty());
  options.min_followed_track_share = -0.1;
  EXPECT_FALSE(options.Check().empty());
}

TEST(KeyframeSelection, BadOptionsThrowNamingTheField) {
  KeyframeSelectionOptions options;
  options.min_tracked_share = 1.5;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { DecideKeyframe(KeyframeCandidate(), options); },
                                          "KeyframeSelectionOptions.min_tracked_share"));
}

}  // namespace
}  // namespace omni
