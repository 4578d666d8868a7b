#pragma once
// `omnisculpt eval`: a reconstruction folder against a drive's ground truth, written as
// eval.json (every number), report.md (a table against the paper's figures), gnuplot plots and
// renders (DESIGN.md §7, issue 5).

#include <filesystem>
#include <string>

#include "apps/eval/mesh_check.h"
#include "apps/eval/pose_eval.h"
#include "apps/eval/render.h"
#include "apps/eval/surface_eval.h"

namespace omni {

struct EvalOptions {
  PoseEvalOptions poses;
  RayErrorOptions ray_errors;
  SurfaceCompareOptions surfaces;
  RenderOptions render;
  bool plots = true;  // gnuplot; skipped with a warning when gnuplot is missing
  bool renders = true;
  int render_width = 800;           // bird's-eye views
  int keyframe_views = 3;           // keyframes rendered from the estimate and the ground truth
  std::string gnuplot = "gnuplot";  // the program

  std::string Check() const;
};

struct EvalSummary {
  PoseEvalResult poses;
  RayErrorResult ray_errors;
  SurfaceCompareResult surfaces;
  PointDistanceResult points;
  bool has_points = false;
  MeshCheckReport estimated_mesh;
  MeshCheckReport gt_mesh;
  std::vector<std::string> warnings;
  std::vector<std::string> images;  // written, relative to the report folder
};

// Reads DRIVE/rig.json, DRIVE/gt/poses.tum, DRIVE/gt/mesh.ply, OUT/poses.tum, OUT/surface.ply,
// OUT/points.ply (optional) and OUT/stats/keyframes.csv (optional), and writes the report into
// report_dir (created). Throws InputError on missing or mismatched inputs.
EvalSummary RunEvaluation(const std::filesystem::path& drive, const std::filesystem::path& rec,
                          const std::filesystem::path& report_dir, const EvalOptions& options);

std::string EvalSummaryToJson(const EvalSummary& summary);
std::string EvalSummaryToMarkdown(const EvalSummary& summary);

}  // namespace omni
