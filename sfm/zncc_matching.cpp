#include "sfm/zncc_matching.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "calib/error.h"
#include "sfm/internal/bilinear_grid.h"
#include "sfm/internal/corner_cells.h"

namespace omni {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// Normalised windows of one call, stored one after the other (no allocation per window).
struct WindowSet {
  int area = 0;
  std::vector<float> values;  // window k at values[k * area]
  std::vector<char> valid;

  void Reset(size_t count, int window_area) {
    area = window_area;
    values.resize(count * window_area);
    valid.assign(count, 0);
  }
  const float* operator[](size_t k) const { return values.data() + k * area; }
  float* operator[](size_t k) { return values.data() + k * area; }
};

double Dot(const float* a, const float* b, int area) {
  // Four partial sums: vectorised, and still double accumulation of the float products.
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  int k = 0;
  for (; k + 4 <= area; k += 4) {
    s0 += static_cast<double>(a[k]) * b[k];
    s1 += static_cast<double>(a[k + 1]) * b[k + 1];
    s2 += static_cast<double>(a[k + 2]) * b[k + 2];
    s3 += static_cast<double>(a[k + 3]) * b[k + 3];
  }
  for (; k < area; ++k) s0 += static_cast<double>(a[k]) * b[k];
  return (s0 + s1) + (s2 + s3);
}

// Where InterpolatedWindow samples the window centred at `pixel`: its top-left sample at
// (ix + a, iy + b); false when the window or its interpolation neighbours leave the image.
struct WindowPlace {
  int ix = 0, iy = 0;
  float a = 0.f, b = 0.f;
};
bool PlaceWindow(const cv::Mat& image, const Eigen::Vector2d& pixel, int half_window,
                 WindowPlace* place) {
  const double margin = half_window + 1.0;
  if (!(pixel.x() >= margin && pixel.y() >= margin && pixel.x() <= image.cols - 1 - margin &&
        pixel.y() <= image.rows - 1 - margin))
    return false;
  // Top-left sample; with the margin above, the window and its interpolation neighbours are
  // inside the image.
  const double x = pixel.x() - half_window, y = pixel.y() - half_window;
  place->ix = static_cast<int>(std::floor(x));
  place->iy = static_cast<int>(std::floor(y));
  place->a = static_cast<float>(x - place->ix);
  place->b = static_cast<float>(y - place->iy);
  return true;
}

// The bilinear samples of the (2 half_window + 1)² window centred at `pixel` into `values`
// (row-major); false when the window or its interpolation neighbours leave the image.
// Separable (internal::SampleBilinearGrid).
bool InterpolatedWindow(const cv::Mat& image, const Eigen::Vector2d& pixel, int half_window,
                        float* __restrict values) {
  WindowPlace place;
  if (!PlaceWindow(image, pixel, half_window, &place)) return false;
  const int size = 2 * half_window + 1;
  thread_local std::vector<float> rows;
  rows.resize(static_cast<size_t>(size + 1) * size);
  internal::SampleBilinearGrid(image, place.ix, place.iy, place.a, place.b, size, rows.data(),
                               values);
  return true;
}

// Sums over a window's samples in kLanes interleaved partial sums (vectorised: a single running
// float sum is a chain of dependent additions), each lane's float sum then added in double.
constexpr int kLanes = 8;
struct WindowSums {
  double sum = 0.0, squares = 0.0, dot = 0.0;  // of d = v − shift, d², w d
};
template <bool kWithDot>
WindowSums SumWindow(const float* __restrict values, const float* __restrict weights, int area,
                     float shift) {
  float sum[kLanes] = {}, squares[kLanes] = {}, dot[kLanes] = {};
  int k = 0;
  for (; k + kLanes <= area; k += kLanes)
    for (int l = 0; l < kLanes; ++l) {
      const float d = values[k + l] - shift;
      sum[l] += d;
      squares[l] += d * d;
      if (kWithDot) dot[l] += weights[k + l] * d;
    }
  WindowSums sums;
  for (; k < area; ++k) {
    const float d = values[k] - shift;
    sums.sum += d;
    sums.squares += d * d;
    if (kWithDot) sums.dot += weights[k] * d;
  }
  for (int l = 0; l < kLanes; ++l) {
    sums.sum += sum[l];
    sums.squares += squares[l];
    if (kWithDot) sums.dot += dot[l];
  }
  return sums;
}

// The norm of a window's samples less their mean, from their sums less the first sample (small
// in a window of low contrast, where the rounding of the squares would matter):
// Σ (v − mean)² = Σ d² − area · (Σ d / area)². NaN when the window is flat (below a quarter of a
// grey level of standard deviation).
double CentredNorm(const WindowSums& sums, int area) {
  const double shifted_mean = sums.sum / area;
  const double norm = std::sqrt(std::max(0.0, sums.squares - area * shifted_mean * shifted_mean));
  return norm < 0.25 * std::sqrt(static_cast<double>(area)) ? kNaN : norm;
}

// The ZNCC of window1 (a normalised window: zero mean, unit norm; its sum window1_sum) with the
// window `values` of the second image, without normalising the second window: with
// d = v − shift,
//   Σ w1 (v − mean) / ‖v − mean‖ = (Σ w1 d − (mean − shift) Σ w1) / ‖v − mean‖.
// NaN where the window is flat.
double ZnccWithValues(const float* window1, double window1_sum, const float* values, int area) {
  const WindowSums sums = SumWindow<true>(values, window1, area, values[0]);
  const double norm = CentredNorm(sums, area);
  return (sums.dot - sums.sum / area * window1_sum) / norm;
}

// ZnccWithValues on the image's window centred at `pixel`; NaN where the window leaves the image.
double ZnccWithWindow(const float* window1, double window1_sum, const cv::Mat& image,
                      const Eigen::Vector2d& pixel, int half_window) {
  const int size = 2 * half_window + 1, area = size * size;
  thread_local std::vector<float> values;
  values.resize(area);
  if (!InterpolatedWindow(image, pixel, half_window, values.data())) return kNaN;
  return ZnccWithValues(window1, window1_sum, values.data(), area);
}

// The ZNCCs of window1 with the windows centred at `minus` and `plus` (ZnccWithWindow each).
// When the two windows are one pixel apart along `axis` (0: x, 1: y) on the same subpixel
// grid, as the refinement's samples half a pixel either side of a point are, both come from one
// grid one pixel wider: the same samples to the bit, for about half the interpolation.
void ZnccPair(const float* window1, double window1_sum, const cv::Mat& image,
              const Eigen::Vector2d& minus, const Eigen::Vector2d& plus, int axis, int half_window,
              double* zncc_minus, double* zncc_plus) {
  WindowPlace m, p;
  const bool shared =
      PlaceWindow(image, minus, half_window, &m) && PlaceWindow(image, plus, half_window, &p) &&
      m.a == p.a && m.b == p.b &&
      (axis == 0 ? p.ix == m.ix + 1 && p.iy == m.iy : p.iy == m.iy + 1 && p.ix == m.ix);
  if (!shared) {
    *zncc_minus = ZnccWithWindow(window1, window1_sum, image, minus, half_window);
    *zncc_plus = ZnccWithWindow(window1, window1_sum, image, plus, half_window);
    return;
  }
  const int size = 2 * half_window + 1, area = size * size;
  const int width = axis == 0 ? size + 1 : size, height = axis == 0 ? size : size + 1;
  thread_local std::vector<float> rows, grid, values;
  rows.resize(static_cast<size_t>(height + 1) * width);
  grid.resize(static_cast<size_t>(width) * height);
  internal::SampleBilinearRect(image, m.ix, m.iy, m.a, m.b, width, height, rows.data(),
                               grid.data());
  if (axis == 1) {  // the two windows are the grid's first and last `size` rows
    *zncc_minus = ZnccWithValues(window1, window1_sum, grid.data(), area);
    *zncc_plus = ZnccWithValues(window1, window1_sum, grid.data() + size, area);
    return;
  }
  values.resize(area);
  for (int shift = 0; shift <= 1; ++shift) {
    for (int r = 0; r < size; ++r)
      std::copy_n(grid.data() + static_cast<size_t>(r) * width + shift, size,
                  values.data() + static_cast<size_t>(r) * size);
    (shift == 0 ? *zncc_minus : *zncc_plus) =
        ZnccWithValues(window1, window1_sum, values.data(), area);
  }
}

// Moves pixel2 to the subpixel maximum of the ZNCC between window1 and the second image's
// window there; returns that ZNCC (or the original score when nothing better is found).
// `score` is the ZNCC at *pixel2 itself.
double RefineSubpixel(const float* window1, const cv::Mat& image2, const ZnccOptions& options,
                      double score, Eigen::Vector2d* pixel2) {
  const int size = 2 * options.half_window + 1;
  const int area = size * size;
  double window1_sum = 0.0;
  for (int k = 0; k < area; ++k) window1_sum += window1[k];
  const double h = options.subpixel_step;
  auto score_at = [&](const Eigen::Vector2d& pixel) {
    return ZnccWithWindow(window1, window1_sum, image2, pixel, options.half_window);
  };
  // Vertex of the parabola through (-h, minus), (0, centre), (h, plus), within [-h, h].
  auto vertex = [h](double minus, double centre, double plus) {
    const double curvature = minus - 2.0 * centre + plus;
    if (!(curvature < 0.0)) return 0.0;  // not a maximum (or NaN): stay
    return std::clamp(0.5 * h * (minus - plus) / curvature, -h, h);
  };
  Eigen::Vector2d best = *pixel2;
  double best_score = score;
  double centre = score;  // the ZNCC at `best`
  for (int iteration = 0; iteration < options.subpixel_iterations; ++iteration) {
    if (std::isnan(centre)) break;
    const Eigen::Vector2d dx(h, 0.0), dy(0.0, h);
    double minus_x, plus_x, minus_y, plus_y;
    ZnccPair(window1, window1_sum, image2, best - dx, best + dx, 0, options.half_window, &minus_x,
             &plus_x);
    ZnccPair(window1, window1_sum, image2, best - dy, best + dy, 1, options.half_window, &minus_y,
             &plus_y);
    const Eigen::Vector2d step(vertex(minus_x, centre, plus_x), vertex(minus_y, centre, plus_y));
    const Eigen::Vector2d candidate = best + step;
    const double candidate_score = score_at(candidate);
    if (!(candidate_score > std::max(best_score, centre))) break;
    best = candidate;
    best_score = candidate_score;
    centre = candidate_score;
    if (step.norm() < 1e-3) break;
  }
  *pixel2 = best;
  return best_score;
}

// Side of the cells of the second image's corners (pixels): a few corners per cell at the usual
// density.
constexpr double kGridCell = 16.0;

// Buffers reused by the calls of one thread (matching runs in parallel over the cameras).
struct MatchBuffers {
  WindowSet windows1, windows2;
  std::vector<int> near;
};

MatchBuffers& ThreadBuffers() {
  thread_local MatchBuffers buffers;
  return buffers;
}

}  // namespace

