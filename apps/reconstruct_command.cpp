// `omnisculpt reconstruct DRIVE --out OUT`: the whole job in one process, SfM and surface on
// their own threads joined by a bounded queue (pipeline/reconstruction.h), writing the outputs
// of docs/design.md §4.
//
// Resume-safe output: everything is written into the sibling folder OUT.incomplete/, marked by
// the file INCOMPLETE, and renamed to OUT only when complete (the last file written is
// reconstruct.json, the run's summary). A killed run leaves OUT.incomplete/ (reused by the next
// run) and never an OUT that looks complete. A non-empty OUT is refused; with --force it is
// replaced only if it holds a reconstruct.json (a previous reconstruction), never a folder of
// other files.

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <unordered_map>

#include "apps/commands.h"
#include "apps/output_folder.h"
#include "apps/sfm_options.h"
#include "apps/sfm_summary.h"
#include "calib/atomic_file.h"
#include "calib/drive.h"
#include "calib/error.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "pipeline/reconstruction.h"
#include "pipeline/sfm_outputs.h"
#include "sfm/colmap_model.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

struct ReconstructCommandOptions {
  std::string drive;
  std::string out;
  bool force = false;
  SfmCommandLine sfm;  // the SfM group, as `sfm` takes it (apps/sfm_options.h)
  std::string loop_replay = "batch";
  // The surface's enclosing set (--enclosing).
  std::string enclosing = EnclosingName(SculptorOptions().enclosing);
  PipelineOptions pipeline;
};

constexpr const char* kIncompleteMarker = "INCOMPLETE";
constexpr const char* kSummaryFile = "reconstruct.json";

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

bool IsEmptyFolder(const fs::path& folder) {
  return fs::is_directory(folder) && fs::directory_iterator(folder) == fs::directory_iterator();
}

// Checks OUT and prepares OUT.incomplete; returns the latter.
fs::path PrepareOutput(const fs::path& out, bool force) {
  if (fs::exists(out) && !fs::is_directory(out))
    throw InputError(out.string(), "--out", "exists and is not a folder");
  if (fs::exists(out) && !IsEmptyFolder(out)) {
    if (!force)
      throw InputError(out.string(), "--out",
                       "exists and is not empty (--force replaces a previous reconstruction)");
    if (!fs::exists(out / kSummaryFile))
      throw InputError(out.string(), "--out",
                       std::string("is not a previous reconstruction (no ") + kSummaryFile +
                           "): not replaced, even with --force");
  }
  // OUT is replaced by a rename at the end: a read-only OUT is refused now, not after the run.
  if (fs::exists(out)) CheckFolderWritable(out, "--out");
  fs::path partial = out;
  partial += ".incomplete";
  if (fs::exists(partial)) {
    if (!fs::exists(partial / kIncompleteMarker))
      throw InputError(partial.string(), "--out",
                       "exists but is not an interrupted reconstruction; move it away");
    spdlog::warn("reconstruct: removing {} left by an interrupted run", partial.string());
    fs::remove_all(partial);
  }
  std::error_code error;
  fs::create_directories(partial / "stats", error);
  if (error) {
    throw InputError(out.string(), "--out",
                     "cannot create " + partial.string() + " (" + error.message() + ")");
  }
  std::ostringstream marker;
  marker << "omnisculpt reconstruct (pid " << getpid() << ") is writing this folder; it is "
         << "renamed to " << out.filename().string() << " when complete.\n";
  WriteTextFileAtomically(partial / kIncompleteMarker, marker.str());
  return partial;
}

// OUT.incomplete -> OUT, the previous OUT (checked by PrepareOutput) removed only then.
void Publish(const fs::path& partial, const fs::path& out) {
  fs::remove(partial / kIncompleteMarker);
  if (IsEmptyFolder(out)) fs::remove(out);
  if (fs::exists(out)) {
    // A name nobody uses: only the checked previous reconstruction is ever removed.
    fs::path old = out;
    old += ".replaced";
    for (int k = 1; fs::exists(old); ++k) {
      old = out;
      old += ".replaced" + std::to_string(k);
    }
    fs::rename(out, old);
    fs::rename(partial, out);
    fs::remove_all(old);
  } else {
    fs::rename(partial, out);
  }
}

