#pragma once
// The subcommands of `omnisculpt`, one registration function each (COLMAP's exe/colmap.cc
// habit: a table of subcommands, each a thin layer over the libraries). A registration adds
// its subcommand(s) to the app and sets the callback that runs it; the callback throws
// InputError on bad input and returns through CommandResult.

#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "calib/mesh_check.h"

namespace omni {

struct SculptorOptions;
struct ObservedMeshOptions;
enum class EnclosingMode;

// Options every subcommand shares.
struct GlobalOptions {
  bool quiet = false;    // no progress, warnings and errors only
  bool verbose = false;  // debug logging
};

// Exit code of the subcommand that ran (0 unless it set one: e.g. mesh-check of a
// non-manifold mesh sets 1).
int& CommandExitCode();

// The exit codes: 0 success; 1 a check that failed (mesh-check of a non-manifold mesh) or an
// internal error; 2 bad input or bad options (one line on stderr naming the file, the field
// and the problem); 3 the run ended without a usable result (the SfM did not initialise or
// lost tracking for good, or the surface is empty), its outputs saying what happened.
constexpr int kExitCheckFailed = 1;
constexpr int kExitBadInput = 2;
constexpr int kExitNotUsable = 3;

// One line on stderr ("omnisculpt: error: <message>") and exit code kExitNotUsable.
void ReportNotUsable(const std::string& message);
// The manifold checks of a command's two surfaces: when δO (`closed`) is not a closed oriented
// 2-manifold, or else the observed surface not one with boundary, one error line naming
// `command` and exit code kExitCheckFailed. Returns true when both hold.
bool ReportSurfaceChecks(const std::string& command, const MeshCheckReport& closed,
                         const MeshCheckReport& observed);

// The warnings logged so far in this process (spdlog warn and error; they went to stderr), for
// the run's JSON summary.
std::vector<std::string> WarningsLogged();

void RegisterCalibCommands(CLI::App& app, const GlobalOptions& global);
void RegisterSynthCommand(CLI::App& app, const GlobalOptions& global);
void RegisterEvalCommands(CLI::App& app, const GlobalOptions& global);
void RegisterSurfaceCommand(CLI::App& app, const GlobalOptions& global);
void RegisterSfmCommand(CLI::App& app, const GlobalOptions& global);
void RegisterReconstructCommand(CLI::App& app, const GlobalOptions& global);
void RegisterMergeCommand(CLI::App& app, const GlobalOptions& global);
void RegisterViewCommand(CLI::App& app, const GlobalOptions& global);
void RegisterExportCommand(CLI::App& app, const GlobalOptions& global);

// The enclosing-set options of the surface that `surface` and `reconstruct` both take
// (--enclosing ball|conflict and the tuning of conflict), registered on `command`;
// ApplyEnclosingOption sets sculptor->enclosing from the --enclosing value (InputError if bad).
void AddEnclosingOptions(CLI::App* command, std::string* enclosing, SculptorOptions* sculptor);
// The carving options beyond the paper (SculptorOptions::enclosed_free_neighbours).
void AddCarvingOptions(CLI::App* command, SculptorOptions* sculptor);
void ApplyEnclosingOption(const std::string& enclosing, SculptorOptions* sculptor);
// The options of the observed surface, surface.ply (ObservedMeshOptions), shared by surface and
// reconstruct.
void AddObservedMeshOptions(CLI::App* command, ObservedMeshOptions* observed);
// The --enclosing value of a mode ("ball" or "conflict").
std::string EnclosingName(EnclosingMode mode);

}  // namespace omni
