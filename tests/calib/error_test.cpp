#include "calib/error.h"

#include <gtest/gtest.h>

#include <cstdio>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace omni {
namespace {

struct ToyOptions {
  int count = 1;
  std::string Check() const { return count >= 1 ? "" : "count: expected at least 1"; }
};

TEST(ThrowIfInvalid, AnEmptyProblemIsNoError) {
  EXPECT_NO_THROW(ThrowIfInvalid("", "ToyOptions"));
  const ToyOptions options;
  EXPECT_EQ(&CheckedOptions(options, "ToyOptions"), &options);
}

TEST(ThrowIfInvalid, TheMessageNamesTheStructAndTheField) {
  try {
    ThrowIfInvalid("keyframes.min_tracked_share: expected a value in (0, 1)", "TrackerOptions");
    FAIL() << "no OptionsError";
  } catch (const OptionsError& error) {
    EXPECT_STREQ(error.what(),
                 "TrackerOptions.keyframes.min_tracked_share: expected a value in (0, 1)");
  }
  ToyOptions bad;
  bad.count = 0;
  EXPECT_THROW(CheckedOptions(bad, "ToyOptions"), OptionsError);
}

// Bad options are a bad argument, not bad data: an std::invalid_argument, not an InputError.
static_assert(std::is_base_of_v<std::invalid_argument, OptionsError>);
static_assert(!std::is_base_of_v<InputError, OptionsError>);

// The option checks above are meant to hold in the build users run: the Release tests must be
// built as Release code is, with NDEBUG (asserts compiled out), or they would not show it.
TEST(BuildType, ReleaseTestsAreBuiltWithNdebug) {
#ifdef NDEBUG
  constexpr bool kNdebug = true;
#else
  constexpr bool kNdebug = false;
#endif
  const std::string build_type = OMNI_BUILD_TYPE;
  RecordProperty("build_type", build_type);
  if (build_type == "Release") {
    EXPECT_TRUE(kNdebug) << "a Release build without NDEBUG";
  } else {
    std::printf("note: build type \"%s\" (not Release), NDEBUG %s\n", build_type.c_str(),
                kNdebug ? "defined" : "not defined");
  }
}

}  // namespace
}  // namespace omni
