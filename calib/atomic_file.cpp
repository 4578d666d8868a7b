#include "calib/atomic_file.h"

#include <cerrno>
#include <cstring>
#include <fstream>
#include <system_error>

#include "calib/error.h"

namespace omni {
namespace {

std::string ErrnoText(int error_number) {
  return error_number != 0 ? std::strerror(error_number) : "unknown error";
}

}  // namespace

void WriteFileAtomically(const std::filesystem::path& path,
                         const std::function<void(std::ostream&)>& write, bool binary) {
  std::filesystem::path tmp_path = path;
  tmp_path += ".tmp";
  auto fail = [&](const std::string& reason) {
    std::error_code ignored;
    std::filesystem::remove(tmp_path, ignored);
    throw InputError(path, "", "cannot write: " + reason);
  };

  {
    errno = 0;
    std::ofstream stream(tmp_path, binary ? std::ios::out | std::ios::binary | std::ios::trunc
                                          : std::ios::out | std::ios::trunc);
    if (!stream) fail(ErrnoText(errno));
    try {
      write(stream);
    } catch (...) {
      stream.close();
      std::error_code ignored;
      std::filesystem::remove(tmp_path, ignored);
      throw;
    }
    errno = 0;
    stream.flush();
    if (!stream) fail(ErrnoText(errno));
    stream.close();
    if (stream.fail()) fail(ErrnoText(errno));
  }

  std::error_code error;
  std::filesystem::rename(tmp_path, path, error);
  if (error) fail(error.message());
}

void WriteTextFileAtomically(const std::filesystem::path& path, const std::string& text) {
  WriteFileAtomically(path, [&](std::ostream& stream) { stream << text; });
}

}  // namespace omni
