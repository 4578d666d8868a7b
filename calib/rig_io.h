#pragma once
// rig.json (docs/design.md §5) reading with validation, and writing.

#include <filesystem>
#include <string>

#include "calib/rig.h"

namespace omni {

// Throws InputError naming the file, the field and what was expected.
Rig ReadRigJson(const std::filesystem::path& path);
// `source` names the text in error messages.
Rig ParseRigJson(const std::string& text, const std::filesystem::path& source);
std::string RigToJson(const Rig& rig);
// Written atomically (name.tmp, then rename).
void WriteRigJson(const Rig& rig, const std::filesystem::path& path);

}  // namespace omni
