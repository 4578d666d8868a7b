// The check of an image file's bytes before decoding (calib/drive.h ImageFileProblem): the PNG
// chunk walk with its CRCs, the JPEG marker walk. (The decoders behind it are OpenCV's.)
#include "calib/drive.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  omni::ImageFileProblem(omni::fuzz::AsText(data, size));
  return 0;
}
