#pragma once
// The short synthetic drive of the end-to-end tests (`synth --preset short`): made once per
// build folder by the CTest fixture short_drive (test make_short_drive, tests/CMakeLists.txt)
// into OMNI_SHORT_DRIVE_DIR; tests whose name contains "ShortDrive" require that fixture. When a
// test binary is run directly and the drive is missing, ShortDrive() makes it.

#include <filesystem>
#include <string>

#include "tests/apps/run_omnisculpt.h"

namespace omni::testing {

// The folder of the short drive, made if missing; empty (with *error set) when making it failed.
inline std::filesystem::path ShortDrive(std::string* error) {
  const std::filesystem::path drive(OMNI_SHORT_DRIVE_DIR);
  if (std::filesystem::exists(drive / "gt" / "poses.tum")) return drive;
  const std::filesystem::path scratch = drive.parent_path() / "short_drive_log";
  std::filesystem::create_directories(scratch);
  const CommandResult made = RunOmnisculpt(
      {"--quiet", "synth", "--preset", "short", "--out", drive.string(), "--force"}, scratch);
  if (made.exit_code != 0) {
    *error = "synth --preset short failed: " + made.err;
    return {};
  }
  return drive;
}

}  // namespace omni::testing
