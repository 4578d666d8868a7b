#include "sfm/descriptor_matching.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core/hal/hal.hpp>
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
  return {};
}

cv::Mat DescribeCorners(const cv::Mat& prepared, const std::vector<Eigen::Vector2d>& corners,
                        const DescriptorMatchingOptions& options) {
  ThrowIfInvalid(options.Check(), "DescriptorMatchingOptions");
  if (prepared.type() != CV_8UC1)
    throw std::invalid_argument("DescribeCorners: expected an 8-bit grey image");
  cv::Mat descriptors(static_cast<int>(corners.size()), 32, CV_8U, cv::Scalar(0));
  if (corners.empty() || prepared.empty()) return descriptors;
  // ORB drops keypoints closer to the border than its edge threshold: pad by reflection so that
  // every corner keeps a descriptor, and shift the corners into the padded image.
  const int pad = options.patch_size + 2;
  cv::Mat padded;
  cv::copyMakeBorder(prepared, padded, pad, pad, pad, pad, cv::BORDER_REFLECT_101);
  std::vector<cv::KeyPoint> keypoints;
  keypoints.reserve(corners.size());
  for (size_t i = 0; i < corners.size(); ++i) {
    cv::KeyPoint keypoint(static_cast<float>(corners[i].x() + pad),
                          static_cast<float>(corners[i].y() + pad),
                          static_cast<float>(options.patch_size), 0.0f);
    keypoint.class_id = static_cast<int>(i);
    keypoints.push_back(keypoint);
  }
  // One level, upright (the given angle 0): a rig on a car does not roll.
  cv::Ptr<cv::ORB> orb =
      cv::ORB::create(static_cast<int>(corners.size()), 1.2f, 1, options.patch_size, 0, 2,
                      cv::ORB::HARRIS_SCORE, options.patch_size);
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
  if (descriptors1.type() != CV_8U || descriptors2.type() != CV_8U ||
      descriptors1.cols != descriptors2.cols)
    throw std::invalid_argument("MatchDescriptors: expected binary descriptors of one size");
  const int n1 = descriptors1.rows, n2 = descriptors2.rows, bytes = descriptors1.cols;
  // Every distance once: the best two of each row and the best of each column.
  std::vector<BestTwo> rows(n1);
  std::vector<int> column_best(n2, std::numeric_limits<int>::max()), column_index(n2, -1);
  for (int i = 0; i < n1; ++i) {
    const uchar* a = descriptors1.ptr<uchar>(i);
    for (int j = 0; j < n2; ++j) {
      const int distance = cv::hal::normHamming(a, descriptors2.ptr<uchar>(j), bytes);
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
