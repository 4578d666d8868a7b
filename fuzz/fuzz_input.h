#pragma once
// What every parser harness shares: the input as a string, and the rule that a parser may only
// answer bad input with InputError (calib/error.h). Any other exception escapes libFuzzer's
// entry point and aborts the run, as a crash, a leak, a sanitizer report or a hang do.

#include <cstddef>
#include <cstdint>
#include <string>

#include "calib/error.h"

namespace omni::fuzz {

inline std::string AsText(const uint8_t* data, size_t size) {
  return std::string(reinterpret_cast<const char*>(data), size);
}

// Runs `parse` on the input; InputError is the expected answer to bad input.
template <typename Parse>
int ParseOrRefuse(Parse parse) {
  try {
    parse();
  } catch (const InputError&) {
  }
  return 0;
}

}  // namespace omni::fuzz
