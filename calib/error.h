#pragma once
// Errors in user input (files, options). A programming error is an assertion instead; see
// DESIGN.md §3 "Errors". apps/ catches InputError and turns it into one line and exit code 2.

#include <filesystem>
#include <stdexcept>
#include <string>

namespace omni {

class InputError : public std::runtime_error {
 public:
  // what() reads "<file>: <field>: <problem>", leaving out the parts that are empty.
  InputError(const std::filesystem::path& file, const std::string& field,
             const std::string& problem);
  explicit InputError(const std::string& problem);

  const std::filesystem::path& file() const { return file_; }
  const std::string& field() const { return field_; }

 private:
  std::filesystem::path file_;
  std::string field_;
};

}  // namespace omni
