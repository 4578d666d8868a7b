// `omnisculpt synth` on the command line: one-line errors for a bad preset or output.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

fs::path TempFolder(const std::string& name) {
  const fs::path path =
      fs::temp_directory_path() / ("omni_synth_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(path);
  return path;
}

using testing::CommandResult;
using testing::RunOmnisculpt;

int CountLines(const std::string& text) {
  return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
}

TEST(SynthCommandTest, BadPresetAndUnwritableOutputAreOneLineErrors) {
  const fs::path folder = TempFolder("cli");
  fs::create_directories(folder);
  CommandResult result =
      RunOmnisculpt({"synth", "--preset", "nope", "--out", (folder / "d").string()}, folder);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(CountLines(result.err), 1) << result.err;
  EXPECT_NE(result.err.find("tiny, demo, paper"), std::string::npos) << result.err;
  EXPECT_FALSE(fs::exists(folder / "d"));

  std::ofstream(folder / "file") << "a file, not a folder";
  result = RunOmnisculpt(
      {"synth", "--preset", "tiny", "--frames", "2", "--out", (folder / "file" / "drive").string()},
      folder);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(CountLines(result.err), 1) << result.err;
  EXPECT_NE(result.err.find("--out"), std::string::npos) << result.err;

  result = RunOmnisculpt({"synth", "--list-presets"}, folder);
  EXPECT_EQ(result.exit_code, 0);
  fs::remove_all(folder);
}

}  // namespace
}  // namespace omni
