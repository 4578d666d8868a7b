#include "sfm/harris.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <opencv2/imgproc.hpp>
#include <random>
#include <set>

#include "sfm/synthetic.h"
#include "tests/calib/options_error_check.h"

namespace omni {
namespace {

// The straightforward detector the optimised one must reproduce: dilation for the non-maximum
// suppression, every bucket sorted, cv::cornerSubPix.
std::vector<Corner> ReferenceHarrisCorners(const cv::Mat& prepared, const HarrisOptions& options) {
  std::vector<Corner> corners;
  cv::Mat response, dilated;
  cv::cornerHarris(prepared, response, options.block_size, options.sobel_aperture,
                   options.harris_k);
  double max_response = 0.0;
  cv::minMaxLoc(response, nullptr, &max_response);
  if (!(max_response > 0.0)) return corners;
  const float threshold = static_cast<float>(options.quality_level * max_response);
  const int kernel_size = 2 * options.min_distance + 1;
  cv::dilate(response, dilated,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(kernel_size, kernel_size)));
  const int num_cells = options.grid_cols * options.grid_rows;
  std::vector<std::vector<Corner>> buckets(num_cells);
  for (int y = options.border; y < prepared.rows - options.border; ++y)
    for (int x = options.border; x < prepared.cols - options.border; ++x) {
      const float r = response.at<float>(y, x);
      if (r < threshold || r < dilated.at<float>(y, x)) continue;
      const int row = std::min(options.grid_rows - 1, y * options.grid_rows / prepared.rows);
      const int col = std::min(options.grid_cols - 1, x * options.grid_cols / prepared.cols);
      buckets[row * options.grid_cols + col].push_back({Eigen::Vector2d(x, y), r});
    }
  for (auto& bucket : buckets)
    std::sort(bucket.begin(), bucket.end(),
              [](const Corner& a, const Corner& b) { return a.response > b.response; });
  std::vector<size_t> taken(num_cells, 0);
  int remaining = options.max_corners;
  while (remaining > 0) {
    int open_buckets = 0;
    for (int i = 0; i < num_cells; ++i) open_buckets += taken[i] < buckets[i].size() ? 1 : 0;
    if (open_buckets == 0) break;
    const int quota = std::max(1, remaining / open_buckets);
    for (int i = 0; i < num_cells && remaining > 0; ++i) {
      const size_t extra =
          std::min<size_t>(quota, std::min<size_t>(buckets[i].size() - taken[i], remaining));
      taken[i] += extra;
      remaining -= static_cast<int>(extra);
    }
  }
  for (int i = 0; i < num_cells; ++i)
    corners.insert(corners.end(), buckets[i].begin(), buckets[i].begin() + taken[i]);
  std::vector<cv::Point2f> points;
  for (const Corner& corner : corners)
    points.emplace_back(static_cast<float>(corner.pixel.x()), static_cast<float>(corner.pixel.y()));
  cv::cornerSubPix(prepared, points,
                   cv::Size(options.subpixel_half_window, options.subpixel_half_window),
                   cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                    options.subpixel_iterations, options.subpixel_epsilon));
  std::vector<Corner> refined;
  for (size_t i = 0; i < corners.size(); ++i) {
    const Eigen::Vector2d pixel(points[i].x, points[i].y);
    if ((pixel - corners[i].pixel).norm() < options.max_subpixel_shift)
      refined.push_back({pixel, corners[i].response});
  }
  std::sort(refined.begin(), refined.end(),
            [](const Corner& a, const Corner& b) { return a.response > b.response; });
  std::vector<Corner> distinct;
  const double min_separation = 0.5 * options.min_distance;
  for (const Corner& corner : refined) {
    bool duplicate = false;
    for (const Corner& kept : distinct)
      duplicate =
          duplicate || (kept.pixel - corner.pixel).squaredNorm() < min_separation * min_separation;
    if (!duplicate) distinct.push_back(corner);
  }
  return distinct;
}

