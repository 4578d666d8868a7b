#pragma once
// TUM trajectories: one pose per line, "timestamp tx ty tz qx qy qz qw", '#' comments.
// Each pose is world_from_rig (the rig's position and orientation in the world).

#include <filesystem>
#include <string>
#include <vector>

#include "calib/pose.h"

namespace omni {

struct StampedPose {
  double timestamp = 0.0;
  Rigid3d world_from_rig;
};

// Throws InputError naming the file and line on malformed input: a line that is not eight
// finite decimal numbers (no hexadecimal, inf or nan), a quaternion not of unit norm (within
// 1e-3), a timestamp not after the one before (timestamps increase strictly).
std::vector<StampedPose> ReadTum(const std::filesystem::path& path);
// The same on text in memory; `source` names it in the errors.
std::vector<StampedPose> ParseTum(const std::string& text, const std::filesystem::path& source);
// Written atomically, with enough digits to round-trip to 1e-9.
void WriteTum(const std::vector<StampedPose>& poses, const std::filesystem::path& path);

}  // namespace omni
