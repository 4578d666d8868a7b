#include "apps/cli.h"

#include <spdlog/sinks/sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <exception>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "apps/commands.h"
#include "calib/error.h"

namespace omni {
namespace {

std::mutex& WarningsMutex() {
  static std::mutex mutex;
  return mutex;
}

std::vector<std::string>& Warnings() {
  static std::vector<std::string> warnings;
  return warnings;
}

// The command line's log: progress (info, debug) on stdout; warnings and errors on stderr,
// each also kept for the run's JSON summary (WarningsLogged()).
class SplitSink : public spdlog::sinks::sink {
 public:
  void log(const spdlog::details::log_msg& message) override {
    if (message.level >= spdlog::level::warn) {
      {
        std::lock_guard<std::mutex> lock(WarningsMutex());
        Warnings().emplace_back(message.payload.data(), message.payload.size());
      }
      std::fflush(stdout);  // keep the order of the two streams on a terminal
      err_.log(message);
    } else {
      out_.log(message);
    }
  }
  void flush() override {
    out_.flush();
    err_.flush();
  }
  void set_pattern(const std::string& pattern) override {
    out_.set_pattern(pattern);
    err_.set_pattern(pattern);
  }
  void set_formatter(std::unique_ptr<spdlog::formatter> formatter) override {
    out_.set_formatter(formatter->clone());
    err_.set_formatter(std::move(formatter));
  }

 private:
  spdlog::sinks::stdout_color_sink_mt out_;
  spdlog::sinks::stderr_color_sink_mt err_;
};

}  // namespace

std::vector<std::string> WarningsLogged() {
  std::lock_guard<std::mutex> lock(WarningsMutex());
  return Warnings();
}

int& CommandExitCode() {
  static int exit_code = 0;
  return exit_code;
}

void ReportNotUsable(const std::string& message) {
  std::fprintf(stderr, "omnisculpt: error: %s\n", message.c_str());
  CommandExitCode() = kExitNotUsable;
}

bool ReportSurfaceChecks(const std::string& command, const MeshCheckReport& closed,
                         const MeshCheckReport& observed) {
  if (!closed.ok) {
    spdlog::error("{}: δO is not a closed oriented 2-manifold: {}", command, closed.Summary());
  } else if (!observed.ok) {
    spdlog::error("{}: the observed surface is not an oriented 2-manifold with boundary: {}",
                  command, observed.Summary());
  } else {
    return true;
  }
  CommandExitCode() = kExitCheckFailed;
  return false;
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
  RegisterMergeCommand(app, global);
  RegisterViewCommand(app, global);
  RegisterExportCommand(app, global);

  spdlog::set_default_logger(
      std::make_shared<spdlog::logger>("omnisculpt", std::make_shared<SplitSink>()));
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
  } catch (const std::filesystem::filesystem_error& error) {
    // The machine refused a file operation (permissions, a full disk, a read-only file system):
    // not a bug of the program, so reported as bad input naming the path.
    std::string message = error.path1().string();
    if (!error.path2().empty()) message += " -> " + error.path2().string();
    std::fprintf(stderr, "omnisculpt: error: %s: %s\n", message.c_str(),
                 error.code().message().c_str());
    return 2;
  } catch (const std::exception& error) {
    std::fprintf(stderr, "omnisculpt: internal error: %s\n", error.what());
    return 1;
  }
  return CommandExitCode();
}

}  // namespace omni
