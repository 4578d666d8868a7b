// Ladybug .conf import (calib/import.h), native and upright.
#include "calib/import.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = omni::fuzz::AsText(data, size);
  omni::LadybugImportOptions upright;
  upright.upright = true;
  omni::fuzz::ParseOrRefuse([&] { omni::ParseLadybug(text, "ladybug.conf"); });
  return omni::fuzz::ParseOrRefuse([&] { omni::ParseLadybug(text, "ladybug.conf", upright); });
}
