#pragma once
// INTERNAL to sfm/*.cpp: the bilinear samples of an 8-bit grey image on a square grid of pixel
// spacing, in two separable passes (the ZNCC windows, the corners' subpixel step).

#include <opencv2/core.hpp>

namespace omni::internal {

// One row interpolated along x: h[c] = p[c] + a (p[c + 1] − p[c]) for c < size. Restricted
// pointers: the row of bytes could otherwise alias the floats as far as the compiler knows,
// which kept the loop scalar.
inline void InterpolateRowAlongX(const uchar* __restrict p, int size, float a,
                                 float* __restrict h) {
  for (int c = 0; c < size; ++c) {
    const float left = p[c], right = p[c + 1];
    h[c] = left + a * (right - left);
  }
}

// The width × height samples whose top-left one lies at (ix + a, iy + b), into `out`
// (row-major), as SampleBilinearGrid (`rows`: (height + 1) · width floats). Each sample is the
// same arithmetic on the same four pixels whatever the grid's size, so a sample of a wider grid
// equals, to the bit, the sample at its place in a smaller one.
inline void SampleBilinearRect(const cv::Mat& image, int ix, int iy, float a, float b, int width,
                               int height, float* __restrict rows, float* __restrict out) {
  for (int r = 0; r <= height; ++r)
    InterpolateRowAlongX(image.ptr<uchar>(iy + r) + ix, width, a,
                         rows + static_cast<size_t>(r) * width);
  for (int k = 0; k < width * height; ++k) out[k] = rows[k] + b * (rows[k + width] - rows[k]);
}

// The size × size samples whose top-left one lies at (ix + a, iy + b), a and b in [0, 1), into
// `out` (row-major): size + 1 rows interpolated along x into `rows` ((size + 1) · size floats;
// each pixel converted once), then pairs of them along y (two products a sample, not four).
// The grid and its interpolation neighbours must lie inside the image.
inline void SampleBilinearGrid(const cv::Mat& image, int ix, int iy, float a, float b, int size,
                               float* __restrict rows, float* __restrict out) {
  SampleBilinearRect(image, ix, iy, a, b, size, size, rows, out);
}

}  // namespace omni::internal
