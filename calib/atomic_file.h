#pragma once
// Writing files so that nothing half-written looks complete: the content goes to
// "<name>.tmp" and is renamed over <name> only when it was written whole (docs/design.md §4).

#include <filesystem>
#include <functional>
#include <ostream>
#include <string>

namespace omni {

// Calls write(stream) on a stream to "<path>.tmp" and renames it to path on success. Throws
// InputError naming the path if the file cannot be written; the .tmp file is removed then.
void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write, bool binary = false);

void WriteTextFileAtomically(const std::filesystem::path& path, const std::string& text);

}  // namespace omni
