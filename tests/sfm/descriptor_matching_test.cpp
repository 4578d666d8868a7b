#include "sfm/descriptor_matching.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <opencv2/imgproc.hpp>
#include <set>

#include "sfm/harris.h"
#include "sfm/synthetic.h"
#include "sfm/track_builder.h"
#include "tests/calib/options_error_check.h"
#include "tests/sfm/test_util.h"

namespace omni {
namespace {

std::vector<Eigen::Vector2d> Corners(const cv::Mat& image) {
  std::vector<Eigen::Vector2d> corners;
  for (const Corner& corner : DetectHarrisCorners(image, HarrisOptions{}))
    corners.push_back(corner.pixel);
  return corners;
}

TEST(DescriptorMatching, FindsAShiftFarBeyondAnySearchRegion) {
  // The second image is the first moved by 60 pixels right and 35 down: no motion prior.
  const Eigen::Vector2d shift(60.0, 35.0);
  const cv::Mat image1 = MakeSyntheticTexture(400, 300, Eigen::Vector2d::Zero(), 250, 7);
  const cv::Mat image2 = MakeSyntheticTexture(400, 300, shift, 250, 7);
  const std::vector<Eigen::Vector2d> corners1 = Corners(image1), corners2 = Corners(image2);
  ASSERT_GT(corners1.size(), 200u);
  const DescriptorMatchingOptions options;
  const std::vector<DescriptorMatch> matches =
      MatchDescriptors(DescribeCorners(image1, corners1, options),
                       DescribeCorners(image2, corners2, options), options);
  // Corners of the first image whose shifted position stays inside the second.
  int visible = 0;
  for (const Eigen::Vector2d& corner : corners1) {
    const Eigen::Vector2d moved = corner + shift;
    visible += moved.x() > 10 && moved.y() > 10 && moved.x() < 390 && moved.y() < 290;
  }
  int right = 0;
  std::set<int> seen1, seen2;
  for (const DescriptorMatch& match : matches) {
    EXPECT_TRUE(seen1.insert(match.index1).second);
    EXPECT_TRUE(seen2.insert(match.index2).second);
    right += (corners1[match.index1] + shift - corners2[match.index2]).norm() < 1.5;
  }
  EXPECT_GT(right, 0.5 * visible) << matches.size() << " matches";
  EXPECT_GE(right, 0.95 * matches.size());
}

// The second image is the first enlarged 1.4 times about its centre (a corner seen nearer
// after a wide step): described at three scales 1.2 apart, more than 1.8 times as many corners
// match rightly as at one scale (86 and 38 of this texture's), three quarters of the matches
// right.
TEST(DescriptorMatching, SeveralScalesHoldUnderAChangeOfScale) {
  const cv::Mat image1 = MakeSyntheticTexture(400, 300, Eigen::Vector2d::Zero(), 250, 7);
  constexpr double kZoom = 1.4;
  cv::Mat enlarged;
  cv::resize(image1, enlarged, cv::Size(), kZoom, kZoom, cv::INTER_LINEAR);
  const cv::Rect crop(static_cast<int>(std::round(kZoom * 200.0 - 200.0)),
                      static_cast<int>(std::round(kZoom * 150.0 - 150.0)), 400, 300);
  const cv::Mat image2 = enlarged(crop).clone();
  // Pixel centres at integers: x2 = zoom (x1 + 0.5) - 0.5 - crop.x.
  auto moved = [&](const Eigen::Vector2d& p) {
    return Eigen::Vector2d(kZoom * (p.x() + 0.5) - 0.5 - crop.x,
                           kZoom * (p.y() + 0.5) - 0.5 - crop.y);
  };
  const std::vector<Eigen::Vector2d> corners1 = Corners(image1), corners2 = Corners(image2);
  auto count_right = [&](int levels, int* total) {
    DescriptorMatchingOptions options;
    options.levels = levels;
    const std::vector<DescriptorMatch> matches =
        MatchDescriptors(DescribeCorners(image1, corners1, options),
                         DescribeCorners(image2, corners2, options), options);
    int right = 0;
    for (const DescriptorMatch& match : matches)
      right += (moved(corners1[match.index1]) - corners2[match.index2]).norm() < 2.0;
    *total = static_cast<int>(matches.size());
    return right;
  };
  int total1 = 0, total3 = 0;
  const int right1 = count_right(1, &total1), right3 = count_right(3, &total3);
  EXPECT_GT(right3, 1.8 * right1) << right1 << " of " << total1 << " at one scale";
  EXPECT_GE(right3, 0.75 * total3) << right3 << " of " << total3;
  EXPECT_GT(right3, 50);
}

TEST(DescriptorMatching, RatioTestRefusesARepeatedPattern) {
  // Two identical halves: every corner of the left half has a twin in the right half, so no
  // match passes the ratio test against the doubled image.
  const cv::Mat half = MakeSyntheticTexture(200, 300, Eigen::Vector2d::Zero(), 120, 3);
  cv::Mat doubled;
  cv::hconcat(half, half, doubled);
  const std::vector<Eigen::Vector2d> corners1 = Corners(half), corners2 = Corners(doubled);
  const DescriptorMatchingOptions options;
  const std::vector<DescriptorMatch> with_twins =
      MatchDescriptors(DescribeCorners(half, corners1, options),
                       DescribeCorners(doubled, corners2, options), options);
  const std::vector<DescriptorMatch> alone = MatchDescriptors(
      DescribeCorners(half, corners1, options), DescribeCorners(half, corners1, options), options);
  EXPECT_GT(alone.size(), 0.8 * corners1.size());
  // Corners away from the seam have a twin 200 pixels away.
  EXPECT_LT(with_twins.size(), 0.2 * corners1.size());
}

TEST(DescriptorMatching, OptionsAreChecked) {
  DescriptorMatchingOptions options;
  options.patch_size = 30;
  EXPECT_NE(options.Check(), "");
  options = {};
  options.max_ratio = 0.0;
  EXPECT_NE(options.Check(), "");
  options = {};
  options.levels = 0;
  EXPECT_NE(options.Check(), "");
  options = {};
  options.level_scale = 1.0;
  EXPECT_NE(options.Check(), "");
  options = {};
  EXPECT_EQ(options.Check(), "");
}

TEST(TrackBuilder, RematchByDescriptorsFollowsTheKeyframeAcrossCameras) {
  // Two cameras. The keyframe: camera 0 sees texture A, camera 1 texture B. The next frame:
  // the rig turned, camera 1 now sees texture A moved by 70 pixels (no motion model predicts
  // that), camera 0 an unrelated texture.
  Rig rig = test::TwoCameraRig();
  TrackBuilder builder(rig, TrackBuilderOptions{});
  const TrackedFrame keyframe =
      builder.AddFrame({MakeSyntheticTexture(400, 300, Eigen::Vector2d::Zero(), 250, 11),
                        MakeSyntheticTexture(400, 300, Eigen::Vector2d::Zero(), 250, 12)});
  builder.SetFrameResult(true, true);
  std::map<int, Eigen::Vector2d> keyframe_pixel;  // track -> pixel of camera 0
  for (size_t i = 0; i < keyframe.observations.size(); ++i)
    if (keyframe.observations[i].camera == 0)
      keyframe_pixel[keyframe.observations[i].track] = keyframe.pixels[i];
  const Eigen::Vector2d shift(70.0, 0.0);
  TrackedFrame frame =
      builder.AddFrame({MakeSyntheticTexture(400, 300, Eigen::Vector2d::Zero(), 250, 13),
                        MakeSyntheticTexture(400, 300, shift, 250, 11)});
  ASSERT_TRUE(builder.RematchByDescriptors(0, &frame));
  EXPECT_EQ(builder.NumRematchReferences(), 1);  // the keyframe, also the last tracked frame
  EXPECT_FALSE(builder.RematchByDescriptors(1, &frame));
  int right = 0, wrong = 0;
  std::set<std::pair<int, int>> seen;
  for (size_t i = 0; i < frame.observations.size(); ++i) {
    const TrackObservation& observation = frame.observations[i];
    EXPECT_TRUE(seen.insert({observation.camera, observation.track}).second);
    const auto it = keyframe_pixel.find(observation.track);
    if (it == keyframe_pixel.end()) continue;
    const bool ok = observation.camera == 1 && (it->second + shift - frame.pixels[i]).norm() < 1.5;
    (ok ? right : wrong) += 1;
  }
  EXPECT_GT(right, 100);
  // The geometry (resection or relative pose in RANSAC) verifies them later.
  EXPECT_LT(wrong, 0.1 * right);
}

}  // namespace
}  // namespace omni
