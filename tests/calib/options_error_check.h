#pragma once
// EXPECT_TRUE(ThrowsOptionsError([&] { ... }, "TrackerOptions.keyframes.min_tracked_share")):
// the call throws an OptionsError (calib/error.h) whose message contains `expected` (the struct
// and the field it names).

#include <gtest/gtest.h>

#include <exception>
#include <string>

#include "calib/error.h"

namespace omni::testing {

template <typename Call>
::testing::AssertionResult ThrowsOptionsError(const Call& call, const std::string& expected) {
  try {
    call();
  } catch (const OptionsError& error) {
    const std::string message = error.what();
    if (message.find(expected) != std::string::npos) return ::testing::AssertionSuccess();
    return ::testing::AssertionFailure()
           << "OptionsError \"" << message << "\" does not name \"" << expected << "\"";
  } catch (const std::exception& error) {
    return ::testing::AssertionFailure() << "threw another exception: " << error.what();
  }
  return ::testing::AssertionFailure() << "threw nothing (expected \"" << expected << "\")";
}

}  // namespace omni::testing
