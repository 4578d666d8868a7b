#pragma once
// The in-process pipeline of `omnisculpt reconstruct` (docs/design.md §1): an SfM thread runs
// the SfM loop (pipeline/sfm_runner.h) over the drive's frames and hands every keyframe that
// left the local adjustment window (its pose and points no longer move) through a bounded
// queue to a surface thread running the incremental sculptor (surface/sculptor.h); after a
// loop closure the corrected map follows through the same queue and the surface is sculpted
// again from it. The calling thread reports progress.

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "calib/drive.h"
#include "calib/ply.h"
#include "pipeline/sfm_runner.h"
#include "surface/sculptor.h"

namespace omni {

// How the surface thread rebuilds the surface after a loop correction moved the map.
enum class LoopReplay {
  kIncremental,  // a new sculptor takes the corrected keyframes one by one (the first
                 // init_keyframes in one batch, which measures s again, paper §5.1)
  kBatch,        // a new sculptor sculpts all the corrected keyframes in one batch (§5.1's
                 // initialisation on the whole map), with the scale s of the first sculpting
};

struct PipelineOptions {
  // The SfM (pipeline/sfm_runner.h): after a loop correction the surface thread replays the
  // sculptor on the corrected finalised keyframes (the keyframes queued meanwhile wait).
  SfmRunnerOptions sfm;
  // The surface sculpted three keyframes a step (SculptorOptions::keyframes_per_step): the final
  // surface is sculpted again in one batch after the SfM's final adjustment (a corrected map),
  // so the steps shape only the live surface, at about 0.7 of the surface thread's time
  // (docs/figures.md F53). Two rounds of enclosed free cells (enclosed_free_rounds, F58), the
  // aperture bound at 4° (min_aperture_deg, F59); surface.ply's as `surface`'s (F63).
  static SculptorOptions DefaultSculptor();
  SculptorOptions sculptor = DefaultSculptor();
  LoopReplay loop_replay = LoopReplay::kBatch;
  // Keyframes waiting between the SfM and the surface threads; a full queue stalls the SfM
  // (backpressure), so memory stays bounded however slow the surface is. A keyframe item is
  // ~22 KB on the paper drive (130 points of 3 rays), so 32 of them ~0.7 MB: room for the
  // keyframes the SfM makes while the surface replays a corrected map (a replay item, the
  // whole map, is ~10 MB there).
  int queue_capacity = 32;
  // The surface thread runs this much nicer than the process (Linux thread niceness, 0 to 19;
  // 0: the SfM's priority). The SfM thread sets the pace while the surface keeps up with the
  // queue; when both want a core the SfM gets it, and a surface that falls behind still gets the
  // cores whenever the SfM waits (a full queue, the end of the input). docs/figures.md F40.
  int surface_thread_nice = 10;
  // A surface thread that is behind when a replay is queued skips the keyframes queued before
  // it, which the replay sculpts again (the same final surfaces); false: it sculpts every
  // keyframe it is handed (each has its row in surface_rows, whatever the timing).
  bool skip_superseded_keyframes = true;
  int snapshot_every = 0;        // snapshot callback every K sculpted keyframes; 0: none
  double progress_period = 2.0;  // seconds between two progress callbacks