// A textured image with the sensor noise of the synthetic drives and an out-of-focus blur.
cv::Mat NoisyTexture(int width, int height, uint32_t seed) {
  cv::Mat image = MakeSyntheticTexture(width, height, Eigen::Vector2d::Zero(), 350, seed);
  cv::GaussianBlur(image, image, cv::Size(3, 3), 0.7);
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.f, 1.5f);
  for (int y = 0; y < image.rows; ++y)
    for (int x = 0; x < image.cols; ++x)
      image.at<uchar>(y, x) = cv::saturate_cast<uchar>(image.at<uchar>(y, x) + noise(rng));
  return image;
}

// The optimised detector (in-place NMS, partial selection per bucket, its own subpixel loop)
// gives the corners of the reference, to floating-point noise.
TEST(Harris, SameCornersAsTheReferenceDetector) {
  for (const uint32_t seed : {3u, 11u, 29u}) {
    const cv::Mat image = NoisyTexture(384, 512, seed);
    HarrisOptions options;
    const std::vector<Corner> fast = DetectHarrisCorners(image, options);
    const std::vector<Corner> reference = ReferenceHarrisCorners(image, options);
    ASSERT_GT(reference.size(), 200u);
    // Every corner of one is a corner of the other (same position to 1e-3 px, response to 1e-5),
    // but for the odd ill-conditioned corner whose subpixel iterations amplify the rounding
    // differences across the max_subpixel_shift limit: at most 2 %.
    const int tolerance = static_cast<int>(0.02 * reference.size());
    EXPECT_LE(std::abs(static_cast<int>(fast.size()) - static_cast<int>(reference.size())),
              tolerance);
    int unmatched = 0;
    for (const Corner& corner : fast) {
      double nearest = 1e9;
      float response = 0.f;
      for (const Corner& other : reference)
        if ((other.pixel - corner.pixel).norm() < nearest) {
          nearest = (other.pixel - corner.pixel).norm();
          response = other.response;
        }
      if (nearest < 1e-3 && std::abs(response - corner.response) <= 1e-5f * std::abs(response))
        continue;
      ++unmatched;
    }
    EXPECT_LE(unmatched, tolerance) << "seed " << seed;
    // Strongest first.
    for (size_t i = 1; i < fast.size(); ++i) EXPECT_GE(fast[i - 1].response, fast[i].response);
  }
}

// The suppression at the image's edges (no border: the 3×3 and the wider windows clipped), with
// several suppression radii, before the subpixel step: the integer maxima of the dilation of
// OpenCV's response above the threshold.
TEST(Harris, SameMaximaAsTheDilationUpToTheImageEdges) {
  const cv::Mat image = NoisyTexture(200, 150, 7);
  for (const int radius : {1, 2, 4, 7}) {
    HarrisOptions options;
    options.border = 0;
    options.min_distance = radius;
    options.subpixel_iterations = 0;
    options.max_corners = 100000;
    std::set<std::pair<int, int>> fast;
    for (const Corner& c : DetectHarrisCorners(image, options))
      fast.insert({static_cast<int>(c.pixel.x()), static_cast<int>(c.pixel.y())});
    cv::Mat response, dilated;
    cv::cornerHarris(image, response, options.block_size, options.sobel_aperture, options.harris_k);
    double max_response = 0.0;
    cv::minMaxLoc(response, nullptr, &max_response);
    const float threshold = static_cast<float>(options.quality_level * max_response);
    cv::dilate(response, dilated,
               cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * radius + 1, 2 * radius + 1)));
    std::set<std::pair<int, int>> reference;
    int on_edge = 0;
    for (int y = 0; y < image.rows; ++y)
      for (int x = 0; x < image.cols; ++x) {
        const float r = response.at<float>(y, x);
        if (r < threshold || r < dilated.at<float>(y, x)) continue;
        reference.insert({x, y});
        on_edge += x < radius || y < radius || x >= image.cols - radius || y >= image.rows - radius;
      }
    ASSERT_GT(reference.size(), 50u) << "radius " << radius;
    EXPECT_GT(on_edge, 0) << "radius " << radius;  // the clipped windows are exercised
    // The same maxima, but where the two responses' rounding orders a near-tie differently.
    int differ = 0;
    for (const auto& pixel : fast) differ += reference.count(pixel) == 0;
    for (const auto& pixel : reference) differ += fast.count(pixel) == 0;
    EXPECT_LE(differ, static_cast<int>(0.01 * reference.size())) << "radius " << radius;
  }
}

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

