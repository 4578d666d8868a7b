#include "calib/error.h"

namespace omni {
namespace {

std::string FormatInputError(const std::filesystem::path& file, const std::string& field,
                             const std::string& problem) {
  std::string message;
  if (!file.empty()) message += file.string() + ": ";
  if (!field.empty()) message += field + ": ";
  message += problem;
  return message;
}

}  // namespace

InputError::InputError(const std::filesystem::path& file, const std::string& field,
                       const std::string& problem)
    : std::runtime_error(FormatInputError(file, field, problem)), file_(file), field_(field) {}

InputError::InputError(const std::string& problem) : std::runtime_error(problem) {}

void ThrowIfInvalid(const std::string& problem, const char* options_name) {
  if (problem.empty()) return;
  throw OptionsError(std::string(options_name) + "." + problem);
}

}  // namespace omni
