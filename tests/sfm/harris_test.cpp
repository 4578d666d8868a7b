#include "sfm/harris.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "sfm/synthetic.h"

namespace omni {
namespace {

TEST(Harris, CornersSpreadOverTheGrid) {
  const cv::Mat image = MakeSyntheticTexture(640, 480, Eigen::Vector2d::Zero(), 400, 4);
  HarrisOptions options;
  const std::vector<Corner> corners = DetectHarrisCorners(PrepareImage(image, options), options);
  EXPECT_LE(corners.size(), static_cast<size_t>(options.max_corners));
  EXPECT_GE(corners.size(), static_cast<size_t>(0.8 * options.max_corners));

  std::vector<int> per_cell(options.grid_cols * options.grid_rows, 0);
  for (const Corner& corner : corners) {
    ASSERT_GE(corner.pixel.x(), options.border - options.subpixel_half_window);
    ASSERT_GE(corner.pixel.y(), options.border - options.subpixel_half_window);
    ASSERT_LT(corner.pixel.x(), 640 - options.border + options.subpixel_half_window);
    ASSERT_LT(corner.pixel.y(), 480 - options.border + options.subpixel_half_window);
    const int col = std::clamp(static_cast<int>(corner.pixel.x() * options.grid_cols / 640), 0,
                               options.grid_cols - 1);
    const int row = std::clamp(static_cast<int>(corner.pixel.y() * options.grid_rows / 480), 0,
                               options.grid_rows - 1);
    ++per_cell[row * options.grid_cols + col];
  }
  // About 300 corners over 48 buckets: about 6 each, none empty, none hogging.
  EXPECT_GE(*std::min_element(per_cell.begin(), per_cell.end()), 2);
  EXPECT_LE(*std::max_element(per_cell.begin(), per_cell.end()), 12);

  // Kept corners respect the suppression distance (before the subpixel step moves them).
  for (size_t i = 0; i < corners.size(); ++i)
    for (size_t j = i + 1; j < corners.size(); ++j)
      EXPECT_GT((corners[i].pixel - corners[j].pixel).norm(),
                options.min_distance - 2.0 * options.subpixel_half_window);
}

TEST(Harris, FlatImageHasNoCornersAndHalfTexturedImageKeepsThemOnTheTexture) {
  HarrisOptions options;
  const cv::Mat flat(240, 320, CV_8UC1, cv::Scalar(90));
  EXPECT_TRUE(DetectHarrisCorners(PrepareImage(flat, options), options).empty());

  cv::Mat half = MakeSyntheticTexture(320, 240, Eigen::Vector2d::Zero(), 200, 9);
  half.colRange(160, 320).setTo(cv::Scalar(128));
  const std::vector<Corner> corners = DetectHarrisCorners(PrepareImage(half, options), options);
  ASSERT_GT(corners.size(), 50u);
  for (const Corner& corner : corners) EXPECT_LT(corner.pixel.x(), 166.0);
}

TEST(Harris, DownscaleHalvesTheImageAndMapsPixelsBack) {
  HarrisOptions options;
  options.downscale = 2.0;
  const cv::Mat image = MakeSyntheticTexture(640, 480, Eigen::Vector2d::Zero(), 300, 5);
  cv::Mat colour;
  cv::Mat channels[] = {image, image, image};
  cv::merge(channels, 3, colour);
  const cv::Mat prepared = PrepareImage(colour, options);
  EXPECT_EQ(prepared.cols, 320);
  EXPECT_EQ(prepared.rows, 240);
  EXPECT_EQ(prepared.type(), CV_8UC1);
  // Pixel areas map onto each other: the input's corner -0.5 and far edge W - 0.5.
  EXPECT_TRUE(
      PreparedToInputPixel(Eigen::Vector2d(-0.5, -0.5), 2.0).isApprox(Eigen::Vector2d(-0.5, -0.5)));
  EXPECT_TRUE(PreparedToInputPixel(Eigen::Vector2d(319.5, 239.5), 2.0)
                  .isApprox(Eigen::Vector2d(639.5, 479.5)));
  const Eigen::Vector2d pixel(123.25, 45.5);
  EXPECT_TRUE(InputToPreparedPixel(PreparedToInputPixel(pixel, 2.0), 2.0).isApprox(pixel));
  EXPECT_FALSE(DetectHarrisCorners(prepared, options).empty());
}

TEST(HarrisOptions, CheckRejectsBadValues) {
  HarrisOptions options;
  EXPECT_TRUE(options.Check().empty());
  options.downscale = 0.5;
  EXPECT_FALSE(options.Check().empty());
  options = HarrisOptions();
  options.sobel_aperture = 4;
  EXPECT_FALSE(options.Check().empty());
}

}  // namespace
}  // namespace omni
