#include "sfm/zncc_matching.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "sfm/harris.h"
#include "sfm/synthetic.h"

namespace omni {
namespace {

std::vector<Eigen::Vector2d> Pixels(const std::vector<Corner>& corners) {
  std::vector<Eigen::Vector2d> pixels;
  for (const Corner& corner : corners) pixels.push_back(corner.pixel);
  return pixels;
}

class ZnccShiftTest : public ::testing::TestWithParam<Eigen::Vector2d> {};

TEST_P(ZnccShiftTest, FindsKnownShift) {
  const Eigen::Vector2d shift = GetParam();
  const cv::Mat image1 = MakeSyntheticTexture(480, 360, Eigen::Vector2d::Zero(), 300, 21);
  const cv::Mat image2 = MakeSyntheticTexture(480, 360, shift, 300, 21);
  HarrisOptions harris;
  harris.max_corners = 400;
  const std::vector<Eigen::Vector2d> corners1 = Pixels(DetectHarrisCorners(image1, harris));
  const std::vector<Eigen::Vector2d> corners2 = Pixels(DetectHarrisCorners(image2, harris));
  ASSERT_GT(corners1.size(), 200u);

  // The motion model predicts the shift to within a few pixels; search 8 pixels around.
  const Eigen::Vector2d predicted_shift = shift + Eigen::Vector2d(1.5, -2.0);
  std::vector<SearchRegion> regions;
  for (const Eigen::Vector2d& corner : corners1) regions.push_back({corner + predicted_shift, 8.0});
  const std::vector<ZnccMatch> matches =
      MatchZncc(image1, corners1, regions, image2, corners2, ZnccOptions());
  ASSERT_GT(matches.size(), 0.6 * corners1.size());

  // A match is right when it lands within half a pixel of the shifted corner. The few wrong
  // ones (a corner whose counterpart was not detected, matched to a similar neighbour) are left
  // to the geometric verification downstream.
  std::vector<double> errors;
  int wrong = 0;
  std::vector<char> used2(corners2.size(), 0);
  for (const ZnccMatch& match : matches) {
    EXPECT_GE(match.zncc, ZnccOptions().min_zncc);
    EXPECT_FALSE(used2[match.index2]) << "corner matched twice";
    used2[match.index2] = 1;
    const double error = (match.pixel2 - corners1[match.index1] - shift).norm();
    if (error < 0.5)
      errors.push_back(error);
    else
      ++wrong;
  }
  EXPECT_LE(wrong, 0.03 * matches.size());
  ASSERT_FALSE(errors.empty());
  std::sort(errors.begin(), errors.end());
  // The refined positions follow the subpixel shift.
  EXPECT_LT(errors[errors.size() / 2], 0.05);
  EXPECT_LT(errors[errors.size() * 9 / 10], 0.1);
}

INSTANTIATE_TEST_SUITE_P(Shifts, ZnccShiftTest,
                         ::testing::Values(Eigen::Vector2d(3.0, -2.0), Eigen::Vector2d(-5.0, 4.0),
                                           Eigen::Vector2d(2.4, 1.7), Eigen::Vector2d(-0.5, 3.25)));

TEST(Zncc, InvariantToGainAndOffset) {
  const cv::Mat image = MakeSyntheticTexture(120, 100, Eigen::Vector2d::Zero(), 40, 2);
  cv::Mat darker;
  image.convertTo(darker, CV_8U, 0.5, 20.0);
  const Eigen::Vector2d pixel(60.0, 50.0);
  EXPECT_NEAR(Zncc(image, pixel, image, pixel, 5), 1.0, 1e-6);
  EXPECT_GT(Zncc(image, pixel, darker, pixel, 5), 0.99);
  EXPECT_LT(Zncc(image, pixel, image, pixel + Eigen::Vector2d(7.0, 0.0), 5), 0.9);
  EXPECT_TRUE(std::isnan(Zncc(image, Eigen::Vector2d(2.0, 2.0), image, pixel, 5)));
}

TEST(ZnccMatching, RatioCheckRejectsRepeatedPattern) {
  // Two identical corners of the second image inside one search region: ambiguous, no match.
  const cv::Mat image1 = MakeSyntheticTexture(200, 200, Eigen::Vector2d::Zero(), 60, 8);
  cv::Mat image2 = image1.clone();
  image1(cv::Rect(80, 80, 21, 21)).copyTo(image2(cv::Rect(110, 80, 21, 21)));
  const std::vector<Eigen::Vector2d> corners1 = {Eigen::Vector2d(90.0, 90.0)};
  const std::vector<Eigen::Vector2d> corners2 = {Eigen::Vector2d(90.0, 90.0),
                                                 Eigen::Vector2d(120.0, 90.0)};
  ZnccOptions options;
  EXPECT_TRUE(
      MatchZncc(image1, corners1, {{Eigen::Vector2d(100.0, 90.0), 40.0}}, image2, corners2, options)
          .empty());
  // With only one candidate in the region, it matches.
  const std::vector<ZnccMatch> matches =
      MatchZncc(image1, corners1, {{Eigen::Vector2d(90.0, 90.0), 10.0}}, image2, corners2, options);
  ASSERT_EQ(matches.size(), 1u);
  EXPECT_EQ(matches[0].index2, 0);
}

}  // namespace
}  // namespace omni
