#pragma once
// The --out folder of a command that writes several files into it (docs/design.md §4, "Output
// folders"): nothing of the user's is overwritten without --force, --force replaces only what
// the command itself wrote, and a run that fails leaves nothing behind.

#include <filesystem>
#include <string>

namespace omni {

class OutputFolder {
 public:
  // Takes `folder` as the output of `command` (e.g. "eval"): a new or empty folder is used; a
  // non-empty one is refused unless `force` is given and it holds `own_file` (relative to the
  // folder), the file the command writes last, which marks a folder as its own earlier output.
  // A path that is not a folder, or a folder that cannot be created or written (read-only, no
  // permission), is refused. Every refusal is an InputError naming the folder and "--out".
  // Creates the folder (and its parents) when missing.
  OutputFolder(const std::filesystem::path& folder, const std::string& own_file, bool force,
               const std::string& command);
  // A run that did not call Keep() (it threw) leaves nothing behind: the folder is removed if
  // this object created it, emptied again if it was empty; an earlier output replaced with
  // --force stays as the failed run left it.
  ~OutputFolder();
  OutputFolder(const OutputFolder&) = delete;
  OutputFolder& operator=(const OutputFolder&) = delete;

  const std::filesystem::path& path() const { return folder_; }
  // The run succeeded (or ended with a result that says why it is not usable): keep the files.
  void Keep() { keep_ = true; }

 private:
  std::filesystem::path folder_;
  std::filesystem::path created_;  // the topmost folder this object created; empty if none
  bool was_empty_ = false;         // the folder existed and was empty
  bool keep_ = false;
};

// Refuses (InputError naming `file` and `option`) to replace an existing file given on the
// command line unless `force`; checks that the file's folder exists and is writable.
void CheckOutputFile(const std::filesystem::path& file, bool force, const std::string& option);

// Why no file can be created in `folder` (the system's reason), or "" when one can.
std::string FolderWriteProblem(const std::filesystem::path& folder);
// An InputError naming `folder` and `option` unless a file can be created in `folder`.
void CheckFolderWritable(const std::filesystem::path& folder, const std::string& option);

}  // namespace omni
