#pragma once
// Reading a file the user gave, whole, before parsing it from memory (every reader of calib/ has
// a Parse… on text that the fuzzers of fuzz/ call).

#include <filesystem>
#include <string>

namespace omni {

// The bytes of `path`. Throws InputError naming it: "cannot open" (missing, no permission), "is a
// folder, not a file", "cannot read".
std::string ReadInputFile(const std::filesystem::path& path);

}  // namespace omni
