// `omnisculpt view OUT [--serve [--port P]]`: writes the offline web viewer of a reconstruction
// into OUT/viewer/ (export/viewer_bundle.h) and, with --serve, serves it on 127.0.0.1
// (export/local_server.h) until stopped.

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include "apps/commands.h"
#include "calib/error.h"
#include "export/local_server.h"
#include "export/viewer_bundle.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

struct ViewCommandOptions {
  std::string reconstruction;
  bool serve = false;
  LocalServerOptions server;
  ViewerOptions viewer;
};

// The page and three.js: OMNISCULPT_VIEWER_ASSETS, else viewer_assets/ beside the executable
// (where the build puts them).
fs::path ViewerAssets() {
  if (const char* assets = std::getenv("OMNISCULPT_VIEWER_ASSETS"); assets && *assets)
    return assets;
  std::error_code error;
  const fs::path executable = fs::read_symlink("/proc/self/exe", error);
  return error ? fs::path("viewer_assets") : executable.parent_path() / "viewer_assets";
}

void RunView(ViewCommandOptions o, const GlobalOptions& global) {
  o.viewer.assets = ViewerAssets();
  // The port is checked before anything is written.
  std::unique_ptr<LocalServer> server;
  const fs::path out = fs::path(o.reconstruction) / "viewer";
  if (o.serve) server = std::make_unique<LocalServer>(out, o.server);
  const ViewerSummary summary = WriteViewer(o.reconstruction, o.viewer);
  if (!global.quiet)
    spdlog::info(
        "view: {} keyframes ({} cameras each), {} points, {} triangles, {} snapshots, {} loop "
        "closures; {:.1f} MB of data",
        summary.keyframes, summary.cameras, summary.points, summary.triangles, summary.snapshots,
        summary.loops, summary.bytes / 1e6);
  if (!server) {
    std::printf("wrote %s (open it in a browser; it works offline from the file system)\n",
                summary.index.string().c_str());
    return;
  }
  std::printf("serving %s at %s (Ctrl-C stops)\n", out.string().c_str(), server->Url().c_str());
  std::fflush(stdout);
  server->Serve();
}

}  // namespace

void RegisterViewCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<ViewCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "view",
      "Write the web viewer of a reconstruction into OUT/viewer/ (index.html: the surface, the "
      "points, the trajectory and loop closures, the per-keyframe times, the playback of "
      "--snapshot-every snapshots); it works offline from the file system");
  command->add_option("OUT", o->reconstruction, "A reconstruction folder (reconstruct, surface)")
      ->required();
  command->add_flag("--serve", o->serve,
                    "Also serve OUT/viewer/ on 127.0.0.1 and print the address (until stopped)");
  command->add_option("--port", o->server.port, "The port of --serve (0: any free port)")
      ->capture_default_str();
  command->callback([o, &global] { RunView(*o, global); });
}

}  // namespace omni
