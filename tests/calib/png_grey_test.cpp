// The plain grey PNG decoder (calib/png_grey.h): PNGs made here byte by byte with each of the
// five row filters (and a mix), and PNGs OpenCV writes, decode to the image written and to what
// cv::imdecode gives; anything that is not a plain 8-bit grey PNG is left to OpenCV.

#include "calib/png_grey.h"

#include <gtest/gtest.h>
#include <zlib.h>

#include <cstdint>
#include <cstdlib>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

namespace omni {
namespace {

// A grey image with flat areas, ramps and noise, so that every filter meets large and small
// differences and wraps around 255.
cv::Mat TestImage(int width, int height) {
  cv::Mat image(height, width, CV_8UC1);
  uint32_t state = 12345;
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      state = state * 1664525u + 1013904223u;
      const int noise = static_cast<int>(state >> 24);
      const int value = (x < width / 3) ? 200 : (y < height / 2 ? 7 * x + 3 * y : noise);
      image.at<uint8_t>(y, x) = static_cast<uint8_t>(value & 0xff);
    }
  return image;
}

void Append32(std::string* out, uint32_t value) {
  for (int shift = 24; shift >= 0; shift -= 8) out->push_back(static_cast<char>(value >> shift));
}

void AppendChunk(std::string* png, const std::string& type, const std::string& payload) {
  Append32(png, static_cast<uint32_t>(payload.size()));
  const std::string body = type + payload;
  png->append(body);
  Append32(png, static_cast<uint32_t>(
                    crc32(0L, reinterpret_cast<const Bytef*>(body.data()), body.size())));
}

// The Paeth predictor as the PNG specification writes it.
int SpecPaeth(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  if (pb <= pc) return b;
  return c;
}

struct PngParts {
  int interlace = 0;
  int colour_type = 0;
  std::string extra_chunk_type;  // written before the image data, when not empty
  size_t drop_filtered_bytes = 0;
};

// An 8-bit grey PNG of `image` whose row y uses filter filter_of_row(y); its data split into
// two IDAT chunks.
template <typename FilterOfRow>
std::string MakePng(const cv::Mat& image, FilterOfRow filter_of_row, const PngParts& parts = {}) {
  std::string filtered;
  for (int y = 0; y < image.rows; ++y) {
    const int filter = filter_of_row(y);
    filtered.push_back(static_cast<char>(filter));
    for (int x = 0; x < image.cols; ++x) {
      const int value = image.at<uint8_t>(y, x);
      const int a = x > 0 ? image.at<uint8_t>(y, x - 1) : 0;
      const int b = y > 0 ? image.at<uint8_t>(y - 1, x) : 0;
      const int c = x > 0 && y > 0 ? image.at<uint8_t>(y - 1, x - 1) : 0;
      const int predicted = filter == 0   ? 0
                            : filter == 1 ? a
                            : filter == 2 ? b
                            : filter == 3 ? (a + b) / 2
                                          : SpecPaeth(a, b, c);
      filtered.push_back(static_cast<char>((value - predicted) & 0xff));
    }
  }
  filtered.resize(filtered.size() - parts.drop_filtered_bytes);
  uLongf compressed_size = compressBound(filtered.size());
  std::string compressed(compressed_size, '\0');
  EXPECT_EQ(compress2(reinterpret_cast<Bytef*>(compressed.data()), &compressed_size,
                      reinterpret_cast<const Bytef*>(filtered.data()), filtered.size(), 6),
            Z_OK);
  compressed.resize(compressed_size);

  std::string png("\x89PNG\r\n\x1a\n", 8);
  std::string header;
  Append32(&header, static_cast<uint32_t>(image.cols));
  Append32(&header, static_cast<uint32_t>(image.rows));
  header += std::string{8, static_cast<char>(parts.colour_type), 0, 0,
                        static_cast<char>(parts.interlace)};
  AppendChunk(&png, "IHDR", header);
  AppendChunk(&png, "tEXt", std::string("Software\0test", 13));
  if (!parts.extra_chunk_type.empty()) AppendChunk(&png, parts.extra_chunk_type, "abcd");
  const size_t half = compressed.size() / 2;
  AppendChunk(&png, "IDAT", compressed.substr(0, half));
  AppendChunk(&png, "IDAT", compressed.substr(half));
  AppendChunk(&png, "IEND", "");
  return png;
}

cv::Mat OpenCvDecode(const std::string& png) {
  return cv::imdecode(
      cv::Mat(1, static_cast<int>(png.size()), CV_8U, const_cast<char*>(png.data())),
      cv::IMREAD_GRAYSCALE);
}

double MaxDifference(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return 1e9;
  return cv::norm(a, b, cv::NORM_INF);
}

TEST(CalibPlainGreyPng, EachRowFilterDecodesToTheImageAndToOpenCvsPixels) {
  const cv::Mat image = TestImage(37, 23);
  // 5: row y uses filter y mod 5; 6: pairs of Paeth rows between Sub rows, then a single one
  // (the decoder takes two consecutive Paeth rows side by side).
  for (int filter = 0; filter <= 6; ++filter) {
    const std::string png = MakePng(image, [filter](int y) {
      return filter == 5 ? y % 5 : filter == 6 ? (y % 3 == 0 ? 1 : 4) : filter;
    });
    cv::Mat decoded;
    ASSERT_TRUE(DecodePlainGreyPng(png, &decoded)) << "filter " << filter;
    EXPECT_EQ(decoded.type(), CV_8UC1);
    EXPECT_EQ(MaxDifference(decoded, image), 0.0) << "filter " << filter;
    EXPECT_EQ(MaxDifference(OpenCvDecode(png), image), 0.0) << "filter " << filter;
  }
}

TEST(CalibPlainGreyPng, OpenCvsOwnGreyPngsDecodeAlike) {
  const cv::Mat image = TestImage(211, 97);
  for (const int level : {0, 1, 3, 9})
    for (const int strategy : {cv::IMWRITE_PNG_STRATEGY_DEFAULT, cv::IMWRITE_PNG_STRATEGY_FILTERED,
                               cv::IMWRITE_PNG_STRATEGY_RLE}) {
      std::vector<uchar> bytes;
      ASSERT_TRUE(
          cv::imencode(".png", image, bytes,
                       {cv::IMWRITE_PNG_COMPRESSION, level, cv::IMWRITE_PNG_STRATEGY, strategy}));
      const std::string png(bytes.begin(), bytes.end());
      cv::Mat decoded;
      ASSERT_TRUE(DecodePlainGreyPng(png, &decoded)) << level << " " << strategy;
      EXPECT_EQ(MaxDifference(decoded, image), 0.0) << level << " " << strategy;
      EXPECT_EQ(MaxDifference(decoded, OpenCvDecode(png)), 0.0) << level << " " << strategy;
    }
}

TEST(CalibPlainGreyPng, AnythingElseIsLeftToOpenCv) {
  const cv::Mat image = TestImage(37, 23);
  const auto paeth = [](int) { return 4; };
  cv::Mat decoded;
  ASSERT_TRUE(DecodePlainGreyPng(MakePng(image, paeth), &decoded));  // the plain case
  PngParts interlaced;
  interlaced.interlace = 1;
  EXPECT_FALSE(DecodePlainGreyPng(MakePng(image, paeth, interlaced), &decoded));
  PngParts grey_alpha;
  grey_alpha.colour_type = 4;
  EXPECT_FALSE(DecodePlainGreyPng(MakePng(image, paeth, grey_alpha), &decoded));
  for (const std::string type : {"eXIf", "tRNS", "sBIT", "abCd"}) {
    PngParts extra;
    extra.extra_chunk_type = type;
    EXPECT_FALSE(DecodePlainGreyPng(MakePng(image, paeth, extra), &decoded)) << type;
  }
  PngParts short_data;  // the last row incomplete
  short_data.drop_filtered_bytes = 5;
  EXPECT_FALSE(DecodePlainGreyPng(MakePng(image, paeth, short_data), &decoded));
  EXPECT_FALSE(DecodePlainGreyPng(MakePng(image, [](int y) { return y == 7 ? 5 : 1; }), &decoded));

  std::vector<uchar> bytes;
  cv::Mat colour;
  cv::merge(std::vector<cv::Mat>{image, image, image}, colour);
  ASSERT_TRUE(cv::imencode(".png", colour, bytes));
  EXPECT_FALSE(DecodePlainGreyPng(std::string(bytes.begin(), bytes.end()), &decoded));
  cv::Mat deep;
  image.convertTo(deep, CV_16U, 257.0);
  ASSERT_TRUE(cv::imencode(".png", deep, bytes));
  EXPECT_FALSE(DecodePlainGreyPng(std::string(bytes.begin(), bytes.end()), &decoded));

  std::string png = MakePng(image, paeth);
  EXPECT_FALSE(DecodePlainGreyPng(png.substr(0, png.size() - 20), &decoded));  // truncated
  png[png.size() - 30] ^= 0x55;  // the compressed data damaged: its check fails
  EXPECT_FALSE(DecodePlainGreyPng(png, &decoded));
  EXPECT_FALSE(DecodePlainGreyPng("", &decoded));
  EXPECT_FALSE(DecodePlainGreyPng("not a png at all, just text", &decoded));
}

}  // namespace
}  // namespace omni
