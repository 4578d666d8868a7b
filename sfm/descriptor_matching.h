#pragma once
// Matching without a motion prior: a binary descriptor (ORB's steered BRIEF) at each Harris
// corner, at several scales of the image (a corner seen nearer or farther in a wide step:
// two corners match at the smallest distance between the one's first scale and any of the
// other's, either way), upright by default (a rig on a car does not roll; steering by the
// patch's intensity centroid, `oriented`, lost matches on the synthetic drives), and
// all-against-all matching of two sets of corners by Hamming distance with a ratio test and a
// mutual-best check. The tracker's front end falls back on it when the image-motion model does
// not hold: the first frames of a drive (no motion model yet), wide baselines and low frame
// rates, and the re-localisation after frames it could not track. The matches are not verified
// here: the caller's geometry (relative pose or resection in RANSAC) is the verification.

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace omni {

struct DescriptorMatchingOptions {
  // ORB's patch side (pixels of the prepared image); the image is padded by reflection so that
  // corners near the border get a descriptor too.
  int patch_size = 31;
  // Lowe's ratio: the best Hamming distance must be below this share of the second best.
  double max_ratio = 0.8;
  // Absolute bound on the best distance (of the descriptor's 256 bits).
  int max_distance = 80;
  bool mutual = true;  // the match must also be the best for the second set's descriptor
  // Scales of the image each corner is described at (1: one scale), level_scale apart.
  int levels = 3;
  double level_scale = 1.2;
  // Steered by the orientation of the patch (intensity centroid) at each scale; false: upright.
  bool oriented = false;

  std::string Check() const;
};

// options.levels 32-byte rows per corner (CV_8U), in the corners' order: corner i's scales are
// rows i * levels to i * levels + levels - 1.
cv::Mat DescribeCorners(const cv::Mat& prepared, const std::vector<Eigen::Vector2d>& corners,
                        const DescriptorMatchingOptions& options);

struct DescriptorMatch {
  int index1 = -1;  // row of the first descriptors
  int index2 = -1;  // row of the second
  int distance = 0;
};

// Matches of corners (index1, index2: corners, not rows; descriptors of DescribeCorners with
// the same options); each corner of either set appears in at most one match.
std::vector<DescriptorMatch> MatchDescriptors(const cv::Mat& descriptors1,
                                              const cv::Mat& descriptors2,
                                              const DescriptorMatchingOptions& options);

}  // namespace omni
