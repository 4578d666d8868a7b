#include "calib/png_grey.h"

#include <libdeflate.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

namespace omni {
namespace {

uint32_t BigEndian32(const unsigned char* bytes) {
  return (uint32_t{bytes[0]} << 24) | (uint32_t{bytes[1]} << 16) | (uint32_t{bytes[2]} << 8) |
         uint32_t{bytes[3]};
}

bool IsChunk(const unsigned char* type, const char* name) {
  return std::memcmp(type, name, 4) == 0;
}

// Ancillary chunks that OpenCV's PNG decoder reads without changing the pixels of an 8-bit
// grey image (no gamma or colour conversion is applied; eXIf, which rotates, is not here).
bool IsDescriptiveChunk(const unsigned char* type) {
  for (const char* name : {"tEXt", "zTXt", "iTXt", "tIME", "pHYs", "gAMA", "cHRM", "sRGB", "iCCP"})
    if (IsChunk(type, name)) return true;
  return false;
}

struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* decompressor) const {
    libdeflate_free_decompressor(decompressor);
  }
};

// Reused by the calls of one thread (a frame's cameras are decoded in parallel).
struct PngBuffers {
  std::unique_ptr<libdeflate_decompressor, DecompressorDeleter> decompressor;
  std::vector<unsigned char> compressed, filtered;
};

PngBuffers& ThreadBuffers() {
  thread_local PngBuffers buffers;
  if (!buffers.decompressor) buffers.decompressor.reset(libdeflate_alloc_decompressor());
  return buffers;
}

// The Paeth predictor of the PNG specification (ties: left, then above, then above-left).
inline int Paeth(int left, int above, int above_left) {
  const int p = above - above_left, q = left - above_left;
  const int pa = std::abs(p), pb = std::abs(q), pc = std::abs(p + q);
  const int above_or_corner = pb <= pc ? above : above_left;
  return pa <= pb && pa <= pc ? left : above_or_corner;
}

// Undoes the Paeth filter of one row (one byte per pixel) with a row above.
void UnfilterPaethRow(const unsigned char* in, const unsigned char* up, int width,
                      unsigned char* out) {
  int left = 0, above_left = 0;
  for (int x = 0; x < width; ++x) {
    const int above = up[x];
    out[x] = static_cast<unsigned char>(in[x] + Paeth(left, above, above_left));
    left = out[x];
    above_left = above;
  }
}

// Undoes the Paeth filter of two consecutive rows (in0 below `up`, in1 below in0) at once: the
// second row one pixel behind the first, whose pixels it takes as its row above, so that the
// two serial chains through the left neighbour run side by side. The same bytes as two calls of
// UnfilterPaethRow.
void UnfilterPaethRowPair(const unsigned char* in0, const unsigned char* in1,
                          const unsigned char* up, int width, unsigned char* out0,
                          unsigned char* out1) {
  int left0 = 0, above_left0 = 0, left1 = 0, above_left1 = 0;
  for (int x = 0; x < width; ++x) {
    const int above0 = up[x];
    const unsigned char decoded0 =
        static_cast<unsigned char>(in0[x] + Paeth(left0, above0, above_left0));
    out0[x] = decoded0;
    if (x > 0) {  // row 1 at x − 1: its pixel above is row 0's at x − 1, left0 before this x
      const int above1 = left0;
      const unsigned char decoded1 =
          static_cast<unsigned char>(in1[x - 1] + Paeth(left1, above1, above_left1));
      out1[x - 1] = decoded1;
      left1 = decoded1;
      above_left1 = above1;
    }
    left0 = decoded0;
    above_left0 = above0;
  }
  const int above1 = left0;  // the last pixel of row 1
  out1[width - 1] = static_cast<unsigned char>(in1[width - 1] + Paeth(left1, above1, above_left1));
}

