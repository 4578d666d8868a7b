// Kalibr camchain.yaml import (calib/import.h).
#include "calib/import.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = omni::fuzz::AsText(data, size);
  return omni::fuzz::ParseOrRefuse([&] { omni::ParseKalibr(text, "camchain.yaml"); });
}
