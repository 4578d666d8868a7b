#pragma once
// Errors in user input (files, options). A programming error is an assertion instead (see
// docs/design.md, "Checks"). apps/ catches InputError and OptionsError and turns each into one
// line and exit code 2.

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

// Options that fail their Check(): what() reads "<Struct>.<field>: <problem>", e.g.
// "TrackerOptions.keyframes.min_tracked_share: expected a share in (0, 1]". Thrown by the
// libraries' constructors and functions in every build type (an assert would vanish in Release).
class OptionsError : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Throws OptionsError("<options_name>.<problem>") unless `problem` (the result of an options
// struct's Check()) is empty.
void ThrowIfInvalid(const std::string& problem, const char* options_name);

// `options`, once ThrowIfInvalid(options.Check(), options_name) has passed: for a member
// initialiser list, so that no member is built from bad options.
template <typename Options>
const Options& CheckedOptions(const Options& options, const char* options_name) {
  ThrowIfInvalid(options.Check(), options_name);
  return options;
}

}  // namespace omni
