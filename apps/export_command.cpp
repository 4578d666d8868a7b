// `omnisculpt export OUT --format glb|ply|obj [--closed]`: the surface of a reconstruction
// (surface.ply, or surface_closed.ply with --closed) as a file for other programs
// (export/gltf.h); the .glb also holds the SfM points (points.ply) as a second mesh of points.

#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "apps/commands.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "export/gltf.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

struct ExportCommandOptions {
  std::string reconstruction;
  std::string format = "glb";
  std::string out;  // default OUT/export/surface[_closed].<format>
  bool closed = false;
  bool no_points = false;
  bool force = false;
};

void RunExport(const ExportCommandOptions& o, const GlobalOptions& global) {
  if (o.format != "glb" && o.format != "ply" && o.format != "obj")
    throw InputError("", "--format", "expected glb, ply or obj, got '" + o.format + "'");
  const fs::path folder(o.reconstruction);
  const std::string stem = o.closed ? "surface_closed" : "surface";
  const fs::path source = folder / (stem + ".ply");
  const fs::path target =
      o.out.empty() ? folder / "export" / (stem + "." + o.format) : fs::path(o.out);
  if (fs::exists(target) && !o.force)
    throw InputError(target, "--out", "exists (--force replaces it)");
  const TriangleMesh mesh = ReadPlyMesh(source);
  if (mesh.triangles.empty()) throw InputError(source, "", "holds no triangle");
  PointCloud points;
  if (o.format == "glb" && !o.no_points && fs::exists(folder / "points.ply"))
    points = ReadPlyPoints(folder / "points.ply");
  if (!target.parent_path().empty()) fs::create_directories(target.parent_path());
  if (o.format == "glb")
    WriteGlb(mesh, points, target);
  else if (o.format == "obj")
    WriteObj(mesh, target);
  else
    WritePlyMesh(mesh, target);
  if (!global.quiet)
    spdlog::info(
        "export: {} vertices, {} triangles{} from {}", mesh.vertices.size(), mesh.triangles.size(),
        points.points.empty() ? "" : ", " + std::to_string(points.points.size()) + " points",
        source.string());
  std::printf("wrote %s\n", target.string().c_str());
}

}  // namespace

void RegisterExportCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<ExportCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "export",
      "Write the surface of a reconstruction for other programs: binary glTF 2.0 (vertex "
      "colours, the SfM points as a second mesh of points), PLY or OBJ");
  command->add_option("OUT", o->reconstruction, "A reconstruction folder (reconstruct, surface)")
      ->required();
  command->add_option("--format", o->format, "glb, ply or obj")->capture_default_str();
  command->add_flag("--closed", o->closed,
                    "surface_closed.ply (the closed 2-manifold) instead of surface.ply");
  command->add_option("--out", o->out, "The file (default OUT/export/surface[_closed].FORMAT)");
  command->add_flag("--no-points", o->no_points, "glb: leave the SfM points out");
  command->add_flag("--force", o->force, "Replace the file if it exists");
  command->callback([o, &global] { RunExport(*o, global); });
}

}  // namespace omni
