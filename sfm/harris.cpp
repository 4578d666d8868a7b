#include "sfm/harris.h"

#include <Eigen/Core>
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "calib/error.h"
#include "sfm/internal/bilinear_grid.h"

namespace omni {

std::string HarrisOptions::Check() const {
  if (max_corners < 1) return "max_corners: expected at least 1";
  if (pool_corners < 0) return "pool_corners: expected 0 (none) or a number of corners";
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
  ThrowIfInvalid(options.Check(), "HarrisOptions");
  if (input.empty()) throw std::invalid_argument("PrepareImage: empty image");
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
  if (grey.type() != CV_8UC1) {
    throw std::invalid_argument("PrepareImage: expected 8 or 16 bits and 1, 3 or 4 channels");
  }
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

namespace {

// Buffers reused by the calls of one thread (the TrackBuilder detects on several threads), so
// that a frame allocates nothing of image size.
struct HarrisBuffers {
  cv::Mat padded;
  std::vector<int32_t> products;  // one row's products of the derivatives: xx, xy, yy
  std::vector<int32_t> row_sums;  // a ring of three rows' sums of three products, per channel
  cv::Mat response;
  cv::Mat row_maxima;             // the response's maxima of three along each row
  std::vector<float> padded_row;  // one response row with −∞ on each side
  std::vector<uint8_t> marks;     // one row's pixels above the threshold and 3×3 maxima
  std::vector<Corner> candidates;
  std::vector<int> bucket_of;
  std::vector<std::vector<Corner>> buckets;
  std::vector<int> cell_head, cell_next;  // the kept corners by cell (the duplicate test)
};

HarrisBuffers& ThreadBuffers() {
  thread_local HarrisBuffers buffers;
  return buffers;
}

// The kernels of HarrisResponse3x3, one row each. Their pointers are restricted parameters: the
// rows of bytes could otherwise alias the integer rows as far as the compiler knows, which keeps
// the loops from being vectorised.
//
// The 3×3 Sobel derivatives of the row `mid` (between `up` and `down`, each readable one byte
// before and after the row) and their products.
void SobelProductsRow(const uchar* __restrict up, const uchar* __restrict mid,
                      const uchar* __restrict down, int cols, int32_t* __restrict xx,
                      int32_t* __restrict xy, int32_t* __restrict yy) {
  for (int x = 0; x < cols; ++x) {
    const int32_t dx =
        (up[x + 1] - up[x - 1]) + 2 * (mid[x + 1] - mid[x - 1]) + (down[x + 1] - down[x - 1]);
    const int32_t dy =
        (down[x - 1] + 2 * down[x] + down[x + 1]) - (up[x - 1] + 2 * up[x] + up[x + 1]);
    xx[x] = dx * dx;
    xy[x] = dx * dy;
    yy[x] = dy * dy;
  }
}

// Sums of three along a row, reflected at both ends (BORDER_REFLECT_101; cols >= 3).
void SumsOfThreeRow(const int32_t* __restrict in, int cols, int32_t* __restrict out) {
  out[0] = in[1] + in[0] + in[1];
  for (int x = 1; x < cols - 1; ++x) out[x] = in[x - 1] + in[x] + in[x + 1];
  out[cols - 1] = in[cols - 2] + in[cols - 1] + in[cols - 2];
}

// One row of the response from the row sums of the rows above, here and below (channels xx, xy,
// yy one after the other, `width` apart): the block sums a, b, c of the scaled derivatives in
// float, as OpenCV computes them, and det − k trace².
void ResponseRow(const int32_t* __restrict above, const int32_t* __restrict here,
                 const int32_t* __restrict below, int cols, size_t width, float scale2, float k,
                 float* __restrict out) {
  for (int x = 0; x < cols; ++x) {
    const float a = static_cast<float>(above[x] + here[x] + below[x]) * scale2;
    const float b =
        static_cast<float>(above[width + x] + here[width + x] + below[width + x]) * scale2;
    const float c =
        static_cast<float>(above[2 * width + x] + here[2 * width + x] + below[2 * width + x]) *
        scale2;
    out[x] = a * c - b * b - k * (a + c) * (a + c);
  }
}

// cv::cornerHarris(image, response, 3, 3, k) on exact integer sums: the 3×3 Sobel derivatives
// dx, dy (BORDER_REFLECT_101 around the image), their products summed over 3×3 blocks (the
// products reflected the same way), and the response det − k trace² of the derivatives scaled
// as OpenCV scales them (1 / (4 · 3 · 255)). The block sums are exact integers, so the values
// are OpenCV's float pipeline's to its rounding. The image is streamed row by row: a row's
// products and their sums along the row go into a ring of three rows, and each response row is
// made from the ring as soon as the row below it is in, so the intermediate sums stay in cache
// (three rows instead of six images of int32). The image has at least 3 rows and 3 columns.
void HarrisResponse3x3(const cv::Mat& image, double k, HarrisBuffers* buffers) {
  const int rows = image.rows, cols = image.cols;
  const size_t width = static_cast<size_t>(cols);
  cv::copyMakeBorder(image, buffers->padded, 1, 1, 1, 1, cv::BORDER_REFLECT_101);
  buffers->products.resize(3 * width);
  buffers->row_sums.resize(9 * width);  // ring slot r % 3, channel c: (3 (r % 3) + c) · cols
  int32_t* const products = buffers->products.data();
  const auto slot_of = [&](int r) {
    return buffers->row_sums.data() + 3 * width * static_cast<size_t>(r % 3);
  };
  // Row r's products, then their sums of three along the row, into its ring slot.
  const auto add_row = [&](int r) {
    // Padded row r + 1 is image row r; the pointers start at image column 0.
    SobelProductsRow(buffers->padded.ptr<uchar>(r) + 1, buffers->padded.ptr<uchar>(r + 1) + 1,
                     buffers->padded.ptr<uchar>(r + 2) + 1, cols, products, products + width,
                     products + 2 * width);
    int32_t* const slot = slot_of(r);
    for (int channel = 0; channel < 3; ++channel)
      SumsOfThreeRow(products + channel * width, cols, slot + channel * width);
  };
  // The column sums of three (rows reflected at both ends) and the response.
  const float scale = static_cast<float>(1.0 / (4.0 * 3.0 * 255.0));
  const float scale2 = scale * scale;
  const float kf = static_cast<float>(k);
  buffers->response.create(rows, cols, CV_32F);
  add_row(0);
  add_row(1);
  for (int y = 0; y < rows; ++y) {
    if (y >= 1 && y + 1 < rows) add_row(y + 1);  // rows y − 1, y, y + 1 are now in the ring
    ResponseRow(slot_of(y > 0 ? y - 1 : 1), slot_of(y), slot_of(y + 1 < rows ? y + 1 : rows - 2),
                cols, width, scale2, kf, buffers->response.ptr<float>(y));
  }
}

// The scan of DetectHarrisCorners goes by chunks of pixels: a chunk without a marked pixel
// (MarkCandidates) is skipped after one test of its marks as two words.
constexpr int kScanChunk = 16;
bool NoneMarked(const uint8_t* marks) {
  uint64_t words[2];
  std::memcpy(words, marks, sizeof(words));
  return (words[0] | words[1]) == 0;
}

// The maxima of three along each response row (clipped to the row), for the suppression's
// 3×3 test of a whole row at once (vectorised).
void RowMaximaOfThree(const cv::Mat& response, HarrisBuffers* buffers) {
  const int cols = response.cols;
  buffers->row_maxima.create(response.rows, cols, CV_32F);
  std::vector<float>& padded = buffers->padded_row;
  padded.assign(static_cast<size_t>(cols + 2), -std::numeric_limits<float>::infinity());
  for (int y = 0; y < response.rows; ++y) {
    std::copy_n(response.ptr<float>(y), cols, padded.begin() + 1);
    const float* __restrict in = padded.data();
    float* __restrict out = buffers->row_maxima.ptr<float>(y);
    for (int x = 0; x < cols; ++x) {
      const float left = in[x], centre = in[x + 1], right = in[x + 2];
      const float side = left < right ? right : left;
      out[x] = centre < side ? side : centre;
    }
  }
}

// Marks the pixels [x_begin, x_end) of response row y that are at least the threshold and
// no smaller than any pixel of their 3×3 neighbourhood (clipped to the image), from the rows'
// maxima of three: the first test of IsLocalMaximum, on a whole row (vectorised).
void MarkCandidates(const cv::Mat& response, const cv::Mat& row_maxima, int y, int x_begin,
                    int x_end, float threshold, uint8_t* __restrict marks) {
  const float* __restrict r = response.ptr<float>(y);
  const float* __restrict up = row_maxima.ptr<float>(std::max(0, y - 1));
  const float* __restrict mid = row_maxima.ptr<float>(y);
  const float* __restrict down = row_maxima.ptr<float>(std::min(response.rows - 1, y + 1));
  for (int x = x_begin; x < x_end; ++x) {
    const float value = r[x];
    const float vertical = up[x] < down[x] ? down[x] : up[x];
    const float around = mid[x] < vertical ? vertical : mid[x];
    marks[x] = static_cast<uint8_t>((value >= threshold) & (value >= around));
  }
}

// True when response(x, y) is the largest value of the (2 radius + 1)² window around it
// (clipped to the image): the dilation test of non-maximum suppression, evaluated only where
// needed (on the pixels MarkCandidates marked: most pixels fail its 3×3 test).
bool IsLocalMaximum(const cv::Mat& response, int x, int y, int radius) {
  const float value = response.ptr<float>(y)[x];
  const int x0 = std::max(0, x - radius), x1 = std::min(response.cols - 1, x + radius);
  const int y0 = std::max(0, y - radius), y1 = std::min(response.rows - 1, y + radius);
  for (int yy = y0; yy <= y1; ++yy) {
    const float* row = response.ptr<float>(yy);
    for (int xx = x0; xx <= x1; ++xx)
      if (row[xx] > value) return false;
  }
  return true;
}

// Bilinear samples of `image` (8-bit grey) on the size × size grid whose top-left sample is at
// (x, y), into out (row-major); replicated border outside the image, as cv::getRectSubPix.
// Inside the image in two separable passes (internal::SampleBilinearGrid; `rows`: (size + 1) ·
// size floats).
void SampleWindow(const cv::Mat& image, float x, float y, int size, float* __restrict rows,
                  float* __restrict out) {
  const int ix = static_cast<int>(std::floor(x)), iy = static_cast<int>(std::floor(y));
  const float a = x - ix, b = y - iy;
  if (ix >= 0 && iy >= 0 && ix + size < image.cols && iy + size < image.rows) {
    internal::SampleBilinearGrid(image, ix, iy, a, b, size, rows, out);
    return;
  }
  cv::Mat window(size, size, CV_32F, out);
  cv::getRectSubPix(image, cv::Size(size, size),
                    cv::Point2f(x + 0.5f * (size - 1), y + 0.5f * (size - 1)), window, CV_32F);
}

// cv::cornerSubPix's own cap on the iterations.
constexpr int kMaxSubpixelIterations = 100;

// cv::cornerSubPix (no zero zone) with the window sampled in place: the same Gauss-weighted
// normal equations of the gradients, iterated until the step is below `epsilon` pixels.
void RefineCornersSubpixel(const cv::Mat& image, const HarrisOptions& options,
                           std::vector<cv::Point2f>* points) {
  const int half = options.subpixel_half_window;
  const int win = 2 * half + 1, padded = win + 2;
  // Per window pixel: the Gauss weight m, and m times the pixel's offset from the centre.
  const int area = win * win;
  Eigen::ArrayXf mask(area), mask_px(area), mask_py(area), gx(area), gy(area);
  Eigen::ArrayXf gxx(area), gxy(area), gyy(area);  // assigned in place: no allocation per step
  std::vector<float> buffer(padded * padded), rows((padded + 1) * padded);
  for (int i = 0; i < win; ++i) {
    const float y = static_cast<float>(i - half) / half;
    const float vy = std::exp(-y * y);
    for (int j = 0; j < win; ++j) {
      const float x = static_cast<float>(j - half) / half;
      const int k = i * win + j;
      mask[k] = vy * std::exp(-x * x);
      mask_px[k] = mask[k] * (j - half);
      mask_py[k] = mask[k] * (i - half);
    }
  }
  const double eps2 = options.subpixel_epsilon * options.subpixel_epsilon;
  const cv::Rect inside(0, 0, image.cols, image.rows);
  for (cv::Point2f& point : *points) {
    const cv::Point2f start = point;
    cv::Point2f current = start;
    for (int iteration = 0;
         iteration < std::min(options.subpixel_iterations, kMaxSubpixelIterations); ++iteration) {
      // The padded window centred at `current`, its central differences, and the weighted sums
      // of the normal equations (float, vectorised).
      SampleWindow(image, current.x - 0.5f * (padded - 1), current.y - 0.5f * (padded - 1), padded,
                   rows.data(), buffer.data());
      for (int i = 0, k = 0; i < win; ++i) {
        const float* row = buffer.data() + (i + 1) * padded + 1;
        for (int j = 0; j < win; ++j, ++k) {
          gx[k] = row[j + 1] - row[j - 1];
          gy[k] = row[j + padded] - row[j - padded];
        }
      }
      gxx = gx * gx;
      gxy = gx * gy;
      gyy = gy * gy;
      const double a = (mask * gxx).sum(), b = (mask * gxy).sum(), c = (mask * gyy).sum();
      const double bb1 = (mask_px * gxx + mask_py * gxy).sum();
      const double bb2 = (mask_px * gxy + mask_py * gyy).sum();
      const double det = a * c - b * b;
      if (std::fabs(det) <= DBL_EPSILON * DBL_EPSILON) break;
      const double scale = 1.0 / det;
      const cv::Point2f next(static_cast<float>(current.x + c * scale * bb1 - b * scale * bb2),
                             static_cast<float>(current.y - b * scale * bb1 + a * scale * bb2));
      const double err =
          (next.x - current.x) * (next.x - current.x) + (next.y - current.y) * (next.y - current.y);
      if (!inside.contains(next)) break;
      current = next;
      if (err <= eps2) break;
    }
    // Too far from the start: poor convergence, keep the start (as cv::cornerSubPix).
    if (std::fabs(current.x - start.x) > half || std::fabs(current.y - start.y) > half)
      current = start;
    point = current;
  }
}

}  // namespace

std::vector<Corner> DetectHarrisCorners(const cv::Mat& prepared, const HarrisOptions& options,
                                        size_t* num_first) {
  if (num_first) *num_first = 0;
  ThrowIfInvalid(options.Check(), "HarrisOptions");
  if (prepared.type() != CV_8UC1) {
    throw std::invalid_argument("DetectHarrisCorners: expected an 8-bit grey image (PrepareImage)");
  }
  std::vector<Corner> corners;
  if (prepared.cols <= 2 * options.border || prepared.rows <= 2 * options.border) return corners;

  HarrisBuffers& buffers = ThreadBuffers();
  cv::Mat& response = buffers.response;
  if (options.block_size == 3 && options.sobel_aperture == 3 && prepared.rows >= 3 &&
      prepared.cols >= 3)
    HarrisResponse3x3(prepared, options.harris_k, &buffers);
  else
    cv::cornerHarris(prepared, response, options.block_size, options.sobel_aperture,
                     options.harris_k);
  double max_response = 0.0;
  cv::minMaxLoc(response, nullptr, &max_response);
  if (!(max_response > 0.0)) return corners;
  const float threshold = static_cast<float>(options.quality_level * max_response);

  // Local maxima over a (2 min_distance + 1)² neighbourhood above the threshold, each with its
  // grid bucket.
  const int num_cells = options.grid_cols * options.grid_rows;
  std::vector<Corner>& candidates = buffers.candidates;
  std::vector<int>& bucket_of = buffers.bucket_of;
  candidates.clear();
  bucket_of.clear();
  std::vector<int> bucket_size(num_cells, 0);
  const int x_begin = options.border, x_end = prepared.cols - options.border;
  const int y_begin = options.border, y_end = prepared.rows - options.border;
  RowMaximaOfThree(response, &buffers);
  std::vector<uint8_t>& marks = buffers.marks;
  marks.assign(static_cast<size_t>(prepared.cols), 0);
  for (int y = y_begin; y < y_end; ++y) {
    const float* r = response.ptr<float>(y);
    const int row = std::min(options.grid_rows - 1, y * options.grid_rows / prepared.rows);
    MarkCandidates(response, buffers.row_maxima, y, x_begin, x_end, threshold, marks.data());
    for (int x0 = x_begin; x0 < x_end; x0 += kScanChunk) {
      const int x1 = std::min(x0 + kScanChunk, x_end);
      if (x1 - x0 == kScanChunk && NoneMarked(marks.data() + x0)) continue;  // most pixels
      for (int x = x0; x < x1; ++x) {
        if (!marks[x]) continue;
        if (!IsLocalMaximum(response, x, y, options.min_distance)) continue;
        const int col = std::min(options.grid_cols - 1, x * options.grid_cols / prepared.cols);
        const int cell = row * options.grid_cols + col;
        candidates.push_back({Eigen::Vector2d(x, y), r[x]});
        bucket_of.push_back(cell);
        ++bucket_size[cell];
      }
    }
  }

  // Each bucket keeps its strongest corners up to its quota; the quota left unused by poor
  // buckets goes to the others in turn, so the total stays max_corners when there are enough.
  // With a pool (HarrisOptions::pool_corners), the same share-out again for the pool's budget:
  // each bucket's corners beyond its first share are its pool corners.
  const auto share_out = [&](int budget, std::vector<int>* taken) {
    taken->assign(num_cells, 0);
    int remaining = budget;
    while (remaining > 0) {
      int open_buckets = 0;
      for (int i = 0; i < num_cells; ++i) open_buckets += (*taken)[i] < bucket_size[i] ? 1 : 0;
      if (open_buckets == 0) break;
      const int quota = std::max(1, remaining / open_buckets);
      for (int i = 0; i < num_cells && remaining > 0; ++i) {
        const int extra = std::min(quota, std::min(bucket_size[i] - (*taken)[i], remaining));
        (*taken)[i] += extra;
        remaining -= extra;
      }
    }
  };
  std::vector<int> first_share;
  share_out(options.max_corners, &first_share);
  std::vector<int> taken = first_share;
  const bool pool = options.pool_corners > options.max_corners;
  if (pool) {
    share_out(options.pool_corners, &taken);
    for (int i = 0; i < num_cells; ++i) taken[i] = std::max(taken[i], first_share[i]);
  }
  // Only the buckets that must drop corners are ordered (a partial selection of their best).
  std::vector<std::vector<Corner>>& buckets = buffers.buckets;
  buckets.resize(num_cells);
  for (auto& bucket : buckets) bucket.clear();
  for (size_t k = 0; k < candidates.size(); ++k) buckets[bucket_of[k]].push_back(candidates[k]);
  const auto stronger = [](const Corner& a, const Corner& b) { return a.response > b.response; };
  // in_pool[k]: corners[k] is beyond its bucket's first share.
  std::vector<char> in_pool;
  for (int i = 0; i < num_cells; ++i) {
    std::vector<Corner>& bucket = buckets[i];
    if (taken[i] < static_cast<int>(bucket.size()))
      std::nth_element(bucket.begin(), bucket.begin() + taken[i], bucket.end(), stronger);
    if (pool && first_share[i] < taken[i])
      std::nth_element(bucket.begin(), bucket.begin() + first_share[i], bucket.begin() + taken[i],
                       stronger);
    corners.insert(corners.end(), bucket.begin(), bucket.begin() + taken[i]);
    if (pool) {
      in_pool.insert(in_pool.end(), first_share[i], 0);
      in_pool.insert(in_pool.end(), taken[i] - first_share[i], 1);
    }
  }
  if (corners.empty()) return corners;

  std::vector<cv::Point2f> points;
  points.reserve(corners.size());
  for (const Corner& corner : corners)
    points.emplace_back(static_cast<float>(corner.pixel.x()), static_cast<float>(corner.pixel.y()));
  if (options.subpixel_iterations > 0) RefineCornersSubpixel(prepared, options, &points);
  // The subpixel step wanders off an edge-like or ill-defined corner: such corners are dropped,
  // as their windows slide along the edge when matched.
  struct Refined {
    Corner corner;
    bool in_pool;
  };
  std::vector<Refined> refined_corners;
  refined_corners.reserve(corners.size());
  for (size_t i = 0; i < corners.size(); ++i) {
    const Eigen::Vector2d refined(points[i].x, points[i].y);
    if (options.subpixel_iterations > 0 &&
        !((refined - corners[i].pixel).norm() < options.max_subpixel_shift))
      continue;
    refined_corners.push_back({{refined, corners[i].response}, pool && in_pool[i] != 0});
  }
  // Two maxima of one physical corner may converge to the same place: keep the stronger (ties
  // of response by position, so that the order does not depend on the selection above). The
  // pool comes after the first shares, so that those are exactly the corners without a pool, and
  // a pool corner is dropped at a corner of the first shares.
  std::sort(refined_corners.begin(), refined_corners.end(),
            [](const Refined& ra, const Refined& rb) {
              if (ra.in_pool != rb.in_pool) return rb.in_pool;
              const Corner& a = ra.corner;
              const Corner& b = rb.corner;
              if (a.response != b.response) return a.response > b.response;
              if (a.pixel.y() != b.pixel.y()) return a.pixel.y() < b.pixel.y();
              return a.pixel.x() < b.pixel.x();
            });
  // The kept corners by cells of side min_separation (a linked list per cell): a candidate is
  // compared with those of the 3 × 3 cells around it only.
  corners.clear();
  const double min_separation = 0.5 * options.min_distance;
  const int cols = static_cast<int>(prepared.cols / min_separation) + 1;
  const int rows = static_cast<int>(prepared.rows / min_separation) + 1;
  std::vector<int>& head = buffers.cell_head;
  std::vector<int>& next = buffers.cell_next;
  head.assign(static_cast<size_t>(cols) * rows, -1);
  next.clear();
  const auto cell_of = [&](const Eigen::Vector2d& p, int* col, int* row) {
    *col = std::clamp(static_cast<int>(p.x() / min_separation), 0, cols - 1);
    *row = std::clamp(static_cast<int>(p.y() / min_separation), 0, rows - 1);
  };
  for (const Refined& candidate : refined_corners) {
    int col = 0, row = 0;
    cell_of(candidate.corner.pixel, &col, &row);
    bool duplicate = false;
    for (int r = std::max(0, row - 1); r <= std::min(rows - 1, row + 1) && !duplicate; ++r)
      for (int c = std::max(0, col - 1); c <= std::min(cols - 1, col + 1) && !duplicate; ++c)
        for (int k = head[static_cast<size_t>(r) * cols + c]; k >= 0; k = next[k])
          if ((corners[k].pixel - candidate.corner.pixel).squaredNorm() <
              min_separation * min_separation) {
            duplicate = true;
            break;
          }
    if (duplicate) continue;
    int& cell_head = head[static_cast<size_t>(row) * cols + col];
    next.push_back(cell_head);
    cell_head = static_cast<int>(corners.size());
    corners.push_back(candidate.corner);
    if (num_first && !candidate.in_pool) ++*num_first;
  }
  return corners;
}

double WorkingDownscale(int width, int height, int target_longest_side) {
  const int longest = std::max(width, height);
  if (target_longest_side <= 0 || longest <= 1.25 * target_longest_side) return 1.0;
  return static_cast<double>(longest) / target_longest_side;
}

}  // namespace omni
