#include "sfm/zncc_matching.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <opencv2/imgproc.hpp>
#include <random>

#include "sfm/harris.h"
#include "sfm/internal/bilinear_grid.h"
#include "sfm/synthetic.h"

namespace omni {
namespace {

std::vector<Eigen::Vector2d> Pixels(const std::vector<Corner>& corners) {
  std::vector<Eigen::Vector2d> pixels;
  for (const Corner& corner : corners) pixels.push_back(corner.pixel);
  return pixels;
}

// The ZNCC as first written: cv::getRectSubPix windows, normalised in double.
double ReferenceZncc(const cv::Mat& image1, const Eigen::Vector2d& pixel1, const cv::Mat& image2,
                     const Eigen::Vector2d& pixel2, int half_window) {
  auto window = [half_window](const cv::Mat& image, const Eigen::Vector2d& pixel) {
    const double margin = half_window + 1.0;
    if (!(pixel.x() >= margin && pixel.y() >= margin && pixel.x() <= image.cols - 1 - margin &&
          pixel.y() <= image.rows - 1 - margin))
      return std::vector<double>();
    const int size = 2 * half_window + 1;
    cv::Mat patch;
    cv::getRectSubPix(image, cv::Size(size, size),
                      cv::Point2f(static_cast<float>(pixel.x()), static_cast<float>(pixel.y())),
                      patch, CV_32F);
    std::vector<double> values(patch.begin<float>(), patch.end<float>());
    double mean = 0.0, norm = 0.0;
    for (double v : values) mean += v;
    mean /= values.size();
    for (double& v : values) {
      v -= mean;
      norm += v * v;
    }
    norm = std::sqrt(norm);
    if (norm < 0.25 * std::sqrt(static_cast<double>(values.size()))) return std::vector<double>();
    for (double& v : values) v /= norm;
    return values;
  };
  const std::vector<double> a = window(image1, pixel1), b = window(image2, pixel2);
  if (a.empty() || b.empty()) return std::numeric_limits<double>::quiet_NaN();
  double dot = 0.0;
  for (size_t k = 0; k < a.size(); ++k) dot += a[k] * b[k];
  return dot;
}

TEST(Zncc, SameScoresAsTheReferenceWindows) {
  const cv::Mat image1 = MakeSyntheticTexture(200, 160, Eigen::Vector2d::Zero(), 80, 5);
  const cv::Mat image2 = MakeSyntheticTexture(200, 160, Eigen::Vector2d(1.3, -0.7), 80, 5);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> x(-2.0, 202.0), y(-2.0, 162.0), jitter(-3.0, 3.0);
  int finite = 0;
  for (int k = 0; k < 500; ++k) {
    const Eigen::Vector2d pixel1(x(rng), y(rng));
    const Eigen::Vector2d pixel2 = pixel1 + Eigen::Vector2d(jitter(rng), jitter(rng));
    for (const int half_window : {2, 5}) {
      const double fast = Zncc(image1, pixel1, image2, pixel2, half_window);
      const double reference = ReferenceZncc(image1, pixel1, image2, pixel2, half_window);
      ASSERT_EQ(std::isnan(fast), std::isnan(reference)) << pixel1.transpose();
      if (std::isnan(fast)) continue;
      ++finite;
      EXPECT_NEAR(fast, reference, 2e-5) << pixel1.transpose() << " / " << pixel2.transpose();
    }
  }
  EXPECT_GT(finite, 600);
}

// MatchZncc against a brute force over every pair with ReferenceZncc: the same pairs, and the
// scores to floating-point noise (no subpixel step here, which moves along the score surface).
TEST(ZnccMatching, SameMatchesAsBruteForce) {
  const cv::Mat image1 = MakeSyntheticTexture(320, 240, Eigen::Vector2d::Zero(), 200, 13);
  const cv::Mat image2 = MakeSyntheticTexture(320, 240, Eigen::Vector2d(4.2, -1.6), 200, 13);
  HarrisOptions harris;
  std::vector<Eigen::Vector2d> corners1 = Pixels(DetectHarrisCorners(image1, harris));
  const std::vector<Eigen::Vector2d> corners2 = Pixels(DetectHarrisCorners(image2, harris));
  ASSERT_GT(corners1.size(), 150u);
  std::vector<SearchRegion> regions;
  for (size_t i = 0; i < corners1.size(); ++i) {  // various radii, some corners skipped
    regions.push_back({corners1[i] + Eigen::Vector2d(3.0, -1.0), i % 7 == 0   ? -1.0
                                                                 : i % 3 == 0 ? 40.0
                                                                              : 12.0});
    // Some bands along a segment (an epipolar search), of either direction.
    if (i % 5 == 1) {
      regions.back().radius = 4.0;
      regions.back().along = Eigen::Vector2d(i % 2 ? 60.0 : -45.0, 20.0);
      regions.back().center -= 0.5 * regions.back().along;
    }
  }
  // Distance from a pixel to a region's segment.
  auto distance = [](const SearchRegion& region, const Eigen::Vector2d& pixel) {
    const double length_squared = region.along.squaredNorm();
    double at = 0.0;
    if (length_squared > 0.0)
      at = std::clamp((pixel - region.center).dot(region.along) / length_squared, 0.0, 1.0);
    return (pixel - region.center - at * region.along).norm();
  };
  ZnccOptions options;
  options.subpixel = false;
  options.min_zncc = 0.5;
  const std::vector<ZnccMatch> matches =
      MatchZncc(image1, corners1, regions, image2, corners2, options);

  std::vector<int> best1(corners1.size(), -1), best2(corners2.size(), -1);
  std::vector<double> score1(corners1.size(), -2.0), second1(corners1.size(), -2.0),
      score2(corners2.size(), -2.0);
  for (size_t i = 0; i < corners1.size(); ++i) {
    if (regions[i].radius < 0.0) continue;
    for (size_t j = 0; j < corners2.size(); ++j) {
      if (distance(regions[i], corners2[j]) > regions[i].radius) continue;
      const double s = ReferenceZncc(image1, corners1[i], image2, corners2[j], 5);
      if (std::isnan(s)) continue;
      if (s > score1[i]) {
        second1[i] = score1[i];
        score1[i] = s;
        best1[i] = static_cast<int>(j);
      } else if (s > second1[i]) {
        second1[i] = s;
      }
      if (s > score2[j]) {
        score2[j] = s;
        best2[j] = static_cast<int>(i);
      }
    }
  }
  std::vector<std::pair<int, int>> expected;
  for (size_t i = 0; i < corners1.size(); ++i) {
    const int j = best1[i];
    if (j < 0 || score1[i] < options.min_zncc || best2[j] != static_cast<int>(i)) continue;
    if (second1[i] > -2.0 &&
        !(std::sqrt(1.0 - score1[i]) < options.max_distance_ratio * std::sqrt(1.0 - second1[i])))
      continue;
    expected.emplace_back(static_cast<int>(i), j);
  }
  ASSERT_GT(expected.size(), 50u);
  ASSERT_EQ(matches.size(), expected.size());
  for (size_t k = 0; k < matches.size(); ++k) {
    EXPECT_EQ(matches[k].index1, expected[k].first);
    EXPECT_EQ(matches[k].index2, expected[k].second);
    EXPECT_NEAR(matches[k].zncc, score1[expected[k].first], 2e-5);
    EXPECT_EQ(matches[k].pixel2, corners2[expected[k].second]);
  }
}

// The second image's windows computed beforehand (ComputeCornerWindows, as the front end does
// on the thread that detects ahead) give the same matches to the last bit; windows of other
// corners are refused.
TEST(ZnccMatching, WindowsComputedAheadGiveTheSameMatches) {
  const cv::Mat image1 = MakeSyntheticTexture(320, 240, Eigen::Vector2d::Zero(), 200, 13);
  const cv::Mat image2 = MakeSyntheticTexture(320, 240, Eigen::Vector2d(4.2, -1.6), 200, 13);
  HarrisOptions harris;
  const std::vector<Eigen::Vector2d> corners1 = Pixels(DetectHarrisCorners(image1, harris));
  std::vector<Eigen::Vector2d> corners2 = Pixels(DetectHarrisCorners(image2, harris));
  corners2.push_back({2.0, 2.0});  // a window that leaves the image: not valid
  std::vector<SearchRegion> regions;
  for (const Eigen::Vector2d& corner : corners1)
    regions.push_back({corner + Eigen::Vector2d(4.0, -2.0), 10.0});
  const ZnccOptions options;
  const size_t pool_begin = corners2.size() / 2;
  const CornerWindows windows2 = ComputeCornerWindows(image2, corners2, options.half_window);
  EXPECT_FALSE(windows2.valid.back());
  const std::vector<ZnccMatch> computed =
      MatchZncc(image1, corners1, regions, image2, corners2, options, pool_begin);
  const std::vector<ZnccMatch> ahead =
      MatchZncc(image1, corners1, regions, image2, corners2, options, pool_begin, &windows2);
  ASSERT_GT(computed.size(), 50u);
  ASSERT_EQ(ahead.size(), computed.size());
  for (size_t k = 0; k < computed.size(); ++k) {
    EXPECT_EQ(ahead[k].index1, computed[k].index1);
    EXPECT_EQ(ahead[k].index2, computed[k].index2);
    EXPECT_EQ(ahead[k].zncc, computed[k].zncc);
    EXPECT_EQ(ahead[k].pixel2, computed[k].pixel2);
  }
  const CornerWindows fewer = ComputeCornerWindows(
      image2, std::vector<Eigen::Vector2d>(corners2.begin(), corners2.end() - 1),
      options.half_window);
  EXPECT_THROW(MatchZncc(image1, corners1, regions, image2, corners2, options, pool_begin, &fewer),
               std::invalid_argument);
  const CornerWindows wider = ComputeCornerWindows(image2, corners2, options.half_window + 1);
  EXPECT_THROW(MatchZncc(image1, corners1, regions, image2, corners2, options, pool_begin, &wider),
               std::invalid_argument);
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

// The subpixel refinement takes its two windows half a pixel either side of a point from one
// grid a pixel wider (or taller): each of its windows must be, to the bit, the square grid
// sampled at its own place.
TEST(Zncc, AWiderBilinearGridHoldsBothWindowsToTheBit) {
  const cv::Mat image = MakeSyntheticTexture(120, 100, Eigen::Vector2d::Zero(), 40, 9);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> fraction(0.f, 1.f);
  std::uniform_int_distribution<int> column(0, 100), row(0, 80);
  for (const int size : {7, 11, 13}) {
    std::vector<float> rows((size + 2) * (size + 1)), wide((size + 1) * size),
        tall(size * (size + 1)), square(size * size), window(size * size);
    for (int k = 0; k < 200; ++k) {
      const int ix = column(rng) % (image.cols - size - 2), iy = row(rng) % (image.rows - size - 2);
      const float a = fraction(rng), b = fraction(rng);
      internal::SampleBilinearRect(image, ix, iy, a, b, size + 1, size, rows.data(), wide.data());
      internal::SampleBilinearRect(image, ix, iy, a, b, size, size + 1, rows.data(), tall.data());
      for (int shift = 0; shift <= 1; ++shift) {
        internal::SampleBilinearGrid(image, ix + shift, iy, a, b, size, rows.data(), square.data());
        for (int r = 0; r < size; ++r)
          std::copy_n(wide.begin() + r * (size + 1) + shift, size, window.begin() + r * size);
        ASSERT_EQ(0, std::memcmp(window.data(), square.data(), sizeof(float) * size * size))
            << "along x, size " << size << ", shift " << shift;
        internal::SampleBilinearGrid(image, ix, iy + shift, a, b, size, rows.data(), square.data());
        ASSERT_EQ(
            0, std::memcmp(tall.data() + shift * size, square.data(), sizeof(float) * size * size))
            << "along y, size " << size << ", shift " << shift;
      }
    }
  }
}

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

// A corner of the second image's pool (from pool_begin on) is a match only at min_zncc_pool:
// the same window with noise scores between min_zncc and min_zncc_pool, so it matches as a
// corner before the pool and not as one of the pool.
TEST(ZnccMatching, APoolCornerNeedsTheHigherScore) {
  const cv::Mat image1 = MakeSyntheticTexture(200, 200, Eigen::Vector2d::Zero(), 60, 8);
  cv::Mat noise(image1.size(), CV_16S), noisy;
  cv::RNG(3).fill(noise, cv::RNG::NORMAL, 0, 15);
  image1.convertTo(noisy, CV_16S);
  noisy += noise;
  cv::Mat image2;
  noisy.convertTo(image2, CV_8U);
  const std::vector<Eigen::Vector2d> corners = {Eigen::Vector2d(90.0, 90.0)};
  const std::vector<SearchRegion> regions = {{Eigen::Vector2d(90.0, 90.0), 10.0}};
  ZnccOptions options;
  const double score = Zncc(image1, corners[0], image2, corners[0], options.half_window);
  ASSERT_GT(score, options.min_zncc);
  ASSERT_LT(score, options.min_zncc_pool);
  EXPECT_EQ(MatchZncc(image1, corners, regions, image2, corners, options).size(), 1u);
  EXPECT_EQ(MatchZncc(image1, corners, regions, image2, corners, options, 1).size(), 1u);
  EXPECT_TRUE(MatchZncc(image1, corners, regions, image2, corners, options, 0).empty());
  options.min_zncc_pool = 0.5;
  EXPECT_NE(options.Check().find("min_zncc_pool"), std::string::npos);
}

}  // namespace
}  // namespace omni
