#pragma once
// A fast decoder for the plain PNGs a drive's grey cameras write: 8-bit grey, not interlaced,
// no chunk that would change the decoded pixels (only IHDR, IDAT, IEND and descriptive
// ancillary chunks: text, time, physical size, colour space). The image data is inflated by
// libdeflate and unfiltered here, about twice as fast as OpenCV's libpng path, with the same
// pixels (PNG is lossless). Anything else is left to cv::imdecode.

#include <opencv2/core.hpp>
#include <string>

namespace omni {

// Decodes `data` (a whole PNG file) into *image (CV_8UC1) when it is such a plain grey PNG
// whose data inflates and unfilters without error; false otherwise (*image then undefined):
// the caller decodes it with cv::imdecode, which also gives its errors.
bool DecodePlainGreyPng(const std::string& data, cv::Mat* image);

}  // namespace omni
