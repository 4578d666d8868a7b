#pragma once
// Helpers shared by the sfm tests.

#include <gtest/gtest.h>

#include <vector>

#include "sfm/synthetic.h"

namespace omni::test {

// Two cameras of 400x300 pixels (f = 200) for the image front-end tests.
inline Rig TwoCameraRig() {
  Rig rig = MakeSyntheticRingRig(2, false, 0.0);
  for (Camera& camera : rig.cameras) {
    camera.width = 400;
    camera.height = 300;
    camera.params = {200.0, 200.0, 199.5, 149.5};
  }
  return rig;
}

// One camera of 400x300 pixels (f = 200).
inline Rig OneCameraRig() {
  Rig rig = MakeSyntheticRingRig(1, false, 0.0);
  rig.cameras[0].width = 400;
  rig.cameras[0].height = 300;
  rig.cameras[0].params = {200.0, 200.0, 199.5, 149.5};
  return rig;
}

// Expects at least min_share of the true inliers kept and at most 1 − min_share of the true
// outliers kept by a RANSAC inlier mask.
inline void ExpectMaskMatchesTruth(const std::vector<char>& mask,
                                   const std::vector<char>& is_outlier, double min_share) {
  ASSERT_EQ(mask.size(), is_outlier.size());
  int true_inliers = 0, kept_true_inliers = 0, outliers = 0, kept_outliers = 0;
  for (size_t i = 0; i < mask.size(); ++i) {
    if (is_outlier[i]) {
      ++outliers;
      kept_outliers += mask[i] ? 1 : 0;
    } else {
      ++true_inliers;
      kept_true_inliers += mask[i] ? 1 : 0;
    }
  }
  ASSERT_GT(outliers, 0);
  EXPECT_GE(kept_true_inliers, min_share * true_inliers);
  EXPECT_LE(kept_outliers, (1.0 - min_share) * outliers);
}

// The matches between two frames of a synthetic scene seen by `rig` from the two poses: points
// between min_depth and max_depth, bearing noise (radians) and a share of outliers.
struct TwoViewSceneOptions {
  int num_points = 300;
  double min_depth = 4.0, max_depth = 12.0;
  double noise = 0.0005;
  double outlier_ratio = 0.15;
  uint32_t seed = 1;
};

inline SyntheticMatches MakeTwoViewMatches(const Rig& rig, const Rigid3d& world_from_rig0,
                                           const Rigid3d& world_from_rig1,
                                           const TwoViewSceneOptions& two_view) {
  SyntheticSceneOptions scene_options;
  scene_options.num_points = two_view.num_points;
  scene_options.min_depth = two_view.min_depth;
  scene_options.max_depth = two_view.max_depth;
  scene_options.noise = two_view.noise;
  scene_options.outlier_ratio = two_view.outlier_ratio;
  scene_options.seed = two_view.seed;
  const SyntheticScene scene =
      MakeSyntheticScene(rig, {world_from_rig0, world_from_rig1}, scene_options);
  return MatchSyntheticFrames(scene, 0, 1);
}

}  // namespace omni::test
