#include "sfm/descriptor_matching.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <opencv2/features2d.hpp>
#include <stdexcept>

#include "calib/error.h"

namespace omni {

std::string DescriptorMatchingOptions::Check() const {
  if (patch_size < 7 || patch_size % 2 == 0)
    return "patch_size: expected an odd number of pixels, at least 7";
  if (!(max_ratio > 0.0 && max_ratio <= 1.0)) return "max_ratio: expected a ratio in (0, 1]";
  if (max_distance < 1 || max_distance > 256)
    return "max_distance: expected a number of bits in [1, 256]";
  if (levels < 1 || levels > 8) return "levels: expected 1 to 8 scales";
  if (!(level_scale > 1.0 && level_scale <= 2.0)) return "level_scale: expected in (1, 2]";
  return {};
}

cv::Mat DescribeCorners(const cv::Mat& prepared, const std::vector<Eigen::Vector2d>& corners,
                        const DescriptorMatchingOptions& options) {
  ThrowIfInvalid(options.Check(), "DescriptorMatchingOptions");
  if (prepared.type() != CV_8UC1)
    throw std::invalid_argument("DescribeCorners: expected an 8-bit grey image");
  const int levels = options.levels;
  cv::Mat descriptors(static_cast<int>(corners.size()) * levels, 32, CV_8U, cv::Scalar(0));
  if (corners.empty() || prepared.empty()) return descriptors;
  // ORB drops keypoints closer to the border than its edge threshold: pad by reflection so that
  // every corner keeps a descriptor at every scale, and shift the corners into the padded image.
  const double largest_scale = std::pow(options.level_scale, levels - 1);
  const int pad = static_cast<int>(std::ceil(options.patch_size * largest_scale)) + 2;
  cv::Mat padded;
  cv::copyMakeBorder(prepared, padded, pad, pad, pad, pad, cv::BORDER_REFLECT_101);
  std::vector<cv::KeyPoint> keypoints;
  keypoints.reserve(corners.size() * levels);
  const int radius = options.patch_size / 2;
  for (size_t i = 0; i < corners.size(); ++i)
    for (int level = 0; level < levels; ++level) {
      const double scale = std::pow(options.level_scale, level);
      float angle = 0.0f;
      if (options.oriented) {
        // The intensity centroid of the disc the patch covers at this scale.
        const int r = static_cast<int>(std::round(radius * scale));
        const int cx = static_cast<int>(std::round(corners[i].x())) + pad;
        const int cy = static_cast<int>(std::round(corners[i].y())) + pad;
        double m10 = 0.0, m01 = 0.0;
        for (int dy = -r; dy <= r; ++dy) {
          const uchar* row = padded.ptr<uchar>(cy + dy);
          for (int dx = -r; dx <= r; ++dx) {
            if (dx * dx + dy * dy > r * r) continue;
            m10 += dx * row[cx + dx];
            m01 += dy * row[cx + dx];
          }
        }
        angle = static_cast<float>(std::atan2(m01, m10) * 180.0 / M_PI);
        if (angle < 0.0f) angle += 360.0f;
      }
      cv::KeyPoint keypoint(static_cast<float>(corners[i].x() + pad),
                            static_cast<float>(corners[i].y() + pad),
                            static_cast<float>(options.patch_size * scale), angle, 0.0f, level,
                            static_cast<int>(i) * levels + level);
      keypoints.push_back(keypoint);
    }
  // ORB on the given keypoints: each is described at its level of ORB's pyramid, steered by
  // the given angle.
  cv::Ptr<cv::ORB> orb =
      cv::ORB::create(static_cast<int>(keypoints.size()), static_cast<float>(options.level_scale),
                      levels, options.patch_size, 0, 2, cv::ORB::HARRIS_SCORE, options.patch_size);
  cv::Mat computed;
  orb->compute(padded, keypoints, computed);
  for (size_t k = 0; k < keypoints.size(); ++k) {
    const int row = keypoints[k].class_id;
    if (row < 0 || row >= descriptors.rows) continue;
    computed.row(static_cast<int>(k)).copyTo(descriptors.row(row));
  }
  return descriptors;
}

namespace {

// Bits that differ between two descriptors of `bytes` bytes (cv::hal::normHamming's count
// without its per-call instrumentation, which took as long as the count itself here).
inline int HammingDistance(const uchar* a, const uchar* b, int bytes) {
  int distance = 0, i = 0;
  for (; i + 8 <= bytes; i += 8) {
    uint64_t x, y;
    std::memcpy(&x, a + i, 8);
    std::memcpy(&y, b + i, 8);
    distance += __builtin_popcountll(x ^ y);
  }
  for (; i < bytes; ++i) distance += __builtin_popcount(static_cast<unsigned>(a[i] ^ b[i]));
  return distance;
}

// The distances of corner i of the first set to every corner of the second: the smallest over
// the scale pairs (first scale, any) and (any, first scale). With GCC, also compiled for CPUs
// with the popcnt instruction (chosen at load time; Debian's baseline has none).
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__)
__attribute__((target_clones("popcnt", "default")))
#endif
void CornerDistances(const cv::Mat& descriptors1, const cv::Mat& descriptors2, int i, int levels,
                     int* distances) {
  const int bytes = descriptors1.cols, n2 = descriptors2.rows / levels;
  const uchar* a0 = descriptors1.ptr<uchar>(i * levels);
  for (int j = 0; j < n2; ++j) {
    const uchar* b0 = descriptors2.ptr<uchar>(j * levels);
    int distance = HammingDistance(a0, b0, bytes);
    for (int level = 1; level < levels; ++level) {
      distance = std::min(distance,
                          HammingDistance(a0, descriptors2.ptr<uchar>(j * levels + level), bytes));
      distance = std::min(distance,
                          HammingDistance(descriptors1.ptr<uchar>(i * levels + level), b0, bytes));
    }
    distances[j] = distance;
  }
}

struct BestTwo {
  int best = std::numeric_limits<int>::max(), second = std::numeric_limits<int>::max();
  int index = -1;
  void Offer(int distance, int i) {
    if (distance < best) {
      second = best;
      best = distance;
      index = i;
    } else if (distance < second) {
      second = distance;
    }
  }
};

}  // namespace

