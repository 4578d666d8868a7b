#include "apps/cli.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "apps/commands.h"
#include "calib/error.h"

namespace omni {

int& CommandExitCode() {
  static int exit_code = 0;
  return exit_code;
}

void ReportNotUsable(const std::string& message) {
  std::fprintf(stderr, "omnisculpt: error: %s\n", message.c_str());
  CommandExitCode() = kExitNotUsable;
}

int RunCommandLine(int argc, char** argv) {
  CLI::App app{
      "omnisculpt: camera poses, sparse points and a 2-manifold surface of a city from the "
      "images of an omnidirectional multi-camera rig, with synthetic drives and evaluation."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "omnisculpt 0.1.0");
  GlobalOptions global;
  app.add_flag("-q,--quiet", global.quiet, "Print warnings and errors only");
  app.add_flag("-v,--verbose", global.verbose, "Print debug messages");
  // The global flags are accepted after the subcommand too (`omnisculpt surface ... --quiet`):
  // subcommands created below inherit this and pass options they do not know to the parent.
  app.fallthrough();

  RegisterCalibCommands(app, global);
  RegisterSynthCommand(app, global);
  RegisterSfmCommand(app, global);
  RegisterSurfaceCommand(app, global);
  RegisterEvalCommands(app, global);
  RegisterReconstructCommand(app, global);
  RegisterViewCommand(app, global);
  RegisterExportCommand(app, global);

  app.parse_complete_callback([&global] {
    spdlog::set_pattern("%^[%L]%$ %v");
    spdlog::set_level(global.quiet     ? spdlog::level::warn
                      : global.verbose ? spdlog::level::debug
                                       : spdlog::level::info);
  });

  CommandExitCode() = 0;
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& success) {
    return app.exit(success);  // --help, --version
  } catch (const CLI::ParseError& error) {
    // One line, like every other bad input (CLI11's own exit() prints two). CLI11 checks for a
    // missing subcommand before it checks for unknown arguments: name those first.
    std::string message = error.what();
    const std::vector<std::string> unknown = app.remaining();
    if (!unknown.empty()) {
      message = "unknown argument" + std::string(unknown.size() > 1 ? "s" : "") + ":";
      for (const std::string& argument : unknown) message += " " + argument;
    }
    std::fprintf(stderr, "omnisculpt: error: %s (see --help)\n", message.c_str());
    return 2;
  } catch (const OptionsError& error) {
    std::fprintf(stderr, "omnisculpt: error: invalid options: %s\n", error.what());
    return 2;
  } catch (const InputError& error) {
    std::fprintf(stderr, "omnisculpt: error: %s\n", error.what());
    return 2;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "omnisculpt: internal error: %s\n", error.what());
    return 1;
  }
  return CommandExitCode();
}

}  // namespace omni
