#pragma once
// Helpers of the end-to-end tests that run `omnisculpt sfm` and `reconstruct`: a fresh scratch
// folder in the build tree, and the keyframes' error against a drive's ground truth.

#include <filesystem>
#include <string>

#include "calib/tum.h"
#include "eval/pose_eval.h"

namespace omni::testing {

// build/test_scratch/<group>/<name>, emptied and made.
inline std::filesystem::path ScratchDir(const std::string& group, const std::string& name) {
  const std::filesystem::path dir =
      std::filesystem::path(OMNI_BINARY_DIR) / "test_scratch" / group / name;
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// RMS distance of the keyframe centres of rec/poses.tum to drive/gt/poses.tum after the
// similarity registration (metres).
inline double PoseRms(const std::filesystem::path& rec, const std::filesystem::path& drive) {
  return EvaluatePoses(ReadTum(rec / "poses.tum"), ReadTum(drive / "gt" / "poses.tum"))
      .registration_rms;
}

}  // namespace omni::testing