bool NormalisedWindow(const cv::Mat& image, const Eigen::Vector2d& pixel, int half_window,
                      float* values) {
  if (!InterpolatedWindow(image, pixel, half_window, values)) return false;
  const int size = 2 * half_window + 1, area = size * size;
  const float shift = values[0];
  const WindowSums sums = SumWindow<false>(values, nullptr, area, shift);
  const double norm = CentredNorm(sums, area);
  if (std::isnan(norm)) return false;
  const float inverse = static_cast<float>(1.0 / norm);
  const float mean_f = static_cast<float>(shift + sums.sum / area);
  for (int k = 0; k < area; ++k) values[k] = (values[k] - mean_f) * inverse;
  return true;
}

CornerWindows ComputeCornerWindows(const cv::Mat& image,
                                   const std::vector<Eigen::Vector2d>& corners, int half_window) {
  if (half_window < 1) throw std::invalid_argument("ComputeCornerWindows: half_window below 1");
  CornerWindows windows;
  windows.half_window = half_window;
  windows.area = (2 * half_window + 1) * (2 * half_window + 1);
  windows.values.resize(corners.size() * windows.area);
  windows.valid.assign(corners.size(), 0);
  for (size_t k = 0; k < corners.size(); ++k)
    windows.valid[k] =
        NormalisedWindow(image, corners[k], half_window, windows.values.data() + k * windows.area);
  return windows;
}

