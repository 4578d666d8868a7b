#include "calib/input_file.h"

#include <fstream>
#include <sstream>
#include <system_error>

#include "calib/error.h"

namespace omni {

std::string ReadInputFile(const std::filesystem::path& path) {
  std::error_code error;
  if (std::filesystem::is_directory(path, error)) {
    throw InputError(path, "", "is a folder, not a file");
  }
  std::ifstream stream(path, std::ios::binary);
  if (!stream) throw InputError(path, "", "cannot open");
  std::ostringstream bytes;
  bytes << stream.rdbuf();
  if (stream.bad()) throw InputError(path, "", "cannot read");
  return bytes.str();
}

}  // namespace omni