// Undoes the filter of each row (one byte per pixel): rows of 1 + width bytes, the first the
// filter type. False on an unknown filter type.
bool Unfilter(const unsigned char* filtered, int width, int height, cv::Mat* image) {
  for (int y = 0; y < height; ++y) {
    const unsigned char* in = filtered + static_cast<size_t>(y) * (width + 1);
    const int type = *in++;
    unsigned char* out = image->ptr<unsigned char>(y);
    const unsigned char* up = y > 0 ? image->ptr<unsigned char>(y - 1) : nullptr;
    switch (type) {
      case 0:
        std::memcpy(out, in, width);
        break;
      case 1: {
        unsigned char left = 0;
        for (int x = 0; x < width; ++x) out[x] = left = static_cast<unsigned char>(in[x] + left);
        break;
      }
      case 2:
        if (up)
          for (int x = 0; x < width; ++x) out[x] = static_cast<unsigned char>(in[x] + up[x]);
        else
          std::memcpy(out, in, width);
        break;
      case 3: {
        int left = 0;
        for (int x = 0; x < width; ++x) {
          const int above = up ? up[x] : 0;
          out[x] = static_cast<unsigned char>(in[x] + ((left + above) >> 1));
          left = out[x];
        }
        break;
      }
      case 4: {
        if (!up) {  // no row above: the predictor is the left neighbour (Sub)
          unsigned char left = 0;
          for (int x = 0; x < width; ++x) out[x] = left = static_cast<unsigned char>(in[x] + left);
          break;
        }
        const unsigned char* next = in + width;  // the filter type of row y + 1
        if (y + 1 < height && *next == 4) {      // two Paeth rows: decoded side by side
          UnfilterPaethRowPair(in, next + 1, up, width, out, image->ptr<unsigned char>(y + 1));
          ++y;
        } else {
          UnfilterPaethRow(in, up, width, out);
        }
        break;
      }
      default:
        return false;
    }
  }
  return true;
}

}  // namespace

bool DecodePlainGreyPng(const std::string& data, cv::Mat* image) {
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
  static const unsigned char kSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (data.size() < 8 + 25 || std::memcmp(bytes, kSignature, 8) != 0) return false;
  // IHDR: width, height, bit depth 8, colour type 0 (grey), compression 0, filter 0, no
  // interlace.
  if (BigEndian32(bytes + 8) != 13 || !IsChunk(bytes + 12, "IHDR")) return false;
  const unsigned char* header = bytes + 16;
  const uint32_t width = BigEndian32(header), height = BigEndian32(header + 4);
  if (width == 0 || height == 0 || width > (1u << 15) || height > (1u << 15)) return false;
  if (header[8] != 8 || header[9] != 0 || header[10] != 0 || header[11] != 0 || header[12] != 0)
    return false;
  PngBuffers& buffers = ThreadBuffers();
  if (!buffers.decompressor) return false;
  buffers.compressed.clear();
  size_t position = 8 + 25;
  bool ended = false;
  while (!ended) {
    if (data.size() - position < 12) return false;
    const uint32_t length = BigEndian32(bytes + position);
    if (length > data.size() - position - 12) return false;
    const unsigned char* type = bytes + position + 4;
    const unsigned char* payload = bytes + position + 8;
    if (IsChunk(type, "IDAT"))
      buffers.compressed.insert(buffers.compressed.end(), payload, payload + length);
    else if (IsChunk(type, "IEND"))
      ended = true;
    else if (!IsDescriptiveChunk(type))
      return false;
    position += 12 + length;
  }
  // The filtered rows exactly: a stream that ends early, runs longer or fails its check is
  // left to libpng's own handling.
  const size_t expected = static_cast<size_t>(height) * (width + 1);
  // Deflate expands at most 1032 times: a header claiming more than the data can hold is not
  // decoded here (nor buffered).
  if (expected / 1032 > buffers.compressed.size() + 1) return false;
  buffers.filtered.resize(expected + 1);
  size_t produced = 0;
  if (libdeflate_zlib_decompress(buffers.decompressor.get(), buffers.compressed.data(),
                                 buffers.compressed.size(), buffers.filtered.data(),
                                 buffers.filtered.size(), &produced) != LIBDEFLATE_SUCCESS ||
      produced != expected)
    return false;
  image->create(static_cast<int>(height), static_cast<int>(width), CV_8UC1);
  return Unfilter(buffers.filtered.data(), static_cast<int>(width), static_cast<int>(height),
                  image);
}

}  // namespace omni