std::vector<DescriptorMatch> MatchDescriptors(const cv::Mat& descriptors1,
                                              const cv::Mat& descriptors2,
                                              const DescriptorMatchingOptions& options) {
  ThrowIfInvalid(options.Check(), "DescriptorMatchingOptions");
  std::vector<DescriptorMatch> matches;
  if (descriptors1.empty() || descriptors2.empty()) return matches;
  const int levels = options.levels;
  if (descriptors1.type() != CV_8U || descriptors2.type() != CV_8U ||
      descriptors1.cols != descriptors2.cols || descriptors1.rows % levels != 0 ||
      descriptors2.rows % levels != 0)
    throw std::invalid_argument(
        "MatchDescriptors: expected binary descriptors of one size, levels rows per corner");
  const int n1 = descriptors1.rows / levels, n2 = descriptors2.rows / levels;
  // Every distance once (in parallel over the first set's corners): the smallest over the
  // scale pairs (first scale, any) and (any, first scale).
  std::vector<int> distances(static_cast<size_t>(n1) * n2);
  tbb::parallel_for(0, n1, [&](int i) {
    CornerDistances(descriptors1, descriptors2, i, levels, &distances[static_cast<size_t>(i) * n2]);
  });
  // The best two of each row and the best of each column.
  std::vector<BestTwo> rows(n1);
  std::vector<int> column_best(n2, std::numeric_limits<int>::max()), column_index(n2, -1);
  for (int i = 0; i < n1; ++i) {
    const int* row = &distances[static_cast<size_t>(i) * n2];
    for (int j = 0; j < n2; ++j) {
      const int distance = row[j];
      rows[i].Offer(distance, j);
      if (distance < column_best[j]) {
        column_best[j] = distance;
        column_index[j] = i;
      }
    }
  }
  for (int i = 0; i < n1; ++i) {
    const BestTwo& row = rows[i];
    if (row.index < 0 || row.best > options.max_distance) continue;
    if (row.second != std::numeric_limits<int>::max() &&
        !(row.best < options.max_ratio * row.second))
      continue;
    if (options.mutual && column_index[row.index] != i) continue;
    matches.push_back({i, row.index, row.best});
  }
  // Without the mutual check two rows may share a column: keep the closer.
  if (!options.mutual) {
    std::sort(
        matches.begin(), matches.end(),
        [](const DescriptorMatch& a, const DescriptorMatch& b) { return a.distance < b.distance; });
    std::vector<char> taken(n2, 0);
    std::vector<DescriptorMatch> unique;
    for (const DescriptorMatch& match : matches)
      if (!taken[match.index2]) {
        taken[match.index2] = 1;
        unique.push_back(match);
      }
    matches = std::move(unique);
  }
  return matches;
}

}  // namespace omni
