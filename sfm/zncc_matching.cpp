#include "sfm/zncc_matching.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <opencv2/imgproc.hpp>

namespace omni {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A window resampled at a subpixel centre, zero-mean and unit-norm: the ZNCC of two windows is
// then their dot product. Empty when the window leaves the image or is flat.
std::vector<float> NormalisedWindow(const cv::Mat& image, const Eigen::Vector2d& pixel,
                                    int half_window) {
  const double margin = half_window + 1.0;
  if (!(pixel.x() >= margin && pixel.y() >= margin && pixel.x() <= image.cols - 1 - margin &&
        pixel.y() <= image.rows - 1 - margin))
    return {};
  const int size = 2 * half_window + 1;
  cv::Mat window;
  cv::getRectSubPix(image, cv::Size(size, size),
                    cv::Point2f(static_cast<float>(pixel.x()), static_cast<float>(pixel.y())),
                    window, CV_32F);
  std::vector<float> values(window.begin<float>(), window.end<float>());
  double mean = 0.0;
  for (float v : values) mean += v;
  mean /= values.size();
  double norm = 0.0;
  for (float& v : values) {
    v -= static_cast<float>(mean);
    norm += static_cast<double>(v) * v;
  }
  norm = std::sqrt(norm);
  // Flat: below a quarter of a grey level of standard deviation.
  if (norm < 0.25 * std::sqrt(static_cast<double>(values.size()))) return {};
  for (float& v : values) v = static_cast<float>(v / norm);
  return values;
}

double Dot(const std::vector<float>& a, const std::vector<float>& b) {
  double sum = 0.0;
  for (size_t i = 0; i < a.size(); ++i) sum += static_cast<double>(a[i]) * b[i];
  return sum;
}

// Moves pixel2 to the subpixel maximum of the ZNCC between window1 and the second image's
// window there; returns that ZNCC (or the original score when nothing better is found).
double RefineSubpixel(const std::vector<float>& window1, const cv::Mat& image2,
                      const ZnccOptions& options, double score, Eigen::Vector2d* pixel2) {
  const double h = options.subpixel_step;
  auto score_at = [&](const Eigen::Vector2d& pixel) {
    const std::vector<float> window2 = NormalisedWindow(image2, pixel, options.half_window);
    return window2.empty() ? kNaN : Dot(window1, window2);
  };
  // Vertex of the parabola through (-h, minus), (0, centre), (h, plus), within [-h, h].
  auto vertex = [h](double minus, double centre, double plus) {
    const double curvature = minus - 2.0 * centre + plus;
    if (!(curvature < 0.0)) return 0.0;  // not a maximum (or NaN): stay
    return std::clamp(0.5 * h * (minus - plus) / curvature, -h, h);
  };
  Eigen::Vector2d best = *pixel2;
  double best_score = score;
  for (int iteration = 0; iteration < options.subpixel_iterations; ++iteration) {
    const double centre = score_at(best);
    if (std::isnan(centre)) break;
    const Eigen::Vector2d dx(h, 0.0), dy(0.0, h);
    const Eigen::Vector2d step(vertex(score_at(best - dx), centre, score_at(best + dx)),
                               vertex(score_at(best - dy), centre, score_at(best + dy)));
    const Eigen::Vector2d candidate = best + step;
    const double candidate_score = score_at(candidate);
    if (!(candidate_score > std::max(best_score, centre))) break;
    best = candidate;
    best_score = candidate_score;
    if (step.norm() < 1e-3) break;
  }
  *pixel2 = best;
  return best_score;
}

}  // namespace

std::string ZnccOptions::Check() const {
  if (half_window < 1) return "half_window: expected at least 1";
  if (!(min_zncc > -1.0 && min_zncc < 1.0)) return "min_zncc: expected a value in (-1, 1)";
  if (!(max_distance_ratio > 0.0 && max_distance_ratio <= 1.0))
    return "max_distance_ratio: expected a value in (0, 1]";
  if (!(subpixel_step > 0.0 && subpixel_step <= 1.0))
    return "subpixel_step: expected a value in (0, 1] pixels";
  if (subpixel_iterations < 0) return "subpixel_iterations: expected a non-negative count";
  return {};
}

