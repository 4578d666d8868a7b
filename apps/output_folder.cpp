#include "apps/output_folder.h"

#include <unistd.h>

#include <cerrno>
#include <fstream>
#include <system_error>
#include <vector>

#include "calib/error.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

bool IsEmptyFolder(const fs::path& folder) {
  std::error_code error;
  return fs::is_directory(folder, error) && fs::is_empty(folder, error) && !error;
}

}  // namespace

std::string FolderWriteProblem(const fs::path& folder) {
  // access(W_OK) answers for the real user; creating a file also catches a read-only file
  // system and an immutable folder, which root's permissions do not override.
  const fs::path probe = folder / (".omnisculpt-write-test-" + std::to_string(getpid()));
  int saved_errno = 0;
  {
    errno = 0;
    std::ofstream stream(probe);
    saved_errno = errno;
    if (stream) {
      stream.close();
      std::error_code ignored;
      fs::remove(probe, ignored);
      return "";
    }
  }
  return std::error_code(saved_errno, std::generic_category()).message();
}

void CheckFolderWritable(const fs::path& folder, const std::string& option) {
  const std::string problem = FolderWriteProblem(folder);
  if (!problem.empty()) {
    throw InputError(folder, option, "cannot write into the folder (" + problem + ")");
  }
}

OutputFolder::OutputFolder(const fs::path& folder, const std::string& own_file, bool force,
                           const std::string& command)
    : folder_(folder) {
  if (folder.empty()) throw InputError("", "--out", "an output folder is required");
  std::error_code error;
  const fs::file_status status = fs::status(folder, error);
  if (fs::exists(status) && !fs::is_directory(status)) {
    throw InputError(folder, "--out", "exists and is not a folder");
  }
  if (fs::is_directory(status)) {
    was_empty_ = IsEmptyFolder(folder);
    if (!was_empty_) {
      if (!force) {
        throw InputError(folder, "--out",
                         "exists and is not empty (give a new or empty folder; --force replaces "
                         "an earlier output of " +
                             command + ")");
      }
      if (!fs::exists(folder / own_file, error)) {
        throw InputError(folder, "--out",
                         "is not an earlier output of " + command + " (no " + own_file +
                             "): not replaced, even with --force");
      }
    }
  } else {
    // The topmost missing folder is the one to remove if the run fails.
    fs::path missing = folder;
    while (missing.has_parent_path() && missing.parent_path() != missing &&
           !fs::exists(missing.parent_path(), error)) {
      missing = missing.parent_path();
    }
    fs::create_directories(folder, error);
    if (error) {
      throw InputError(folder, "--out", "cannot create the folder (" + error.message() + ")");
    }
    created_ = missing;
  }
  CheckFolderWritable(folder, "--out");
}

OutputFolder::~OutputFolder() {
  if (keep_) return;
  std::error_code ignored;
  if (!created_.empty()) {
    fs::remove_all(created_, ignored);
  } else if (was_empty_) {
    std::vector<fs::path> written;
    for (fs::directory_iterator it(folder_, ignored), end; !ignored && it != end;
         it.increment(ignored)) {
      written.push_back(it->path());
    }
    for (const fs::path& path : written) fs::remove_all(path, ignored);
  }
}

void CheckOutputFile(const fs::path& file, bool force, const std::string& option) {
  std::error_code error;
  if (fs::is_directory(file, error)) throw InputError(file, option, "is a folder, not a file");
  if (fs::exists(file, error) && !force) {
    throw InputError(file, option, "exists already (--force replaces it)");
  }
  fs::path folder = file.parent_path();
  if (folder.empty()) folder = ".";
  if (!fs::is_directory(folder, error)) {
    throw InputError(file, option, "no folder " + folder.string() + " to write it in");
  }
  if (const std::string problem = FolderWriteProblem(folder); !problem.empty()) {
    throw InputError(file, option,
                     "cannot write into the folder " + folder.string() + " (" + problem + ")");
  }
}

}  // namespace omni
