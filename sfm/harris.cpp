#include "sfm/harris.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <opencv2/imgproc.hpp>

namespace omni {

std::string HarrisOptions::Check() const {
  if (max_corners < 1) return "max_corners: expected at least 1";
  if (grid_cols < 1 || grid_rows < 1) return "grid_cols, grid_rows: expected at least 1";
  if (!(downscale >= 1.0)) return "downscale: expected a factor >= 1";
  if (block_size < 2) return "block_size: expected at least 2";
  if (sobel_aperture != 1 && sobel_aperture != 3 && sobel_aperture != 5 && sobel_aperture != 7)
    return "sobel_aperture: expected 1, 3, 5 or 7";
  if (!(harris_k > 0.0 && harris_k < 0.25)) return "harris_k: expected a value in (0, 0.25)";
  if (!(quality_level >= 0.0 && quality_level < 1.0))
    return "quality_level: expected a value in [0, 1)";
  if (min_distance < 1) return "min_distance: expected at least 1 pixel";
  if (border < 0) return "border: expected a non-negative number of pixels";
  if (subpixel_half_window < 1) return "subpixel_half_window: expected at least 1";
  if (subpixel_iterations < 0) return "subpixel_iterations: expected a non-negative count";
  if (!(subpixel_epsilon > 0.0)) return "subpixel_epsilon: expected a positive step";
  if (!(max_subpixel_shift > 0.0)) return "max_subpixel_shift: expected a positive distance";
  return {};
}

cv::Mat PrepareImage(const cv::Mat& input, const HarrisOptions& options) {
  assert(options.Check().empty());
  assert(!input.empty());
  cv::Mat grey;
  if (input.channels() == 3)
    cv::cvtColor(input, grey, cv::COLOR_BGR2GRAY);
  else if (input.channels() == 4)
    cv::cvtColor(input, grey, cv::COLOR_BGRA2GRAY);
  else
    grey = input;
  if (grey.depth() == CV_16U) {
    cv::Mat converted;
    grey.convertTo(converted, CV_8U, 1.0 / 257.0);
    grey = converted;
  }
  assert(grey.type() == CV_8UC1);
  if (options.downscale == 1.0) return grey.clone();
  cv::Mat shrunk;
  const cv::Size size(static_cast<int>(std::lround(grey.cols / options.downscale)),
                      static_cast<int>(std::lround(grey.rows / options.downscale)));
  cv::resize(grey, shrunk, size, 0, 0, cv::INTER_AREA);
  return shrunk;
}

// With pixel centres at integers, the input pixel area [-0.5, W - 0.5) maps onto
// [-0.5, W / s - 0.5): x_input = s (x + 0.5) - 0.5.
Eigen::Vector2d PreparedToInputPixel(const Eigen::Vector2d& prepared, double downscale) {
  return downscale * (prepared.array() + 0.5) - 0.5;
}

Eigen::Vector2d InputToPreparedPixel(const Eigen::Vector2d& input, double downscale) {
  return (input.array() + 0.5) / downscale - 0.5;
}

std::vector<Corner> DetectHarrisCorners(const cv::Mat& prepared, const HarrisOptions& options) {
  assert(options.Check().empty());
  assert(prepared.type() == CV_8UC1);
  std::vector<Corner> corners;
  if (prepared.cols <= 2 * options.border || prepared.rows <= 2 * options.border) return corners;

  cv::Mat response;
  cv::cornerHarris(prepared, response, options.block_size, options.sobel_aperture,
                   options.harris_k);
  double max_response = 0.0;
  cv::minMaxLoc(response, nullptr, &max_response);
  if (!(max_response > 0.0)) return corners;
  const float threshold = static_cast<float>(options.quality_level * max_response);

  // Local maxima over a (2 min_distance + 1)² neighbourhood.
  cv::Mat dilated;
  const int kernel_size = 2 * options.min_distance + 1;
  cv::dilate(response, dilated,
             cv::getStructuringElement(cv::MORPH_RECT, cv::Size(kernel_size, kernel_size)));

  const int num_cells = options.grid_cols * options.grid_rows;
  std::vector<std::vector<Corner>> buckets(num_cells);
  for (int y = options.border; y < prepared.rows - options.border; ++y) {
    const float* r = response.ptr<float>(y);
    const float* d = dilated.ptr<float>(y);
    const int row = std::min(options.grid_rows - 1, y * options.grid_rows / prepared.rows);
    for (int x = options.border; x < prepared.cols - options.border; ++x) {
      if (r[x] < threshold || r[x] < d[x]) continue;
      const int col = std::min(options.grid_cols - 1, x * options.grid_cols / prepared.cols);
      buckets[row * options.grid_cols + col].push_back({Eigen::Vector2d(x, y), r[x]});
    }
  }

  // Each bucket keeps its strongest corners up to its quota; the quota left unused by poor
  // buckets goes to the others in turn, so the total stays max_corners when there are enough.
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
  if (corners.empty()) return corners;

  std::vector<cv::Point2f> points;
  points.reserve(corners.size());
  for (const Corner& corner : corners)
    points.emplace_back(static_cast<float>(corner.pixel.x()), static_cast<float>(corner.pixel.y()));
  if (options.subpixel_iterations > 0) {
    cv::cornerSubPix(prepared, points,
                     cv::Size(options.subpixel_half_window, options.subpixel_half_window),
                     cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS,
                                      options.subpixel_iterations, options.subpixel_epsilon));
  }
  // cornerSubPix wanders off an edge-like or ill-defined corner: such corners are dropped, as
  // their windows slide along the edge when matched.
  std::vector<Corner> refined_corners;
  refined_corners.reserve(corners.size());
  for (size_t i = 0; i < corners.size(); ++i) {
    const Eigen::Vector2d refined(points[i].x, points[i].y);
    if (options.subpixel_iterations > 0 &&
        !((refined - corners[i].pixel).norm() < options.max_subpixel_shift))
      continue;
    refined_corners.push_back({refined, corners[i].response});
  }
  corners = std::move(refined_corners);
  // Two maxima of one physical corner may converge to the same place: keep the stronger.
  std::sort(corners.begin(), corners.end(),
            [](const Corner& a, const Corner& b) { return a.response > b.response; });
  std::vector<Corner> distinct;
  distinct.reserve(corners.size());
  const double min_separation = 0.5 * options.min_distance;
  for (const Corner& corner : corners) {
    bool duplicate = false;
    for (const Corner& kept : distinct)
      if ((kept.pixel - corner.pixel).squaredNorm() < min_separation * min_separation) {
        duplicate = true;
        break;
      }
    if (!duplicate) distinct.push_back(corner);
  }
  return distinct;
}

}  // namespace omni