// Runs the pipeline and writes its outputs into `partial`, published as `out` at the end.
void WriteReconstruction(const ReconstructCommandOptions& o, const GlobalOptions& global,
                         const Drive& drive, const fs::path& out, const fs::path& partial) {
  const Rig& rig = drive.rig();
  const bool central = o.pipeline.sfm.tracker.central;
  spdlog::info("reconstruct: {} frames of {}, {} cameras, {} mode; writing {}", drive.NumFrames(),
               drive.folder().string(), rig.NumCameras(), central ? "central" : "non-central",
               partial.string());

  PipelineCallbacks callbacks;
  if (!global.quiet) {
    callbacks.progress = [](const PipelineProgress& p) {
      const double rate = p.frames_done / std::max(p.seconds, 1e-9);
      spdlog::info(
          "reconstruct: frame {}/{} ({:.1f} frames/s, ETA {:.0f} s), {} keyframes, {} points, "
          "{} keyframes sculpted, {} triangles",
          p.frames_done, p.frames_total, rate,
          rate > 0 ? (p.frames_total - p.frames_done) / rate : 0.0, p.keyframes, p.points,
          p.keyframes_sculpted, p.triangles);
    };
  }
  // Snapshots: the closed δO (surface_<keyframe>.ply) and its observed part
  // (observed_<keyframe>.ply), written as they come and coloured at the end, when the points
  // have their colours (a later snapshot of the same keyframe, after a loop closure's replay,
  // replaces the earlier one).
  std::map<uint32_t, std::vector<PointId>> snapshot_observed_points;
  if (o.pipeline.snapshot_every > 0) {
    fs::create_directories(partial / "snapshots");
    callbacks.snapshot = [&partial, &snapshot_observed_points](const PipelineSnapshot& snapshot) {
      const std::string keyframe = std::to_string(snapshot.last_keyframe.value);
      WritePlyMesh(snapshot.closed, partial / "snapshots" / ("surface_" + keyframe + ".ply"));
      WritePlyMesh(snapshot.observed, partial / "snapshots" / ("observed_" + keyframe + ".ply"));
      snapshot_observed_points[snapshot.last_keyframe.value] = snapshot.observed_points;
    };
  }
  // The SfM's files, by the sfm command's writer (pipeline/sfm_outputs.h), as soon as the SfM
  // has finished, while the surface finishes.
  SfmOutputs outputs;
  callbacks.sfm_finished = [&](const SfmRunResult& sfm, double queue_blocked_seconds) {
    SfmOutputOptions output_options;
    output_options.frame_rate = o.sfm.frame_rate;
    output_options.queue_wait_seconds = queue_blocked_seconds;
    outputs = WriteSfmOutputs(drive, sfm, partial, output_options);
  };
  const PipelineResult result = RunPipeline(drive, o.pipeline, callbacks);
  const SfmRunResult& sfm = result.sfm;
  spdlog::info("reconstruct: point colours from {} keyframe images in {:.2f} s",
               outputs.colors.images_read, outputs.colors.seconds);
  // No surface file without a surface (a run that is not usable says why). Each vertex takes
  // its point's colour of points.ply.
  std::unordered_map<PointId, Rgb8> point_colors;
  {
    size_t i = 0;
    for (const FinalizedKeyframe& keyframe : sfm.keyframes) {
      for (const FinalizedPoint& point : keyframe.points) {
        if (i < outputs.cloud.colors.size())
          point_colors[PointId(static_cast<uint32_t>(point.point))] = outputs.cloud.colors[i];
        ++i;
      }
    }
  }
  TriangleMesh surface = result.mesh, closed = result.closed_mesh;
  ColorMeshVertices(result.mesh_points, point_colors, &surface);
  ColorMeshVertices(result.closed_mesh_points, point_colors, &closed);
  if (!closed.triangles.empty()) {
    WritePlyMesh(surface, partial / "surface.ply");
    WritePlyMesh(closed, partial / "surface_closed.ply");
  }
  for (const auto& [keyframe, observed_points] : snapshot_observed_points) {
    const fs::path file = partial / "snapshots" / ("observed_" + std::to_string(keyframe) + ".ply");
    TriangleMesh observed = ReadPlyMesh(file);
    ColorMeshVertices(observed_points, point_colors, &observed);
    WritePlyMesh(observed, file);
  }
  std::ostringstream keyframes_csv;
  keyframes_csv << PipelineKeyframesCsvHeader() << '\n';
  for (const PipelineKeyframeRow& row : result.surface_rows)
    keyframes_csv << PipelineKeyframesCsvRow(row) << '\n';
  WriteTextFileAtomically(partial / "stats" / "keyframes.csv", keyframes_csv.str());

  std::vector<double> surface_ms, queue_ms;
  // The rays short of the uncertain points (SculptorOptions::uncertain_ray_margin_deg) in the
  // last sculpting, the surface written (the last replay's rows, or the stream's).
  size_t uncertain_rays = 0;
  for (const PipelineKeyframeRow& row : result.surface_rows) {
    if (!row.surface.batch) surface_ms.push_back(MsPerKeyframe(row.surface));
    queue_ms.push_back(row.queue_ms);
    if (row.replay == result.surface_rows.back().replay)
      uncertain_rays += row.surface.rays_uncertain;
  }
  const SfmStats& stats = outputs.stats;
  // surface.ply: an oriented 2-manifold with boundary; surface_closed.ply: closed.
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  bounded.allow_empty = !result.closed_mesh.triangles.empty();
  const MeshCheckReport manifold = CheckMesh(result.mesh, bounded);
  const MeshCheckReport closed_manifold = CheckMesh(result.closed_mesh);
  // A usable result: a usable SfM map and a surface with triangles.
  std::string failure;
  if (sfm.outcome != SfmOutcome::kUsable)
    failure = sfm.outcome_reason;
  else if (result.closed_mesh.triangles.empty())
    failure = "the surface is empty (" + sfm.outcome_reason + ")";
  const double frames_per_second = sfm.frames_total / std::max(result.seconds, 1e-9);
  // The SfM's part (as in sfm.json), the loop closures with the surface's replay of each.
  nlohmann::json summary = SfmSummaryJson(drive, sfm, outputs, central, result.loop_replay_seconds,
                                          result.loop_replay_keyframes);
  const nlohmann::json surface_fields = {
      {"status", failure.empty() ? "usable" : "not_usable"},
      {"outcome", failure.empty() ? sfm.outcome_reason : failure},
      {"triangles", result.mesh.triangles.size()},
      {"manifold", manifold.ok},
      {"boundary_loops", manifold.boundary_loops},
      {"closed_triangles", result.closed_mesh.triangles.size()},
      {"closed_manifold", closed_manifold.ok},
      {"uncertain_rays", uncertain_rays},
      {"seconds", result.seconds},
      {"frames_per_second", frames_per_second},
      {"surface_busy_seconds", result.surface_seconds},
      {"surface_ms_median", Quantile(surface_ms, 0.5)},
      {"surface_ms_p95", Quantile(surface_ms, 0.95)},
      {"queue_capacity", o.pipeline.queue_capacity},
      {"surface_thread_nice", o.pipeline.surface_thread_nice},
      {"queue_max_size", result.queue_max_size},
      {"queue_blocked_pushes", result.queue_blocked_pushes},
      {"queue_blocked_seconds", result.queue_blocked_seconds},
      {"queue_ms_median", Quantile(queue_ms, 0.5)},
      {"queue_ms_max",
       queue_ms.empty() ? 0.0 : *std::max_element(queue_ms.begin(), queue_ms.end())},
      {"loop_closure", o.pipeline.sfm.loop_closure},
      {"surface_replay_seconds", result.replay_seconds},
      {"surface_keyframes_skipped", result.surface_keyframes_skipped},
      {"surface_smoothing",
       {{"every_keyframe", o.pipeline.sculptor.smoothing.every_keyframe},
        {"at_extraction_seconds", result.final_smoothing.seconds},
        {"at_extraction_vertices", result.final_smoothing.vertices}}},
  };
  summary.update(surface_fields);
  // The final bundle adjustment's replay is the one after the loop closures' replays.
  const bool final_ba = summary["final_bundle_adjustment"]["ran"].get<bool>();
  summary["final_bundle_adjustment"]["surface_replay_seconds"] =
      final_ba && result.loop_replay_seconds.size() > sfm.loop_closures.size()
          ? result.loop_replay_seconds.back()
          : 0.0;
  summary["frame_rate"] = o.sfm.frame_rate;
  summary["profile"] = o.sfm.profile;
  summary["loop_replay"] = o.loop_replay;
  summary["enclosing"] = o.enclosing;
  summary["prefetch_frames_ahead"] = o.pipeline.sfm.prefetch.frames_ahead;
  summary["prefetch_thread_nice"] = o.pipeline.sfm.prefetch.thread_nice;
  summary["point_colors_seconds"] = outputs.colors.seconds;
  WriteTextFileAtomically(partial / kSummaryFile, summary.dump(2) + "\n");
  Publish(partial, out);

  std::string written;
  if (!result.closed_mesh.triangles.empty()) written += "surface.ply, surface_closed.ply, ";
  if (sfm.outcome != SfmOutcome::kNotInitialised)
    written += "points.ply, poses.tum, frame_poses.tum, sparse/, ";
  written += std::string("stats/, ") + kSummaryFile;
  std::printf(
      "reconstruct: %zu frames (%zu skipped, %zu not tracked) in %.1f s (%.1f frames/s), %zu "
      "keyframes, %zu points, %zu observed triangles of %zu (manifold with boundary %s, "
      "closed %s)%s\n"
      "  surface ms per keyframe: median %.1f, p95 %.1f; queue: at most %zu of %d waiting, "
      "the SfM waited %.1f s for room; %zu loop closure(s), surface replays %.1f s\n"
      "  wrote %s (%s)\n",
      sfm.frames_total, sfm.skipped.size(), stats.frames_not_tracked, result.seconds,
      frames_per_second, sfm.keyframes.size(), outputs.cloud.points.size(),
      result.mesh.triangles.size(), result.closed_mesh.triangles.size(), manifold.ok ? "yes" : "NO",
      closed_manifold.ok ? "yes" : "NO", failure.empty() ? "" : "; NOT USABLE",
      Quantile(surface_ms, 0.5), Quantile(surface_ms, 0.95), result.queue_max_size,
      o.pipeline.queue_capacity, result.queue_blocked_seconds, sfm.loop_closures.size(),
      result.replay_seconds, out.c_str(), written.c_str());
  if (!failure.empty()) {
    ReportNotUsable(drive.folder().string() + ": " + failure + "; " + out.string() + "/" +
                    kSummaryFile + " and stats/sfm_frames.csv say what happened");
  } else {
    ReportSurfaceChecks("reconstruct", closed_manifold, manifold);
  }
}

