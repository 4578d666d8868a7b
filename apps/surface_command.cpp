// `omnisculpt surface` (issue 6): the incremental sculptor of surface/ fed by a simulated
// perfect SfM on a drive's ground truth (--from-gt), writing surface.ply and
// stats/keyframes.csv.

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>

#include "apps/commands.h"
#include "apps/surface/gt_keyframes.h"
#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "surface/manifold_check.h"
#include "surface/sculptor.h"

namespace omni {
namespace {

struct SurfaceCommandOptions {
  std::string from_gt;
  std::string out;
  std::string enclosing = "ball";
  bool no_batch = false;
  GtKeyframeOptions gt;
  SculptorOptions sculptor;
};

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

void RunSurface(SurfaceCommandOptions& o, const GlobalOptions& global) {
  if (o.from_gt.empty()) throw InputError("", "--from-gt", "a drive with gt/ is required");
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  if (o.enclosing == "ball") {
    o.sculptor.enclosing = EnclosingMode::kBall;
  } else if (o.enclosing == "conflict") {
    o.sculptor.enclosing = EnclosingMode::kConflictZones;
  } else {
    throw InputError("", "--enclosing", "expected ball or conflict, got '" + o.enclosing + "'");
  }
  o.sculptor.batch_init = !o.no_batch;
  for (const std::string& problem : {o.sculptor.Check(), o.gt.Check()}) {
    if (!problem.empty()) throw InputError("", "options", problem);
  }
  const auto start = std::chrono::steady_clock::now();
  const std::vector<SurfaceKeyframe> stream = LoadGtKeyframes(o.from_gt, o.gt);
  const double gen_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  size_t num_points = 0;
  for (const auto& kf : stream) num_points += kf.points.size();
  spdlog::info("surface: {} keyframes, {} points from the ground truth of {} ({:.1f} s)",
               stream.size(), num_points, o.from_gt, gen_s);

  IncrementalSculptor sculptor(o.sculptor);
  std::vector<KeyframeStats> stats;
  for (size_t i = 0; i < stream.size(); ++i) {
    for (const KeyframeStats& st : sculptor.AddKeyframe(stream[i])) stats.push_back(st);
    if (!global.quiet && (i + 1) % 50 == 0) {
      spdlog::info("surface: keyframe {}/{}", i + 1, stream.size());
    }
  }
  for (const KeyframeStats& st : sculptor.Finish()) stats.push_back(st);

  const std::filesystem::path out(o.out);
  std::filesystem::create_directories(out / "stats");
  const TriangleMesh mesh = sculptor.ExtractMesh();
  WritePlyMesh(mesh, out / "surface.ply");
  std::ostringstream csv;
  csv << KeyframeStatsCsvHeader() << "\n";
  for (const KeyframeStats& st : stats) csv << KeyframeStatsCsvRow(st) << "\n";
  WriteTextFileAtomically(out / "stats" / "keyframes.csv", csv.str());

  std::vector<double> ms;
  size_t max_e = 0, added = 0, rejected = 0;
  for (const KeyframeStats& st : stats) {
    if (!st.batch) ms.push_back(st.ms_total);
    max_e = std::max(max_e, st.cells_e);
    added += st.points_added;
    rejected += st.points_rejected;
  }
  const ManifoldReport report = CheckManifold(mesh);
  std::printf(
      "surface: %zu keyframes, %zu points added, %zu rejected (%.2f%%), %zu triangles, "
      "manifold %s\n"
      "  ms per incremental keyframe: median %.1f, p95 %.1f, max %.1f; max |E| %zu\n"
      "  wrote %s and %s\n",
      stream.size(), added, rejected, 100.0 * rejected / std::max<size_t>(1, added + rejected),
      mesh.triangles.size(), report.IsOrientedManifold() ? "yes" : "NO", Quantile(ms, 0.5),
      Quantile(ms, 0.95), ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end()), max_e,
      (out / "surface.ply").c_str(), (out / "stats" / "keyframes.csv").c_str());
  if (!report.IsOrientedManifold()) {
    spdlog::error("surface: the output is not an oriented 2-manifold: {}", report.Summary());
    CommandExitCode() = 1;
  }
}

}  // namespace

void RegisterSurfaceCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<SurfaceCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "surface",
      "Incremental 2-manifold surface (Litvinov & Lhuillier 2013) from a keyframe stream; "
      "--from-gt simulates a perfect SfM on a drive's ground truth");
  command->add_option("--from-gt", o->from_gt,
                      "Drive folder with rig.json, gt/poses.tum, gt/mesh.ply");
  command->add_option("--out", o->out, "Output folder (surface.ply, stats/keyframes.csv)");
  command
      ->add_option("--enclosing", o->enclosing,
                   "Enclosing set E: ball (paper §4.1) | conflict (conflict zones + margin)")
      ->capture_default_str();
  command->add_flag("--no-batch", o->no_batch,
                    "Sculpt the first keyframes one by one instead of in one batch (§5.1)");
  command
      ->add_option("--init-keyframes", o->sculptor.init_keyframes,
                   "Keyframes measuring s (and sculpted in batch), paper §5.1")
      ->capture_default_str();
  command->add_option("--keyframe-spacing", o->gt.keyframe_spacing, "Metres between keyframes")
      ->capture_default_str();
  command->add_option("--points-per-keyframe", o->gt.points_per_keyframe, "New points per keyframe")
      ->capture_default_str();
  command->add_option("--max-keyframes", o->gt.max_keyframes, "0: the whole drive")
      ->capture_default_str();
  command->add_option("--point-noise", o->gt.point_noise, "Gaussian noise on points, metres")
      ->capture_default_str();
  command->add_option("--seed", o->gt.seed, "Seed of the point sampling")->capture_default_str();
  command->callback([o, &global] { RunSurface(*o, global); });
}

}  // namespace omni