  std::string Check() const;
};

// One row per call of the sculptor that processed keyframes (the batch initialisation is one
// row), with the time the keyframe waited in the queue.
struct PipelineKeyframeRow {
  KeyframeStats surface;
  double queue_ms = 0.0;  // from the SfM's push to the surface's pop
  int replay = 0;         // > 0: the row of a replay after the replay-th loop closure
};

struct PipelineProgress {
  size_t frames_done = 0, frames_total = 0;
  int keyframes = 0, points = 0;
  size_t keyframes_sculpted = 0, triangles = 0;
  double seconds = 0.0;
};

// The surface after a multiple of PipelineOptions::snapshot_every sculpted keyframes, as the
// final one: the closed δO (ExtractMesh) and its observed part (ExtractObservedMesh, what
// surface.ply holds at the end) with the point id of each of its vertices, so that it can be
// coloured as surface.ply once the points have colours. Taking it smooths what waited for a
// mesh to be taken (SmoothingOptions::every_keyframe off), once for both meshes.
struct PipelineSnapshot {
  KeyframeId last_keyframe;
  TriangleMesh closed;
  TriangleMesh observed;
  std::vector<PointId> observed_points;
};

struct PipelineCallbacks {
  // From the calling thread, every progress_period seconds and once at the end.
  std::function<void(const PipelineProgress&)> progress;
  // From the surface thread, after each multiple of snapshot_every sculpted keyframes.
  std::function<void(const PipelineSnapshot&)> snapshot;
  // From the SfM thread, once, when the SfM has finished without error (PipelineResult::sfm as
  // it will be returned; the seconds the SfM waited for room in the queue), while the surface
  // thread finishes its last keyframes: where a caller writes the SfM's files. What it throws
  // fails the run as an error of the SfM.
  std::function<void(const SfmRunResult&, double queue_blocked_seconds)> sfm_finished;
};

struct PipelineResult {
  SfmRunResult sfm;  // keyframes (final poses and points), frame rows, loop closures, timings
  // The observed surface (IncrementalSculptor::ExtractObservedMesh, surface.ply) and the closed
  // δO (ExtractMesh, surface_closed.ply), with the point id of each vertex (ColorMeshVertices).
  TriangleMesh mesh;
  std::vector<PointId> mesh_points;
  TriangleMesh closed_mesh;
  std::vector<PointId> closed_mesh_points;
  ObservedMeshStats observed;
  std::vector<PipelineKeyframeRow> surface_rows;
  double seconds = 0.0, surface_seconds = 0.0;
  size_t queue_max_size = 0, queue_blocked_pushes = 0;
  double queue_blocked_seconds = 0.0;
  // Per loop closure: the surface time of the replay that followed it and the keyframes it
  // re-sculpted (0 and 0 when a later replay superseded it before it began); then the final
  // adjustment's replay.
  std::vector<double> loop_replay_seconds;
  std::vector<size_t> loop_replay_keyframes;
  double replay_seconds = 0.0;  // surface time spent replaying after corrections
  // Keyframes the surface thread did not sculpt because a replay queued after them re-sculpts
  // them (the surface thread was behind when a correction came).
  size_t surface_keyframes_skipped = 0;
  // The smoothing of the final surface when it waited for the end (SmoothingOptions::
  // every_keyframe off), part of surface_seconds.
  IncrementalSculptor::DeferredSmoothing final_smoothing;
};

// Runs the pipeline to the end of the drive. Throws InputError when every frame was skipped
// and OptionsError for bad options; rethrows, on the calling thread, what a stage thread threw.
// A run whose SfM is not usable (result.sfm.outcome) still returns, with what was done.
PipelineResult RunPipeline(const Drive& drive, const PipelineOptions& options,
                           const PipelineCallbacks& callbacks = {});

// The s of a replay when the correction changed the map's scale: the first sculptor measured
// `scale` on keyframes whose centres were `reference_spacing` apart on average; the replay's
// first `count` keyframes (the same ones, corrected) are compared with that spacing, and when
// the ratio is outside [1 / max_change, max_change] (an SfM whose map was rescaled, not a loop
// closure's usual correction of a percent) s follows it, so that the bounds and the Steiner
// grid keep their meaning in the new units. Otherwise `scale`, unchanged. *new_spacing: the
// replay's spacing (the reference of the next replay when s changed).
double ReplayScale(double scale, double reference_spacing,
                   const std::vector<SurfaceKeyframe>& keyframes, size_t count,
                   double max_change = 1.25, double* new_spacing = nullptr);

// The options of the sculptor that replays the `keyframes` corrected keyframes after a loop
// closure, the first sculptor having measured `scale` (0: not yet known). kBatch with s known:
// all of them in one batch at that s, then one by one; otherwise `base` (s measured again).
SculptorOptions ReplaySculptorOptions(const SculptorOptions& base, LoopReplay mode, double scale,
                                      size_t keyframes);

// The final batch of `surface --final-batch` and `merge --final-batch`: every keyframe sculpted
// again in one batch at the scale s that `streamed` measured on them (ReplaySculptorOptions with
// kBatch), as the pipeline's replay after the SfM's final adjustment. Not run (sculptor null)
// when `streamed` has no s or sculpted every keyframe in its first batch (no row of
// `streamed_stats` is incremental): that batch is the surface already.
struct FinalBatch {
  std::unique_ptr<IncrementalSculptor> sculptor;
  std::vector<KeyframeStats> stats;  // the batch's rows
  double seconds = 0.0;
  double keyframe_spacing = 0.0;  // of the keyframes s was measured on
};
FinalBatch SculptFinalBatch(const SculptorOptions& base, const IncrementalSculptor& streamed,
                            const std::vector<KeyframeStats>& streamed_stats,
                            const std::vector<SurfaceKeyframe>& keyframes);

// The same final batch without the keyframe-by-keyframe sculpting before it: every keyframe in
// one batch at the s that sculpting would measure on them (MeasureScale of surface/sculptor.h),
// so the surface SculptFinalBatch writes, for the batch's time alone. Not run (sculptor null)
// when no s is measured or the keyframes fit in the first batch (SculptFinalBatch would not run).
FinalBatch SculptBatchOnly(const SculptorOptions& base,
                           const std::vector<SurfaceKeyframe>& keyframes);

// KeyframeStatsCsvHeader() and the pipeline's columns (queue_ms).
std::string PipelineKeyframesCsvHeader();
std::string PipelineKeyframesCsvRow(const PipelineKeyframeRow& row);

}  // namespace omni