void RunReconstruct(ReconstructCommandOptions& o, const GlobalOptions& global) {
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  if (o.loop_replay == "batch") {
    o.pipeline.loop_replay = LoopReplay::kBatch;
  } else if (o.loop_replay == "incremental") {
    o.pipeline.loop_replay = LoopReplay::kIncremental;
  } else {
    throw InputError("", "--loop-replay", "expected batch or incremental");
  }
  ApplyEnclosingOption(o.enclosing, &o.pipeline.sculptor);
  const Drive drive = Drive::Open(o.drive);
  const Rig& rig = drive.rig();
  o.pipeline.sculptor.pixel_angle = rig.FinestPixelAngle();
  ApplySfmOptions(rig, "reconstruct", &o.sfm);
  ApplyFrameRange(drive, &o.sfm);
  o.pipeline.sfm = o.sfm.sfm;
  o.pipeline.progress_period = isatty(fileno(stderr)) ? 2.0 : 10.0;
  ThrowIfInvalid(o.pipeline.Check(), "PipelineOptions");
  const fs::path out = fs::absolute(fs::path(o.out)).lexically_normal();
  const fs::path partial = PrepareOutput(out.has_filename() ? out : out.parent_path(), o.force);
  try {
    WriteReconstruction(o, global, drive, out, partial);
  } catch (...) {
    // A run that failed leaves nothing behind (a killed one leaves OUT.incomplete, which the
    // next run cleans up).
    std::error_code ignored;
    fs::remove_all(partial, ignored);
    throw;
  }
}

}  // namespace

void RegisterReconstructCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<ReconstructCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "reconstruct",
      "Images to surface in one process: SfM and incremental manifold surface on their own "
      "threads, joined by a bounded queue");
  command->add_option("drive", o->drive, "Drive folder (rig.json, images/<camera>/...)")
      ->required();
  command
      ->add_option("--out", o->out,
                   "Output folder (surface.ply, surface_closed.ply, points.ply, poses.tum, stats/, "
                   "reconstruct.json); written as OUT.incomplete and renamed when complete")
      ->required();
  command->add_flag("--force", o->force, "Replace OUT if it holds a previous reconstruction");
  command
      ->add_option(
          "--snapshot-every", o->pipeline.snapshot_every,
          "Write OUT/snapshots/surface_<keyframe>.ply (closed) and observed_<keyframe>.ply every "
          "K keyframes (0: none)")
      ->capture_default_str();
  command
      ->add_option("--queue", o->pipeline.queue_capacity,
                   "Keyframes that may wait between the SfM and the surface")
      ->capture_default_str();
  command
      ->add_option("--surface-nice", o->pipeline.surface_thread_nice,
                   "The surface thread runs this much nicer than the SfM (0 to 19; 0: the same "
                   "priority): the SfM sets the pace, the surface keeps up in the time left")
      ->capture_default_str();
  command->add_flag("!--sculpt-superseded", o->pipeline.skip_superseded_keyframes,
                    "A surface thread that is behind sculpts every keyframe, even those that a "
                    "replay queued after them sculpts again (default: skipped, the same final "
                    "surface; stats/keyframes.csv then has a row for each)");
  command
      ->add_option("--loop-replay", o->loop_replay,
                   "Surface after a loop closure: batch (the corrected keyframes sculpted at "
                   "once) or incremental (one by one from scratch)")
      ->capture_default_str();
  AddSfmOptions(command, &o->sfm);
  AddEnclosingOptions(command, &o->enclosing, &o->pipeline.sculptor);
  AddCarvingOptions(command, &o->pipeline.sculptor);
  AddObservedMeshOptions(command, &o->pipeline.sculptor.observed);
  command->callback([o, &global] { RunReconstruct(*o, global); });
}

}  // namespace omni
