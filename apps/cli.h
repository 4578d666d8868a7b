#pragma once
// The `omnisculpt` command line: parses argv, runs the subcommand, maps failures to exit codes
// (0 success; 1 a check that failed, e.g. mesh-check of a non-manifold mesh; 2 bad input or bad
// options, with one line naming the file, the field and the problem).

namespace omni {

int RunCommandLine(int argc, char** argv);

}  // namespace omni