bool IsDistinctZncc(double best, double second, double max_distance_ratio) {
  if (second <= BestTwoZncc::kNone) return true;
  return std::sqrt(std::max(0.0, 1.0 - best)) <
         max_distance_ratio * std::sqrt(std::max(0.0, 1.0 - second));
}

std::string ZnccOptions::Check() const {
  if (half_window < 1) return "half_window: expected at least 1";
  if (!(min_zncc > -1.0 && min_zncc < 1.0)) return "min_zncc: expected a value in (-1, 1)";
  if (!(max_distance_ratio > 0.0 && max_distance_ratio <= 1.0))
    return "max_distance_ratio: expected a value in (0, 1]";
  if (!(subpixel_step > 0.0 && subpixel_step <= 1.0))
    return "subpixel_step: expected a value in (0, 1] pixels";
  if (subpixel_iterations < 0) return "subpixel_iterations: expected a non-negative count";
  if (!(min_zncc_pool >= min_zncc && min_zncc_pool < 1.0))
    return "min_zncc_pool: expected a value in [min_zncc, 1)";
  return {};
}

double Zncc(const cv::Mat& image1, const Eigen::Vector2d& pixel1, const cv::Mat& image2,
            const Eigen::Vector2d& pixel2, int half_window) {
  const int area = (2 * half_window + 1) * (2 * half_window + 1);
  std::vector<float> a(area), b(area);
  if (!NormalisedWindow(image1, pixel1, half_window, a.data()) ||
      !NormalisedWindow(image2, pixel2, half_window, b.data()))
    return kNaN;
  return Dot(a.data(), b.data(), area);
}

