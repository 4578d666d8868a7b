// frames.csv of a drive (calib/drive.h), for a drive of frames 0 to 3.
#include "calib/drive.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const std::vector<std::string> kFrames = {"0", "1", "2", "3"};
  const std::string text = omni::fuzz::AsText(data, size);
  return omni::fuzz::ParseOrRefuse(
      [&] { omni::ParseFrameTimestamps(text, "frames.csv", kFrames); });
}
