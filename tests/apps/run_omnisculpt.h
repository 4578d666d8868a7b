#pragma once
// Running the built `omnisculpt` (OMNI_EXECUTABLE) from a test, as a user would: arguments
// quoted for the shell, stdout and stderr captured through files in a scratch folder.

#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace omni::testing {

struct CommandResult {
  int exit_code = -1;  // -1 when the process did not exit normally
  std::string out;
  std::string err;
};

inline std::string ReadTextFile(const std::filesystem::path& path) {
  std::ifstream stream(path, std::ios::binary);
  std::ostringstream text;
  text << stream.rdbuf();
  return text.str();
}

// Splits on `separator`; a trailing separator makes no empty last part.
inline std::vector<std::string> SplitText(const std::string& text, char separator = '\n') {
  std::vector<std::string> parts;
  std::istringstream stream(text);
  std::string part;
  while (std::getline(stream, part, separator)) parts.push_back(part);
  return parts;
}

inline std::string ShellQuote(const std::string& argument) {
  std::string quoted = "'";
  for (char c : argument) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return quoted + "'";
}

// Runs omnisculpt with `arguments` (no shell interpretation of them), standard input empty;
// stdout.txt and stderr.txt are written in `scratch`, which must exist.
inline CommandResult RunOmnisculpt(const std::vector<std::string>& arguments,
                                   const std::filesystem::path& scratch) {
  std::string command = ShellQuote(OMNI_EXECUTABLE);
  for (const std::string& argument : arguments) command += " " + ShellQuote(argument);
  const std::filesystem::path out = scratch / "stdout.txt";
  const std::filesystem::path err = scratch / "stderr.txt";
  command += " >" + ShellQuote(out.string()) + " 2>" + ShellQuote(err.string()) + " </dev/null";
  const int status = std::system(command.c_str());
  CommandResult result;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result.out = ReadTextFile(out);
  result.err = ReadTextFile(err);
  return result;
}

}  // namespace omni::testing
