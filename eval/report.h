#pragma once
// `omnisculpt eval`: a reconstruction folder against a drive's ground truth, written as
// eval.json (every number), report.md (a table against the paper's figures), gnuplot plots and
// renders.

#include <filesystem>
#include <limits>
#include <string>
#include <vector>

#include "calib/mesh_check.h"
#include "eval/pose_eval.h"
#include "eval/render.h"
#include "eval/surface_eval.h"

namespace omni {

struct EvalOptions {
  PoseEvalOptions poses;
  RayErrorOptions ray_errors;
  SurfaceCompareOptions surfaces;
  RenderOptions render;
  bool plots = true;           // gnuplot; skipped with a warning when gnuplot is missing
  bool closed_surface = true;  // also evaluate REC/surface_closed.ply when it exists
  bool renders = true;
  int render_width = 800;           // bird's-eye views
  int keyframe_views = 3;           // keyframes rendered from the estimate and the ground truth
  std::string gnuplot = "gnuplot";  // the program

  std::string Check() const;
};

// A loop closure of `omnisculpt reconstruct` (OUT/reconstruct.json, "loop_closures").
struct EvalLoopClosure {
  int keyframe = -1, frame = -1;                      // the revisit
  int candidate_keyframe = -1, candidate_frame = -1;  // the place seen before
  int inliers = 0;                                    // of the 3-D similarity
  int relative_inliers = 0;  // of the relative pose from the 2-D matches (0: not in the file)
  double translation = 0.0;  // how far the revisiting keyframe moved, map units
  double rotation_deg = std::numeric_limits<double>::quiet_NaN();  // NaN: not in the file
  double scale = 1.0;
  double ms = 0.0;  // detection, correction and global adjustment
  double replay_seconds = std::numeric_limits<double>::quiet_NaN();  // surface replay after it
};

// Whole-pipeline figures of `omnisculpt reconstruct`, from OUT/reconstruct.json and
// OUT/stats/keyframes.csv when they exist. NaN: not given.
struct EvalPipeline {
  bool present = false;  // OUT/reconstruct.json was read
  long frames = 0, keyframes = 0;
  double seconds = std::numeric_limits<double>::quiet_NaN();
  double frames_per_second = std::numeric_limits<double>::quiet_NaN();
  bool loop_closure_enabled = false;
  std::vector<EvalLoopClosure> loop_closures;
  double surface_replay_seconds = std::numeric_limits<double>::quiet_NaN();
  // Surface time per keyframe (ms_total) as sculpted while the drive was read: the non-batch
  // rows of stats/keyframes.csv whose keyframe appears there for the first time (a replay after
  // a loop closure repeats earlier keyframes); reconstruct.json's figures otherwise.
  long surface_keyframes = 0;
  double surface_ms_median = std::numeric_limits<double>::quiet_NaN();
  double surface_ms_p95 = std::numeric_limits<double>::quiet_NaN();
  std::string surface_ms_source;  // "stats/keyframes.csv", "reconstruct.json" or empty
};

// Reads REC/reconstruct.json (absent: present = false) and REC/stats/keyframes.csv. Throws
// InputError naming the file when reconstruct.json is malformed.
EvalPipeline ReadEvalPipeline(const std::filesystem::path& rec);

struct EvalSummary {
  PoseEvalResult poses;
  RayErrorResult ray_errors;
  SurfaceCompareResult surfaces;
  PointDistanceResult points;
  bool has_points = false;
  EvalPipeline pipeline;
  MeshCheckReport estimated_mesh;
  MeshCheckReport gt_mesh;
  // REC/surface_closed.ply (the closed δO beside the observed surface.ply), when it exists and
  // EvalOptions::closed_surface: the same ray-traced and surface-against-surface figures, and
  // its mesh check (a closed oriented 2-manifold expected).
  bool has_closed = false;
  RayErrorResult closed_ray_errors;
  SurfaceCompareResult closed_surfaces;
  MeshCheckReport closed_mesh;
  std::vector<std::string> warnings;
  std::vector<std::string> images;  // written, relative to the report folder
};

// Reads DRIVE/rig.json, DRIVE/gt/poses.tum, DRIVE/gt/mesh.ply, OUT/poses.tum, OUT/surface.ply,
// OUT/surface_closed.ply, OUT/points.ply and OUT/stats/keyframes.csv (the last three optional),
// and writes the report into
// report_dir (created). Throws InputError on missing or mismatched inputs.
EvalSummary RunEvaluation(const std::filesystem::path& drive, const std::filesystem::path& rec,
                          const std::filesystem::path& report_dir, const EvalOptions& options);

std::string EvalSummaryToJson(const EvalSummary& summary);
std::string EvalSummaryToMarkdown(const EvalSummary& summary);

}  // namespace omni