TEST(Harris, APoolListsTheCornersWithoutItFirstThenFurtherCornersOfEachBucket) {
  const cv::Mat image = MakeSyntheticTexture(640, 480, Eigen::Vector2d(3.3, 1.7), 900, 4);
  HarrisOptions options;
  options.max_corners = 300;
  const cv::Mat prepared = PrepareImage(image, options);
  const std::vector<Corner> without = DetectHarrisCorners(prepared, options);
  options.pool_corners = 600;
  const std::vector<Corner> with = DetectHarrisCorners(prepared, options);
  ASSERT_GE(without.size(), 200u);
  ASSERT_GT(with.size(), without.size() + 150);
  EXPECT_LE(with.size(), 600u);
  // The first corners are those without the pool, bit for bit and in order.
  for (size_t i = 0; i < without.size(); ++i) {
    ASSERT_EQ(with[i].pixel, without[i].pixel) << i;
    ASSERT_EQ(with[i].response, without[i].response) << i;
  }
  // The pool: strongest first, each corner apart from every corner listed before it.
  const double min_separation = 0.5 * options.min_distance;
  for (size_t i = without.size(); i < with.size(); ++i) {
    if (i > without.size()) {
      EXPECT_LE(with[i].response, with[i - 1].response) << i;
    }
    for (size_t j = 0; j < i; ++j)
      ASSERT_GE((with[i].pixel - with[j].pixel).norm(), min_separation) << i << " " << j;
  }
  // Spread as the first shares: every bucket holds some of the pool.
  std::vector<int> per_cell(options.grid_cols * options.grid_rows, 0);
  for (size_t i = without.size(); i < with.size(); ++i) {
    const int col = std::clamp(static_cast<int>(with[i].pixel.x() * options.grid_cols / 640), 0,
                               options.grid_cols - 1);
    const int row = std::clamp(static_cast<int>(with[i].pixel.y() * options.grid_rows / 480), 0,
                               options.grid_rows - 1);
    ++per_cell[row * options.grid_cols + col];
  }
  EXPECT_GE(*std::min_element(per_cell.begin(), per_cell.end()), 1);
  // A pool no larger than max_corners is no pool.
  options.pool_corners = options.max_corners;
  const std::vector<Corner> same = DetectHarrisCorners(prepared, options);
  ASSERT_EQ(same.size(), without.size());
  for (size_t i = 0; i < same.size(); ++i) ASSERT_EQ(same[i].pixel, without[i].pixel);
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
  options = HarrisOptions();
  options.pool_corners = -1;
  EXPECT_NE(options.Check().find("pool_corners"), std::string::npos);
}

TEST(Harris, BadOptionsThrowNamingTheField) {
  const cv::Mat image(120, 160, CV_8UC1, cv::Scalar(128));
  HarrisOptions options;
  options.sobel_aperture = 4;
  EXPECT_THROW(DetectHarrisCorners(image, options), OptionsError);
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { DetectHarrisCorners(image, options); },
                                          "HarrisOptions.sobel_aperture: expected"));
  options = HarrisOptions();
  options.downscale = 0.5;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { PrepareImage(image, options); },
                                          "HarrisOptions.downscale"));
}

TEST(Harris, ImagesItCannotReadThrow) {
  const HarrisOptions options;
  EXPECT_THROW(PrepareImage(cv::Mat(), options), std::invalid_argument);
  EXPECT_THROW(PrepareImage(cv::Mat(120, 160, CV_32FC1, cv::Scalar(0.5)), options),
               std::invalid_argument);
  EXPECT_THROW(DetectHarrisCorners(cv::Mat(120, 160, CV_8UC3, cv::Scalar(0, 0, 0)), options),
               std::invalid_argument);
}

}  // namespace
}  // namespace omni
