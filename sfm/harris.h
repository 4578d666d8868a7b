#pragma once
// Harris corners with an even spatial spread (a quota per grid bucket) and subpixel refinement
// (paper §2 after Mouragnon et al.: Harris points matched along the sequence).
//
// Images go through PrepareImage once (grey, 8 bits, optionally downscaled: the paper halves
// the Ladybug images to 512×384); detection and matching work in the prepared image's pixels,
// and PreparedToInputPixel maps a corner back to the input image for Camera::Unproject.

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace omni {

struct HarrisOptions {
  // Corners kept per image (paper §2 / Mouragnon et al.: about 300–400 per image).
  int max_corners = 350;
  // A pool of further corners, listed after the max_corners (each grid bucket's next strongest,
  // shared out as for a budget of pool_corners in all): candidates for continuing the tracks of
  // the frame before (TrackBuilderOptions::continuation_pool), so that a track does not end
  // only because its corner ranked below the max_corners strongest in this frame. 0 or at most
  // max_corners: no pool.
  int pool_corners = 0;
  // The image is split into grid_cols × grid_rows buckets, each keeping at most its share.
  int grid_cols = 8;
  int grid_rows = 6;
  // Input images are shrunk by this factor before detection (1: none; 2: the paper's halving).
  double downscale = 1.0;
  int block_size = 3;      // Harris neighbourhood (pixels)
  int sobel_aperture = 3;  // derivative kernel
  double harris_k = 0.04;
  // A corner's response must be at least this share of the image's strongest response
  // (cv::goodFeaturesToTrack's usual 0.01). 0.003 lets the buckets of weak texture (plain walls,
  // the ground) fill their share: a denser, more even surface on every drive measured, at 1.2 to
  // 1.3 times the keyframes' ATE on the multi-camera drives (the single camera's gain: its count
  // was held far below the budget), docs/figures.md F64.
  double quality_level = 0.003;
  // Non-maximum suppression radius: kept corners are at least this far apart (pixels).
  int min_distance = 4;
  // Corners closer than this to the border are dropped (leave room for matching windows).
  int border = 8;
  // cv::cornerSubPix: half window, iterations and stopping step (pixels).
  int subpixel_half_window = 3;
  int subpixel_iterations = 20;
  double subpixel_epsilon = 0.01;
  // A corner the subpixel step moves farther than this from its integer maximum is not a
  // well-localised corner (an edge or a blob): it is dropped (pixels; the Harris maximum sits
  // about a pixel inside a blurred corner).
  double max_subpixel_shift = 2.0;

  std::string Check() const;
};

struct Corner {
  Eigen::Vector2d pixel = Eigen::Vector2d::Zero();  // prepared image, subpixel
  float response = 0.0f;                            // Harris response
};

// Grey 8-bit image, shrunk by options.downscale (cv::INTER_AREA). Accepts 8-bit grey, BGR or
// BGRA, or 16-bit grey.
cv::Mat PrepareImage(const cv::Mat& input, const HarrisOptions& options);

// Pixel of the prepared image -> pixel of the input image (pixel centres at integers).
// The shrink factor of a rig's images when none is given: the longest image side to about
// target_longest_side pixels (the working resolution the tracker's pixel radii are tuned for);
// 1 for images up to 1.25 times that.
double WorkingDownscale(int width, int height, int target_longest_side = 640);

Eigen::Vector2d PreparedToInputPixel(const Eigen::Vector2d& prepared, double downscale);
Eigen::Vector2d InputToPreparedPixel(const Eigen::Vector2d& input, double downscale);

// Corners of a prepared image, strongest first; with a pool, the max_corners strongest first
// (the corners without a pool), then the pool, strongest first. num_first, if given: how many
// come before the pool (all without one).
std::vector<Corner> DetectHarrisCorners(const cv::Mat& prepared, const HarrisOptions& options,
                                        size_t* num_first = nullptr);

}  // namespace omni
