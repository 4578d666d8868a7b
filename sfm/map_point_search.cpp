#include "sfm/map_point_search.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "calib/error.h"
#include "sfm/harris.h"
#include "sfm/internal/corner_cells.h"
#include "sfm/zncc_matching.h"

namespace omni {

std::string MapPointSearchOptions::Check() const {
  if (!(search_radius > 0.0)) return "search_radius: expected a positive number of pixels";
  if (half_window < 1) return "half_window: expected at least 1";
  if (!(min_zncc > -1.0 && min_zncc < 1.0)) return "min_zncc: expected a value in (-1, 1)";
  if (!(max_distance_ratio > 0.0 && max_distance_ratio <= 1.0))
    return "max_distance_ratio: expected a value in (0, 1]";
  if (!(snap_radius > 0.0)) return "snap_radius: expected a positive number of pixels";
  if (max_reference_age < 1) return "max_reference_age: expected at least 1 frame";
  return {};
}

MapPointSearch::MapPointSearch(const Rig& rig, const MapPointSearchOptions& options,
                               double downscale)
    : rig_(rig), options_(options), downscale_(downscale) {
  ThrowIfInvalid(options.Check(), "MapPointSearchOptions");
  if (!(downscale > 0.0))
    throw OptionsError("MapPointSearch.downscale: expected a positive factor");
}

namespace {

// Side of a reference patch: the ZNCC window plus the margin Zncc needs around its centre.
int PatchSize(int half_window) { return 2 * half_window + 5; }

// The (2h+1)² window of an 8-bit image centred at the integer pixel (x, y), zero-mean and
// unit-norm, into `window`; false when it leaves the image or is flat (below a quarter of a
// grey level of standard deviation, as sfm/zncc_matching).
bool NormalisedWindowAt(const cv::Mat& image, int x, int y, int h, std::vector<float>* window) {
  if (x < h || y < h || x + h >= image.cols || y + h >= image.rows) return false;
  const int size = 2 * h + 1;
  window->resize(static_cast<size_t>(size) * size);
  double sum = 0.0;
  float* out = window->data();
  for (int dy = -h; dy <= h; ++dy) {
    const uint8_t* row = image.ptr<uint8_t>(y + dy) + x - h;
    for (int dx = 0; dx < size; ++dx) {
      *out = row[dx];
      sum += *out++;
    }
  }
  const float mean = static_cast<float>(sum / window->size());
  double norm = 0.0;
  for (float& v : *window) {
    v -= mean;
    norm += static_cast<double>(v) * v;
  }
  norm = std::sqrt(norm);
  if (norm < 0.25 * std::sqrt(static_cast<double>(window->size()))) return false;
  const float scale = static_cast<float>(1.0 / norm);
  for (float& v : *window) v *= scale;
  return true;
}

float Dot(const float* a, const float* b, int area) {
  float sum = 0.0f;
  for (int i = 0; i < area; ++i) sum += a[i] * b[i];
  return sum;
}

// The ZNCC maximum of `reference` (a normalised window) over the integer pixels within
// `radius` of `predicted`, refined to subpixel by parabolas; false when there is none inside
// the disc (a maximum on its rim is not one), or it is not distinctive (max_distance_ratio
// against the best other local maximum).
bool SearchEveryPixel(const std::vector<float>& reference, const cv::Mat& image,
                      const Eigen::Vector2d& predicted, double radius, int h,
                      double max_distance_ratio, Eigen::Vector2d* pixel, double* score) {
  const int r = static_cast<int>(std::ceil(radius)) + 1;
  const int side = 2 * r + 1;
  const int x0 = static_cast<int>(std::lround(predicted.x())) - r;
  const int y0 = static_cast<int>(std::lround(predicted.y())) - r;
  constexpr float kNone = -2.0f;
  std::vector<float> scores(static_cast<size_t>(side) * side, kNone);
  std::vector<float> window;
  int best = -1;
  for (int j = 0; j < side; ++j)
    for (int i = 0; i < side; ++i) {
      if (!NormalisedWindowAt(image, x0 + i, y0 + j, h, &window)) continue;
      const int index = j * side + i;
      scores[index] = Dot(reference.data(), window.data(), static_cast<int>(window.size()));
      if (best < 0 || scores[index] > scores[best]) best = index;
    }
  if (best < 0) return false;
  const int bi = best % side, bj = best / side;
  if (bi == 0 || bj == 0 || bi == side - 1 || bj == side - 1) return false;
  if ((Eigen::Vector2d(x0 + bi, y0 + bj) - predicted).norm() > radius) return false;
  auto at = [&](int i, int j) { return scores[j * side + i]; };
  // The best other local maximum, outside the best one's 3x3 neighbourhood.
  float second = kNone;
  for (int j = 1; j < side - 1; ++j)
    for (int i = 1; i < side - 1; ++i) {
      if (std::abs(i - bi) <= 1 && std::abs(j - bj) <= 1) continue;
      const float v = at(i, j);
      if (v <= second) continue;
      bool maximum = true;
      for (int dj = -1; dj <= 1 && maximum; ++dj)
        for (int di = -1; di <= 1 && maximum; ++di)
          if ((di || dj) && at(i + di, j + dj) > v) maximum = false;
      if (maximum) second = v;
    }
  const double top = at(bi, bj);
  if (!IsDistinctZncc(top, second, max_distance_ratio)) return false;
  // Vertex of the parabola through the three samples around the maximum, within half a pixel.
  auto vertex = [](float minus, float centre, float plus) {
    if (minus == kNone || plus == kNone) return 0.0;
    const double curvature = minus - 2.0 * centre + plus;
    if (!(curvature < 0.0)) return 0.0;
    return std::clamp(0.5 * (minus - plus) / curvature, -0.5, 0.5);
  };
  *pixel = Eigen::Vector2d(x0 + bi + vertex(at(bi - 1, bj), at(bi, bj), at(bi + 1, bj)),
                           y0 + bj + vertex(at(bi, bj - 1), at(bi, bj), at(bi, bj + 1)));
  *score = top;
  return true;
}

}  // namespace

cv::Mat MapPointSearch::Patch(int slot) const {
  // The pool is not written while the patch is read (Search is const).
  return cv::Mat(patch_side_, patch_side_, CV_8UC1,
                 const_cast<uint8_t*>(patches_.data()) +
                     static_cast<size_t>(slot) * patch_side_ * patch_side_);
}

void MapPointSearch::Remember(int frame, const cv::Mat& prepared,
                              const std::vector<Eigen::Vector2d>& corners,
                              const std::vector<int>& tracks) {
  assert(corners.size() == tracks.size());
  if (!options_.enabled || prepared.empty()) return;
  patch_side_ = PatchSize(options_.half_window);
  const size_t area = static_cast<size_t>(patch_side_) * patch_side_;
  for (size_t i = 0; i < corners.size(); ++i) {
    const int track = tracks[i];
    if (track < 0) continue;  // a corner without a track has no reference
    if (static_cast<size_t>(track) >= slot_of_track_.size())
      slot_of_track_.resize(std::max<size_t>(track + 1, 2 * slot_of_track_.size()), -1);
    int& slot = slot_of_track_[track];
    if (slot < 0) {
      if (!free_slots_.empty()) {
        slot = free_slots_.back();
        free_slots_.pop_back();
      } else {
        slot = static_cast<int>(slot_frame_.size());
        slot_frame_.push_back(-1);
        slot_track_.push_back(-1);
        patches_.resize(patches_.size() + area);
      }
      slot_track_[slot] = track;
    }
    slot_frame_[slot] = frame;
    cv::Mat patch = Patch(slot);  // written in place: its size and type are getRectSubPix's
    cv::getRectSubPix(
        prepared, cv::Size(patch_side_, patch_side_),
        cv::Point2f(static_cast<float>(corners[i].x()), static_cast<float>(corners[i].y())), patch);
  }
}

void MapPointSearch::Forget(int frame) {
  for (size_t slot = 0; slot < slot_frame_.size(); ++slot) {
    if (slot_frame_[slot] < 0 || frame - slot_frame_[slot] <= options_.max_reference_age) continue;
    slot_of_track_[slot_track_[slot]] = -1;
    slot_frame_[slot] = -1;
    free_slots_.push_back(static_cast<int>(slot));
  }
}

std::vector<MapPointSearch::Match> MapPointSearch::Search(
    const std::vector<MapPointProjection>& candidates, const std::vector<cv::Mat>& prepared,
    const std::vector<std::vector<Eigen::Vector2d>>& corners,
    const std::vector<std::vector<char>>& eligible) const {
  const int num_cameras = static_cast<int>(rig_.NumCameras());
  assert(static_cast<int>(prepared.size()) == num_cameras);
  assert(static_cast<int>(corners.size()) == num_cameras);
  assert(static_cast<int>(eligible.size()) == num_cameras);
  if (!options_.enabled) return {};
  std::vector<std::vector<int>> by_camera(num_cameras);
  for (size_t i = 0; i < candidates.size(); ++i) {
    assert(candidates[i].camera >= 0 && candidates[i].camera < num_cameras);
    by_camera[candidates[i].camera].push_back(static_cast<int>(i));
  }
  const double radius = options_.search_radius / downscale_;
  const double snap = options_.snap_radius / downscale_;
  const double cell = std::max(2.0 * std::max(radius, snap), 1.0);

  std::vector<std::vector<Match>> found(num_cameras);
  tbb::parallel_for(0, num_cameras, [&](int c) {
    if (by_camera[c].empty() || corners[c].empty() || prepared[c].empty()) return;
    // The eligible corners in a grid of cells of side 2 radius: a disc of that radius touches
    // at most the 2x2 cells around its centre's nearest cell corner (3x3 searched for safety).
    const int cols = static_cast<int>(std::ceil(prepared[c].cols / cell)) + 1;
    const int rows = static_cast<int>(std::ceil(prepared[c].rows / cell)) + 1;
    // Each cell's corners in index order (compressed rows: no allocation per cell); `eligible`
    // the same for the eligible corners only.
    const internal::CornerCells all_grid(corners[c], cols, rows, cell);
    const internal::CornerCells grid(corners[c], cols, rows, cell, &eligible[c]);
    std::vector<float> reference_window;
    // The corners' windows, computed when first needed, one after the other in one buffer.
    const int area = (2 * options_.half_window + 1) * (2 * options_.half_window + 1);
    std::vector<float> corner_windows(corners[c].size() * static_cast<size_t>(area));
    std::vector<char> corner_window_state(corners[c].size(), 0);  // 0 not yet, 1 valid, 2 not
    const Camera& camera = rig_.cameras[c];
    for (int index : by_camera[c]) {
      const MapPointProjection& candidate = candidates[index];
      const int slot =
          candidate.track >= 0 && static_cast<size_t>(candidate.track) < slot_of_track_.size()
              ? slot_of_track_[candidate.track]
              : -1;
      if (slot < 0) continue;
      Eigen::Vector2d pixel;
      if (!camera.Project(candidate.bearing, &pixel) || !camera.IsInImage(pixel)) continue;
      const Eigen::Vector2d predicted = InputToPreparedPixel(pixel, downscale_);
      if (options_.search_every_pixel) {
        const cv::Mat patch = Patch(slot);
        if (!NormalisedWindowAt(patch, patch.cols / 2, patch.rows / 2, options_.half_window,
                                &reference_window))
          continue;
        Eigen::Vector2d peak;
        double score = 0.0;
        if (!SearchEveryPixel(reference_window, prepared[c], predicted,
                              radius * candidate.radius_scale, options_.half_window,
                              options_.max_distance_ratio, &peak, &score) ||
            score < options_.min_zncc)
          continue;
        // The nearest corner within the snap radius, if any.
        int nearest = -1;
        double nearest_distance = snap;
        const int px = static_cast<int>(std::floor(peak.x() / cell));
        const int py = static_cast<int>(std::floor(peak.y() / cell));
        for (int y = std::max(0, py - 1); y <= std::min(rows - 1, py + 1); ++y)
          for (int x = std::max(0, px - 1); x <= std::min(cols - 1, px + 1); ++x)
            for (int i : all_grid.Cell(x, y)) {
              const double distance = (corners[c][i] - peak).norm();
              if (distance <= nearest_distance) {
                nearest_distance = distance;
                nearest = i;
              }
            }
        if (nearest >= 0 && !eligible[c][nearest]) continue;  // another point's corner
        if (nearest >= 0)
          found[c].push_back({index, nearest, peak, score});
        else
          found[c].push_back({index, -1, peak, score});
        continue;
      }
      const int cx = static_cast<int>(std::floor(predicted.x() / cell));
      const int cy = static_cast<int>(std::floor(predicted.y() / cell));
      BestTwoZncc two;
      bool reference_ready = false, reference_ok = false;
      for (int y = std::max(0, cy - 1); y <= std::min(rows - 1, cy + 1); ++y)
        for (int x = std::max(0, cx - 1); x <= std::min(cols - 1, cx + 1); ++x)
          for (int i : grid.Cell(x, y)) {
            if ((corners[c][i] - predicted).norm() > radius * candidate.radius_scale) continue;
            // Zncc(reference, corner), with each window normalised once.
            if (!reference_ready) {
              reference_ready = true;
              const cv::Mat patch = Patch(slot);
              reference_ok = NormalisedWindowAt(patch, patch.cols / 2, patch.rows / 2,
                                                options_.half_window, &reference_window);
            }
            if (!reference_ok) break;
            float* const window = corner_windows.data() + static_cast<size_t>(i) * area;
            if (corner_window_state[i] == 0)
              corner_window_state[i] =
                  NormalisedWindow(prepared[c], corners[c][i], options_.half_window, window) ? 1
                                                                                             : 2;
            if (corner_window_state[i] != 1) continue;
            two.Offer(Dot(reference_window.data(), window, area), i);
          }
      if (two.index < 0 || two.best < options_.min_zncc) continue;
      if (!IsDistinctZncc(two.best, two.second, options_.max_distance_ratio)) continue;
      found[c].push_back({index, two.index, corners[c][two.index], two.best});
    }
  });

  // Each corner to the candidate that matches it best (per camera: corners are per camera).
  std::vector<Match> matches;
  for (int c = 0; c < num_cameras; ++c) {
    std::vector<Match>& list = found[c];
    std::sort(list.begin(), list.end(),
              [](const Match& a, const Match& b) { return a.zncc > b.zncc; });
    std::vector<char> used(corners[c].size(), 0);
    std::vector<Eigen::Vector2d> added;  // new observations of this camera
    for (const Match& match : list) {
      if (match.corner >= 0) {
        if (used[match.corner]) continue;
        used[match.corner] = 1;
      } else {
        if (std::any_of(added.begin(), added.end(),
                        [&](const Eigen::Vector2d& a) { return (a - match.pixel).norm() < snap; }))
          continue;
        added.push_back(match.pixel);
      }
      matches.push_back(match);
    }
  }
  return matches;
}

}  // namespace omni