double Zncc(const cv::Mat& image1, const Eigen::Vector2d& pixel1, const cv::Mat& image2,
            const Eigen::Vector2d& pixel2, int half_window) {
  const std::vector<float> a = NormalisedWindow(image1, pixel1, half_window);
  const std::vector<float> b = NormalisedWindow(image2, pixel2, half_window);
  if (a.empty() || b.empty()) return kNaN;
  return Dot(a, b);
}

std::vector<ZnccMatch> MatchZncc(const cv::Mat& image1,
                                 const std::vector<Eigen::Vector2d>& corners1,
                                 const std::vector<SearchRegion>& regions, const cv::Mat& image2,
                                 const std::vector<Eigen::Vector2d>& corners2,
                                 const ZnccOptions& options) {
  assert(options.Check().empty());
  assert(regions.size() == corners1.size());
  assert(image1.type() == CV_8UC1 && image2.type() == CV_8UC1);
  std::vector<std::vector<float>> windows1(corners1.size()), windows2(corners2.size());
  for (size_t i = 0; i < corners1.size(); ++i)
    if (regions[i].radius >= 0.0)
      windows1[i] = NormalisedWindow(image1, corners1[i], options.half_window);
  for (size_t j = 0; j < corners2.size(); ++j)
    windows2[j] = NormalisedWindow(image2, corners2[j], options.half_window);

  // Best and second best score for each corner of the first image; best for each corner of
  // the second among the first-image corners whose region contains it.
  constexpr double kNone = -2.0;
  std::vector<int> best1(corners1.size(), -1);
  std::vector<double> score1(corners1.size(), kNone), second1(corners1.size(), kNone);
  std::vector<int> best2(corners2.size(), -1);
  std::vector<double> score2(corners2.size(), kNone);
  for (size_t i = 0; i < corners1.size(); ++i) {
    if (windows1[i].empty()) continue;
    const double radius_squared = regions[i].radius * regions[i].radius;
    for (size_t j = 0; j < corners2.size(); ++j) {
      if (windows2[j].empty()) continue;
      if ((corners2[j] - regions[i].center).squaredNorm() > radius_squared) continue;
      const double score = Dot(windows1[i], windows2[j]);
      if (score > score1[i]) {
        second1[i] = score1[i];
        score1[i] = score;
        best1[i] = static_cast<int>(j);
      } else if (score > second1[i]) {
        second1[i] = score;
      }
      if (score > score2[j]) {
        score2[j] = score;
        best2[j] = static_cast<int>(i);
      }
    }
  }

  std::vector<ZnccMatch> matches;
  for (size_t i = 0; i < corners1.size(); ++i) {
    const int j = best1[i];
    if (j < 0 || score1[i] < options.min_zncc) continue;
    if (second1[i] > kNone) {
      const double d_best = std::sqrt(std::max(0.0, 1.0 - score1[i]));
      const double d_second = std::sqrt(std::max(0.0, 1.0 - second1[i]));
      if (!(d_best < options.max_distance_ratio * d_second)) continue;
    }
    if (options.mutual && best2[j] != static_cast<int>(i)) continue;
    ZnccMatch match{static_cast<int>(i), j, score1[i], corners2[j]};
    if (options.subpixel)
      match.zncc = RefineSubpixel(windows1[i], image2, options, match.zncc, &match.pixel2);
    matches.push_back(match);
  }
  if (!options.mutual) {
    // Without the mutual check two corners may still pick the same one: keep the best.
    std::vector<int> owner(corners2.size(), -1);
    for (size_t k = 0; k < matches.size(); ++k) {
      int& o = owner[matches[k].index2];
      if (o < 0 || matches[k].zncc > matches[o].zncc) o = static_cast<int>(k);
    }
    std::vector<ZnccMatch> unique;
    for (size_t k = 0; k < matches.size(); ++k)
      if (owner[matches[k].index2] == static_cast<int>(k)) unique.push_back(matches[k]);
    matches = std::move(unique);
  }
  return matches;
}

}  // namespace omni
