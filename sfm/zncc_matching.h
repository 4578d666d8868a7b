#pragma once
// Matching of corners between two prepared images by the zero-mean normalised cross-correlation
// (ZNCC) of small windows, each corner of the first image searching only inside its predicted
// region of the second (from the motion model, or by reprojection once the pose is known),
// with a distinctiveness (ratio) check and a mutual-best check.

#include <Eigen/Core>
#include <limits>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace omni {

struct ZnccOptions {
  int half_window = 5;  // windows of (2 half_window + 1)² pixels (Mouragnon et al. use 11×11)
  double min_zncc = 0.8;
  // Distinctiveness: with d = sqrt(1 − zncc) (proportional to the distance between normalised
  // windows), the best candidate must satisfy d_best < max_distance_ratio · d_second.
  double max_distance_ratio = 0.8;
  bool mutual = true;  // the match must also be the best for the second image's corner
  // A corner of the second image's pool (MatchZncc's pool_begin on; HarrisOptions::pool_corners)
  // is a match only at this ZNCC or more: the pool offers each corner more candidates, so more
  // chances of a look-alike above min_zncc, while a corner seen again one frame later scores
  // far above it.
  double min_zncc_pool = 0.9;
  // Refine the matched position in the second image to the subpixel maximum of the ZNCC
  // (separable parabola fits on samples subpixel_step apart, subpixel_iterations times), so
  // the match follows the first corner's window rather than the second detector's corner.
  bool subpixel = true;
  double subpixel_step = 0.5;
  int subpixel_iterations = 3;

  std::string Check() const;
};

// Where a corner of the first image is looked for in the second (pixels of the second prepared
// image): the points within `radius` of the segment from `center` to `center + along`, a disc
// when `along` is zero (an epipolar band when it is not). A negative radius skips the corner.
struct SearchRegion {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double radius = 20.0;
  Eigen::Vector2d along = Eigen::Vector2d::Zero();
};

struct ZnccMatch {
  int index1 = -1;  // corner of the first image
  int index2 = -1;  // corner of the second image
  double zncc = 0.0;
  // Where the first corner's window lies in the second image: corners2[index2], or the
  // subpixel ZNCC maximum near it when ZnccOptions::subpixel is set.
  Eigen::Vector2d pixel2 = Eigen::Vector2d::Zero();
};

// The best and second-best ZNCC scores offered, and the index of the best (-1: none yet).
struct BestTwoZncc {
  static constexpr double kNone = -2.0;  // below any ZNCC
  double best = kNone, second = kNone;
  int index = -1;
  void Offer(double score, int i) {
    if (score > best) {
      second = best;
      best = score;
      index = i;
    } else if (score > second) {
      second = score;
    }
  }
};

// The distinctiveness (ratio) test of a ZNCC match: the window distance of the best, which is
// proportional to sqrt(1 − zncc), is below max_distance_ratio times that of the second best;
// true when there is no second (second at or below BestTwoZncc::kNone).
bool IsDistinctZncc(double best, double second, double max_distance_ratio);

// The window of (2 half_window + 1)² pixels of a grey 8-bit image centred at a subpixel
// position, bilinearly sampled (as cv::getRectSubPix), zero-mean and unit-norm, into `values`
// (that many floats): the ZNCC of two windows is then their dot product. False when the window
// or its interpolation neighbours leave the image, or it is flat (below a quarter of a grey level
// of standard deviation).
bool NormalisedWindow(const cv::Mat& image, const Eigen::Vector2d& pixel, int half_window,
                      float* values);

// ZNCC of the windows centred at two subpixel positions (bilinear sampling); NaN when a window
// leaves its image or is flat.
double Zncc(const cv::Mat& image1, const Eigen::Vector2d& pixel1, const cv::Mat& image2,
            const Eigen::Vector2d& pixel2, int half_window);

// The normalised windows (NormalisedWindow) of an image's corners, computed once: the window of
// corner k at values[k · area], valid[k] false where NormalisedWindow failed. A caller may
// compute them ahead, on another thread, for MatchZncc's second image.
struct CornerWindows {
  int half_window = 0;
  int area = 0;
  std::vector<float> values;
  std::vector<char> valid;
  const float* operator[](size_t k) const { return values.data() + k * area; }
};
CornerWindows ComputeCornerWindows(const cv::Mat& image,
                                   const std::vector<Eigen::Vector2d>& corners, int half_window);

// corners1/corners2 are pixels of the prepared (grey 8-bit) images; regions has one entry per
// corner of the first image. Each corner appears in at most one match. The corners2 from
// pool_begin on are a pool (ZnccOptions::min_zncc_pool). windows2: the windows of corners2
// (ComputeCornerWindows with options.half_window) when computed beforehand; the same matches.
std::vector<ZnccMatch> MatchZncc(const cv::Mat& image1,
                                 const std::vector<Eigen::Vector2d>& corners1,
                                 const std::vector<SearchRegion>& regions, const cv::Mat& image2,
                                 const std::vector<Eigen::Vector2d>& corners2,
                                 const ZnccOptions& options,
                                 size_t pool_begin = std::numeric_limits<size_t>::max(),
                                 const CornerWindows* windows2 = nullptr);

}  // namespace omni
