// `omnisculpt sfm DRIVE --out OUT [--central|--non-central]`: the incremental rig SfM
// (pipeline/sfm_runner.h, the loop `reconstruct` runs too) on a drive's images, writing the
// keyframe poses (poses.tum; every tracked frame in frame_poses.tum), the points (points.ply), a
// COLMAP text model (sparse/), one row per frame (stats/sfm_frames.csv), the time per stage
// (stats/sfm_stages.csv) and a summary (stats/sfm_summary.csv), by pipeline/sfm_outputs.h, and
// sfm.json: the run's outcome, skipped frames and warnings (apps/sfm_summary.h).

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "apps/commands.h"
#include "apps/output_folder.h"
#include "apps/sfm_options.h"
#include "apps/sfm_summary.h"
#include "calib/atomic_file.h"
#include "calib/drive.h"
#include "calib/error.h"
#include "pipeline/sfm_outputs.h"
#include "pipeline/sfm_runner.h"

namespace omni {
namespace {

struct SfmCommandOptions {
  std::string drive;
  std::string out;
  bool force = false;
  SfmCommandLine sfm;
};

void RunSfmCommand(SfmCommandOptions& o, const GlobalOptions& global) {
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  const Drive drive = Drive::Open(o.drive);
  const Rig& rig = drive.rig();
  ApplySfmOptions(rig, "sfm", &o.sfm);
  ApplyFrameRange(drive, &o.sfm);
  OutputFolder folder(o.out, "stats/sfm_summary.csv", o.force, "sfm");
  spdlog::info("sfm: {} frames, {} cameras, {} mode (largest camera offset {:.3f} m)",
               drive.NumFrames(), rig.NumCameras(),
               o.sfm.sfm.tracker.central ? "central" : "non-central", rig.MaxCenterOffset());

  const size_t num_frames = SfmFramesToRun(o.sfm.sfm, drive.NumFrames());
  SfmRunnerCallbacks callbacks;
  auto last_progress = std::chrono::steady_clock::now();
  const auto start = last_progress;
  size_t frames_done = 0;
  if (!global.quiet) {
    callbacks.frame_done = [&](const SfmFrameRow&, int keyframes, int points) {
      ++frames_done;
      const auto now = std::chrono::steady_clock::now();
      if (std::chrono::duration<double>(now - last_progress).count() < 2.0 &&
          frames_done != num_frames)
        return;
      last_progress = now;
      const double seconds = std::chrono::duration<double>(now - start).count();
      const double rate = frames_done / std::max(seconds, 1e-9);
      spdlog::info("sfm: frame {}/{}, {:.1f} frames/s, ETA {:.0f} s, {} keyframes, {} points",
                   frames_done, num_frames, rate, (num_frames - frames_done) / rate, keyframes,
                   points);
    };
  }
  const SfmRunResult run = RunSfm(rig, DriveFrameSource(drive), o.sfm.sfm, callbacks);

  const std::filesystem::path out(o.out);
  SfmOutputOptions output_options;
  output_options.frame_rate = o.sfm.frame_rate;
  const SfmOutputs outputs = WriteSfmOutputs(drive, run, out, output_options);
  nlohmann::json summary = SfmSummaryJson(drive, run, outputs, o.sfm.sfm.tracker.central);
  summary["frame_rate"] = o.sfm.frame_rate;
  summary["profile"] = o.sfm.profile;
  WriteTextFileAtomically(out / "sfm.json", summary.dump(2) + "\n");
  folder.Keep();
  const SfmStats& stats = outputs.stats;
  spdlog::info(
      "sfm: {} keyframes, {} points, {} of {} frames not tracked, {} skipped, {} loop "
      "closure(s), {:.1f} frames/s, written to {}",
      run.keyframes.size(), outputs.cloud.points.size(), stats.frames_not_tracked, run.frames_total,
      stats.frames_skipped, run.loop_closures.size(),
      run.frames_total / std::max(run.seconds, 1e-9), out.string());
  spdlog::info(
      "sfm: seconds per stage: detect {:.1f}, match {:.1f}, resect {:.1f}, triangulate "
      "{:.1f}, bundle adjustment {:.1f}, loop closure {:.1f}, waiting for images {:.1f}, total "
      "{:.1f}; point colours {:.1f} s after",
      run.front.detect, run.front.match, run.back.resect, run.back.triangulate,
      run.back.bundle_adjustment, run.loop_closure_seconds, run.load_seconds, run.seconds,
      outputs.colors.seconds);
  if (run.outcome != SfmOutcome::kUsable)
    ReportNotUsable(drive.folder().string() + ": " + run.outcome_reason + "; " + out.string() +
                    "/stats/sfm_frames.csv says what happened to each frame");
}

}  // namespace

void RegisterSfmCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<SfmCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "sfm",
      "Incremental rig SfM (Harris + ZNCC tracks, OpenGV, local bundle adjustment, loop "
      "closure)");
  command->add_option("drive", o->drive, "Drive folder (rig.json, images/<camera>/...)")
      ->required();
  command->add_option("--out", o->out,
                      "Output folder (poses.tum, points.ply, sparse/, stats/), new or empty");
  command->add_flag("--force", o->force,
                    "Write into --out if it holds an earlier sfm output (stats/sfm_summary.csv)");
  AddSfmOptions(command, &o->sfm);
  command->callback([o, &global] { RunSfmCommand(*o, global); });
}

}  // namespace omni