std::vector<ZnccMatch> MatchZncc(const cv::Mat& image1,
                                 const std::vector<Eigen::Vector2d>& corners1,
                                 const std::vector<SearchRegion>& regions, const cv::Mat& image2,
                                 const std::vector<Eigen::Vector2d>& corners2,
                                 const ZnccOptions& options, size_t pool_begin,
                                 const CornerWindows* windows2) {
  ThrowIfInvalid(options.Check(), "ZnccOptions");
  assert(regions.size() == corners1.size());
  assert(image1.type() == CV_8UC1 && image2.type() == CV_8UC1);
  MatchBuffers& buffers = ThreadBuffers();
  const int area = (2 * options.half_window + 1) * (2 * options.half_window + 1);
  WindowSet& windows1 = buffers.windows1;
  windows1.Reset(corners1.size(), area);
  for (size_t i = 0; i < corners1.size(); ++i)
    if (regions[i].radius >= 0.0)
      windows1.valid[i] = NormalisedWindow(image1, corners1[i], options.half_window, windows1[i]);
  if (windows2 != nullptr) {
    if (windows2->half_window != options.half_window || windows2->area != area ||
        windows2->valid.size() != corners2.size() ||
        windows2->values.size() != corners2.size() * static_cast<size_t>(area))
      throw std::invalid_argument("MatchZncc: windows2 are not the windows of corners2");
  } else {
    WindowSet& computed = buffers.windows2;
    computed.Reset(corners2.size(), area);
    for (size_t j = 0; j < corners2.size(); ++j)
      computed.valid[j] = NormalisedWindow(image2, corners2[j], options.half_window, computed[j]);
  }
  const std::vector<char>& valid2 = windows2 ? windows2->valid : buffers.windows2.valid;
  auto window2 = [&](int j) {
    return windows2 ? (*windows2)[j] : static_cast<const WindowSet&>(buffers.windows2)[j];
  };
  // The second image's corners by cell, to find those inside a search disc without visiting
  // them all.
  const internal::CornerCells grid(
      corners2, std::max(1, static_cast<int>(std::ceil(image2.cols / kGridCell))),
      std::max(1, static_cast<int>(std::ceil(image2.rows / kGridCell))), kGridCell);

  // Best and second best score for each corner of the first image; best for each corner of
  // the second among the first-image corners whose region contains it (candidates visited in
  // index order, as a scan of all of them would).
  constexpr double kNone = -2.0;
  std::vector<int> best1(corners1.size(), -1);
  std::vector<double> score1(corners1.size(), kNone), second1(corners1.size(), kNone);
  std::vector<int> best2(corners2.size(), -1);
  std::vector<double> score2(corners2.size(), kNone);
  std::vector<int>& near = buffers.near;
  for (size_t i = 0; i < corners1.size(); ++i) {
    if (!windows1.valid[i]) continue;
    const SearchRegion& region = regions[i];
    const double radius_squared = region.radius * region.radius;
    if (region.along.squaredNorm() > 0.0) {
      grid.NearSegment(region.center, region.along, region.radius, &near);
    } else {
      grid.Near(region.center, region.radius, &near);
    }
    for (const int j : near) {
      if (!valid2[j]) continue;
      if (internal::SquaredDistanceToSegment(corners2[j], region.center, region.along) >
          radius_squared)
        continue;
      const double score = Dot(windows1[i], window2(j), area);
      if (score > score1[i]) {
        second1[i] = score1[i];
        score1[i] = score;
        best1[i] = j;
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
    if (static_cast<size_t>(j) >= pool_begin && score1[i] < options.min_zncc_pool) continue;
    if (!IsDistinctZncc(score1[i], second1[i], options.max_distance_ratio)) continue;
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
