// `omnisculpt reconstruct DRIVE --out OUT` (issue 9): the whole job in one process, SfM and
// surface on their own threads joined by a bounded queue (apps/pipeline/), writing the outputs
// of DESIGN.md §4.
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
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "apps/commands.h"
#include "apps/pipeline/pipeline.h"
#include "apps/pipeline/point_colors.h"
#include "apps/pipeline/sfm_stats.h"
#include "calib/atomic_file.h"
#include "calib/drive.h"
#include "calib/error.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "sfm/colmap_model.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

struct ReconstructCommandOptions {
  std::string drive;
  std::string out;
  bool force = false;
  bool central = false;
  bool non_central = false;
  double frame_rate = 15.0;  // timestamps of poses.tum: frame index / frame_rate
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
  fs::path partial = out;
  partial += ".incomplete";
  if (fs::exists(partial)) {
    if (!fs::exists(partial / kIncompleteMarker))
      throw InputError(partial.string(), "--out",
                       "exists but is not an interrupted reconstruction; move it away");
    spdlog::warn("reconstruct: removing {} left by an interrupted run", partial.string());
    fs::remove_all(partial);
  }
  fs::create_directories(partial / "stats");
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

void RunReconstruct(ReconstructCommandOptions& o, const GlobalOptions& global) {
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  if (o.central && o.non_central)
    throw InputError("", "--central, --non-central", "give at most one of them");
  if (!(o.frame_rate > 0.0)) throw InputError("", "--frame-rate", "expected a positive rate");
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
  o.pipeline.tracker.central = o.central ? true : o.non_central ? false : rig.central;
  o.pipeline.progress_period = isatty(fileno(stderr)) ? 2.0 : 10.0;
  if (const std::string problem = o.pipeline.Check(); !problem.empty())
    throw InputError("", "options", problem);
  const fs::path out = fs::absolute(fs::path(o.out)).lexically_normal();
  const fs::path partial = PrepareOutput(out.has_filename() ? out : out.parent_path(), o.force);
  spdlog::info("reconstruct: {} frames of {}, {} cameras, {} mode; writing {}", drive.NumFrames(),
               drive.folder().string(), rig.NumCameras(),
               o.pipeline.tracker.central ? "central" : "non-central", partial.string());

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
  if (o.pipeline.snapshot_every > 0) {
    fs::create_directories(partial / "snapshots");
    callbacks.snapshot = [&partial](const KeyframeId& keyframe, const TriangleMesh& mesh) {
      WritePlyMesh(mesh,
                   partial / "snapshots" / ("surface_" + std::to_string(keyframe.value) + ".ply"));
    };
  }
  const PipelineResult result = RunPipeline(drive, o.pipeline, callbacks);

  std::vector<StampedPose> poses;
  PointCloud cloud;
  for (const FinalizedKeyframe& keyframe : result.keyframes) {
    poses.push_back({keyframe.frame / o.frame_rate, keyframe.world_from_rig});
    for (const FinalizedPoint& point : keyframe.points) cloud.points.push_back(point.position);
  }
  // Point colours from the keyframe images, now that the SfM thread is done.
  PointColorStats color_stats;
  cloud.colors = ColorPoints(
      rig, result.keyframes,
      [&drive](int frame, int camera) { return drive.LoadRgb(frame, camera); }, {}, &color_stats);
  spdlog::info("reconstruct: point colours from {} keyframe images in {:.2f} s",
               color_stats.images_read, color_stats.seconds);
  WriteTum(poses, partial / "poses.tum");
  WritePlyPoints(cloud, partial / "points.ply");
  WritePlyMesh(result.mesh, partial / "surface.ply");
  // The COLMAP text model, by the sfm command's writer (sfm/colmap_model.h).
  const ColmapModelStats colmap = WriteColmapTextModel(
      rig, result.keyframes,
      [&drive](int frame, int camera) {
        return fs::relative(drive.ImagePath(frame, camera), drive.folder()).generic_string();
      },
      partial / "sparse", cloud.colors);
  std::ostringstream frames_csv, keyframes_csv;
  frames_csv << PipelineFramesCsvHeader() << '\n';
  for (const PipelineFrameRow& row : result.frames) frames_csv << PipelineFramesCsvRow(row) << '\n';
  keyframes_csv << PipelineKeyframesCsvHeader() << '\n';
  for (const PipelineKeyframeRow& row : result.surface_rows)
    keyframes_csv << PipelineKeyframesCsvRow(row) << '\n';
  WriteTextFileAtomically(partial / "stats" / "sfm_frames.csv", frames_csv.str());
  WriteTextFileAtomically(partial / "stats" / "keyframes.csv", keyframes_csv.str());
  // stats/sfm_stages.csv and sfm_summary.csv, by the sfm command's writer.
  SfmStats sfm;
  for (const PipelineFrameRow& row : result.frames)
    sfm.AddFrame(row.loaded, row.matched, row.result);
  sfm.keyframes = result.keyframes.size();
  sfm.points = cloud.points.size();
  sfm.colmap = colmap;
  sfm.tracks = ComputeTrackStats(result.keyframes);
  sfm.front = result.sfm_front;
  sfm.back = result.sfm_back;
  sfm.load_seconds = result.load_seconds;
  sfm.loop_closure_seconds = result.loop_closure_seconds;
  sfm.queue_wait_seconds = result.queue_blocked_seconds;
  sfm.total_seconds = result.sfm_seconds;
  WriteSfmStats(sfm, partial / "stats");

  std::vector<double> surface_ms, queue_ms;
  for (const PipelineKeyframeRow& row : result.surface_rows) {
    if (!row.surface.batch) surface_ms.push_back(row.surface.ms_total);
    queue_ms.push_back(row.queue_ms);
  }
  const size_t untracked = sfm.frames_not_tracked;
  const MeshCheckReport manifold = CheckMesh(result.mesh);
  nlohmann::json summary = {
      {"drive", drive.folder().string()},
      {"mode", o.pipeline.tracker.central ? "central" : "non-central"},
      {"frames", result.frames_total},
      {"frames_skipped", result.skipped.size()},
      {"skipped", result.skipped},
      {"frames_not_tracked", untracked},
      {"keyframes", result.keyframes.size()},
      {"points", cloud.points.size()},
      {"triangles", result.mesh.triangles.size()},
      {"manifold", manifold.ok},
      {"seconds", result.seconds},
      {"frames_per_second", result.frames_total / std::max(result.seconds, 1e-9)},
      {"sfm_seconds", result.sfm_seconds},
      {"surface_busy_seconds", result.surface_seconds},
      {"surface_ms_median", Quantile(surface_ms, 0.5)},
      {"surface_ms_p95", Quantile(surface_ms, 0.95)},
      {"queue_capacity", o.pipeline.queue_capacity},
      {"queue_max_size", result.queue_max_size},
      {"queue_blocked_pushes", result.queue_blocked_pushes},
      {"queue_blocked_seconds", result.queue_blocked_seconds},
      {"queue_ms_median", Quantile(queue_ms, 0.5)},
      {"queue_ms_max",
       queue_ms.empty() ? 0.0 : *std::max_element(queue_ms.begin(), queue_ms.end())},
  };
  nlohmann::json loops = nlohmann::json::array();
  for (size_t i = 0; i < result.loop_closures.size(); ++i) {
    const LoopClosureEvent& e = result.loop_closures[i];
    loops.push_back(
        {{"keyframe", e.keyframe},
         {"frame", e.frame},
         {"candidate_keyframe", e.candidate_keyframe},
         {"candidate_frame", e.candidate_frame},
         {"ring_shift", e.shift},
         {"appearance_score", e.score},
         {"matches", e.matches},
         {"inliers", e.inliers},
         {"relative_pose_matches", e.relative_matches},
         {"relative_pose_inliers", e.relative_inliers},
         {"rotation_disagreement_deg", e.rotation_disagreement * 180.0 / M_PI},
         {"correction_translation", e.correction_translation},
         {"correction_rotation_deg", i < result.loop_correction_rotation_deg.size()
                                         ? result.loop_correction_rotation_deg[i]
                                         : 0.0},
         {"correction_scale", e.correction_scale},
         {"ms", e.ms},
         {"surface_replay_seconds",
          i < result.loop_replay_seconds.size() ? result.loop_replay_seconds[i] : 0.0},
         {"surface_replay_keyframes",
          i < result.loop_replay_keyframes.size() ? result.loop_replay_keyframes[i] : 0}});
  }
  summary["colmap_images"] = colmap.images;
  summary["colmap_points"] = colmap.points;
  summary["colmap_mean_reprojection_error_px"] = colmap.mean_reprojection_error;
  summary["loop_closure"] = o.pipeline.loop_closure;
  summary["loop_closures"] = loops;
  summary["surface_replay_seconds"] = result.replay_seconds;
  summary["loop_replay"] = o.loop_replay;
  summary["enclosing"] = o.enclosing;
  summary["prefetch_frames_ahead"] = o.pipeline.prefetch.frames_ahead;
  summary["point_colors_seconds"] = color_stats.seconds;
  WriteTextFileAtomically(partial / kSummaryFile, summary.dump(2) + "\n");
  Publish(partial, out);

  std::printf(
      "reconstruct: %zu frames (%zu skipped, %zu not tracked) in %.1f s (%.1f frames/s), %zu "
      "keyframes, %zu points, %zu triangles, manifold %s\n"
      "  surface ms per keyframe: median %.1f, p95 %.1f; queue: at most %zu of %d waiting, "
      "the SfM waited %.1f s for room; %zu loop closure(s), surface replays %.1f s\n"
      "  wrote %s (surface.ply, points.ply, poses.tum, sparse/, stats/, %s)\n",
      result.frames_total, result.skipped.size(), untracked, result.seconds,
      result.frames_total / std::max(result.seconds, 1e-9), result.keyframes.size(),
      cloud.points.size(), result.mesh.triangles.size(),
      manifold.ok ? "yes" : "NO", Quantile(surface_ms, 0.5),
      Quantile(surface_ms, 0.95), result.queue_max_size, o.pipeline.queue_capacity,
      result.queue_blocked_seconds, result.loop_closures.size(), result.replay_seconds, out.c_str(),
      kSummaryFile);
  if (!manifold.ok) {
    spdlog::error("reconstruct: the surface is not an oriented 2-manifold: {}", manifold.Summary());
    CommandExitCode() = 1;
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
                   "Output folder (surface.ply, points.ply, poses.tum, stats/, "
                   "reconstruct.json); written as OUT.incomplete and renamed when complete")
      ->required();
  command->add_flag("--force", o->force, "Replace OUT if it holds a previous reconstruction");
  command->add_flag("--central", o->central, "Central approximation (default: rig.json)");
  command->add_flag("--non-central", o->non_central, "True camera offsets (default: rig.json)");
  command->add_option("--max-frames", o->pipeline.max_frames, "0: the whole drive")
      ->capture_default_str();
  command
      ->add_option("--snapshot-every", o->pipeline.snapshot_every,
                   "Write OUT/snapshots/surface_<keyframe>.ply every K keyframes (0: none)")
      ->capture_default_str();
  command
      ->add_option("--queue", o->pipeline.queue_capacity,
                   "Keyframes that may wait between the SfM and the surface")
      ->capture_default_str();
  command
      ->add_option("--downscale", o->pipeline.tracks.harris.downscale,
                   "Shrink the images by this factor before detection (paper: 2)")
      ->capture_default_str();
  command
      ->add_option("--corners", o->pipeline.tracks.harris.max_corners, "Harris corners per image")
      ->capture_default_str();
  command->add_flag("!--no-loop-closure", o->pipeline.loop_closure,
                    "Do not detect revisits nor correct the drift");
  command->add_flag("!--no-global-ba", o->pipeline.loop.global_bundle_adjustment,
                    "After a loop closure, correct with the pose graph only");
  command
      ->add_option("--loop-replay", o->loop_replay,
                   "Surface after a loop closure: batch (the corrected keyframes sculpted at "
                   "once) or incremental (one by one from scratch)")
      ->capture_default_str();
  AddEnclosingOptions(command, &o->enclosing, &o->pipeline.sculptor);
  command
      ->add_option("--prefetch", o->pipeline.prefetch.frames_ahead,
                   "Frames whose images are decoded ahead of the SfM")
      ->capture_default_str();
  command->add_option("--frame-rate", o->frame_rate, "Timestamps of poses.tum: frame / rate")
      ->capture_default_str();
  command->callback([o, &global] { RunReconstruct(*o, global); });
}

}  // namespace omni
