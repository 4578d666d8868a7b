// The check of an image file's bytes before decoding (calib/drive.h ImageFileProblem): the PNG
// chunk walk with its CRCs, the JPEG marker walk; and the plain grey PNG decoder
// (calib/png_grey.h; the other decoders are OpenCV's).
#include "calib/drive.h"
#include "calib/png_grey.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = omni::fuzz::AsText(data, size);
  omni::ImageFileProblem(text);
  cv::Mat image;
  omni::DecodePlainGreyPng(text, &image);
  return 0;
}
