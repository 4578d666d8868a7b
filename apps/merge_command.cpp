// `omnisculpt merge REC... --out CITY`: reconstructions of segments of drives (made apart, e.g.
// one cluster task each with `reconstruct --frames A:B`) aligned, merged and sculpted again
// (pipeline/merge.h, docs/design.md §12). CITY has the layout of a reconstruction (poses.tum and
// frame_poses.tum of its drive, or drives/<label>/ for several, points.ply, sparse/, surface.ply,
// surface_closed.ply, stats/keyframes.csv) and merge.json, written last: what was aligned with
// what, the inliers and corrections, what is missing and why.

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "apps/commands.h"
#include "apps/output_folder.h"
#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "pipeline/colmap_keyframes.h"
#include "pipeline/merge.h"
#include "pipeline/point_colors.h"
#include "pipeline/reconstruction.h"
#include "surface/sculptor.h"

namespace omni {
namespace {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

// The frame points of a model's frame_rays.txt (tracks between keyframes, for the surface).
size_t FramePoints(const ColmapModel& model) {
  return static_cast<size_t>(
      std::count_if(model.frame_rays.begin(), model.frame_rays.end(),
                    [](const ColmapFrameRayPoint& line) { return line.point3d_id == 0; }));
}

SculptorOptions MergeSculptor() {
  SculptorOptions sculptor;
  sculptor.uncertain_ray_margin_deg = PipelineOptions::DefaultSculptor().uncertain_ray_margin_deg;
  return sculptor;
}

struct MergeCommandOptions {
  std::vector<std::string> inputs;
  std::string out;
  bool force = false;
  MergeOptions merge;
  std::string enclosing = EnclosingName(SculptorOptions().enclosing);
  // The SfM's points, sculpted as `reconstruct` sculpts them at the end: the rays of the points
  // the aperture bound drops carve short of them, and (--final-batch, on unless
  // --no-final-batch) the surface written is every keyframe sculpted again in one batch after
  // the keyframe-by-keyframe sculpting (SculptFinalBatch). docs/figures.md F66.
  SculptorOptions sculptor = MergeSculptor();
  bool final_batch = true;
};

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

nlohmann::json Sim3Json(const Sim3d& s) {
  return {{"scale", s.scale},
          {"rotation_deg",
           2.0 * std::atan2(s.rotation.vec().norm(), std::abs(s.rotation.w())) * 180.0 / M_PI},
          {"translation", {s.translation.x(), s.translation.y(), s.translation.z()}},
          {"quaternion_wxyz", {s.rotation.w(), s.rotation.x(), s.rotation.y(), s.rotation.z()}}};
}

// The q-quantile of v, null when v is empty.
nlohmann::json Quantile(std::vector<double> v, double q) {
  if (v.empty()) return nullptr;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

void RunMerge(MergeCommandOptions& o, const GlobalOptions& global) {
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  ApplyEnclosingOption(o.enclosing, &o.sculptor);
  ThrowIfInvalid(o.merge.Check(), "MergeOptions");
  ThrowIfInvalid(o.sculptor.Check(), "SculptorOptions");
  const auto start = Clock::now();

  // The inputs; those that are not complete, usable reconstructions are listed, not merged.
  std::vector<MergeSegment> segments;
  nlohmann::json missing = nlohmann::json::array();
  std::string missing_text;
  for (const std::string& input : o.inputs) {
    std::string why;
    std::optional<MergeSegment> segment = LoadMergeSegment(fs::path(input), &why);
    if (segment) {
      spdlog::info("merge: {}: frames {} to {}, {} keyframes, {} points ({})", input,
                   segment->first_frame, segment->last_frame, segment->keyframe_poses.size(),
                   segment->model.points.size(), segment->drive);
      segments.push_back(std::move(*segment));
    } else {
      spdlog::warn("merge: {}: {}; left out", input, why);
      missing.push_back({{"folder", input}, {"why", why}});
      missing_text += (missing_text.empty() ? "" : "; ") + input + ": " + why;
    }
  }
  if (segments.empty())
    throw InputError(o.inputs.empty() ? std::string() : o.inputs.front(), "",
                     "no reconstruction to merge (" + missing_text + ")");
  const double load_seconds = SecondsSince(start);

  OutputFolder folder(fs::path(o.out), "merge.json", o.force, "merge");
  const fs::path out = folder.path();
  const auto align_start = Clock::now();
  MergeResult merged = MergeSegments(segments, o.merge);
  const double align_seconds = SecondsSince(align_start);
  // The segments' frame rays are in the merged model now: their memory goes before the surface's.
  std::vector<size_t> input_frame_points;
  for (MergeSegment& segment : segments) {
    input_frame_points.push_back(FramePoints(segment.model));
    std::vector<ColmapFrameRayPoint>().swap(segment.model.frame_rays);
  }
  size_t segments_merged = 0;
  for (size_t s = 0; s < segments.size(); ++s) {
    if (merged.merged[s]) {
      ++segments_merged;
    } else {
      spdlog::warn("merge: {} not merged: {}", segments[s].folder.string(),
                   merged.not_merged_why[s]);
    }
  }

  // The merged map's files.
  WriteColmapModel(merged.model, out / "sparse");
  // points.ply: the map's points, then the frame points (as `reconstruct` writes it).
  PointCloud cloud;
  for (const ColmapPoint3D& point : merged.model.points) {
    if (point.track.empty()) continue;
    cloud.points.push_back(point.xyz);
    cloud.colors.push_back(point.color);
  }
  const size_t map_points = cloud.points.size();
  const size_t frame_points = FramePoints(merged.model);
  for (const ColmapFrameRayPoint& line : merged.model.frame_rays) {
    if (line.point3d_id != 0) continue;
    cloud.points.push_back(line.xyz);
    cloud.colors.push_back(line.color);
  }
  WritePlyPoints(cloud, out / "points.ply");
  for (const MergedDrive& drive : merged.drives) {
    const fs::path poses_folder = merged.drives.size() == 1 ? out : out / "drives" / drive.label;
    fs::create_directories(poses_folder);
    WriteTum(drive.keyframes, poses_folder / "poses.tum");
    WriteTum(drive.frames, poses_folder / "frame_poses.tum");
  }

  // The surface of the merged map, sculpted keyframe by keyframe in drive and frame order.
  const auto surface_start = Clock::now();
  std::unordered_map<PointId, Rgb8> point_colors;
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  const std::vector<SurfaceKeyframe> stream = ColmapKeyframes(merged.model, &point_colors, &up);
  std::vector<ColmapFrameRayPoint>().swap(merged.model.frame_rays);  // in the stream now
  o.sculptor.up = up;
  o.sculptor.pixel_angle = ColmapFinestPixelAngle(merged.model);
  // With the final batch (the default) only that batch is sculpted: the keyframe-by-keyframe
  // surface before it would not be written (SculptBatchOnly).
  FinalBatch batch = o.final_batch ? SculptBatchOnly(o.sculptor, stream) : FinalBatch{};
  std::unique_ptr<IncrementalSculptor> sculptor;
  std::vector<KeyframeStats> stats = batch.stats;
  if (!batch.sculptor) {
    sculptor = std::make_unique<IncrementalSculptor>(o.sculptor);
    for (size_t i = 0; i < stream.size(); ++i) {
      const std::vector<KeyframeStats> new_stats = sculptor->AddKeyframe(stream[i]);
      stats.insert(stats.end(), new_stats.begin(), new_stats.end());
      if (!global.quiet && (i + 1) % 100 == 0)
        spdlog::info("merge: surface, keyframe {}/{}", i + 1, stream.size());
    }
    const std::vector<KeyframeStats> last_stats = sculptor->Finish();
    stats.insert(stats.end(), last_stats.begin(), last_stats.end());
  }
  ColoredSurfaces surfaces =
      ExtractColoredSurfaces(batch.sculptor ? *batch.sculptor : *sculptor, point_colors);
  const TriangleMesh& closed = surfaces.closed;
  const TriangleMesh& mesh = surfaces.observed;
  if (!closed.triangles.empty()) {
    WritePlyMesh(mesh, out / "surface.ply");
    WritePlyMesh(closed, out / "surface_closed.ply");
  }
  fs::create_directories(out / "stats");
  std::ostringstream csv;
  csv << KeyframeStatsCsvHeader() << "\n";
  std::vector<double> surface_ms;
  for (const KeyframeStats& st : stats) {
    csv << KeyframeStatsCsvRow(st) << "\n";
    if (!st.batch) surface_ms.push_back(MsPerKeyframe(st));
  }
  WriteTextFileAtomically(out / "stats" / "keyframes.csv", csv.str());
  const double surface_seconds = SecondsSince(surface_start);
  size_t uncertain_rays = 0;  // of the surface written
  for (const KeyframeStats& st : stats) uncertain_rays += st.rays_uncertain;
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  bounded.allow_empty = !closed.triangles.empty();
  const MeshCheckReport manifold = CheckMesh(mesh, bounded);
  const MeshCheckReport closed_manifold = CheckMesh(closed);

  // merge.json, last.
  nlohmann::json inputs = nlohmann::json::array();
  for (size_t s = 0; s < segments.size(); ++s) {
    nlohmann::json input = {{"folder", segments[s].folder.string()},
                            {"drive", segments[s].drive},
                            {"mode", segments[s].mode},
                            {"first_frame", segments[s].first_frame},
                            {"last_frame", segments[s].last_frame},
                            {"keyframes", segments[s].keyframe_poses.size()},
                            {"frames_tracked", segments[s].frame_poses.size()},
                            {"points", segments[s].model.points.size()},
                            {"frame_points", input_frame_points[s]},
                            {"merged", bool(merged.merged[s])}};
    if (merged.merged[s]) {
      input["city_from_segment"] = Sim3Json(merged.city_from_segment[s]);
      input["fixed"] = static_cast<int>(s) == merged.fixed_segment;
    } else {
      input["why"] = merged.not_merged_why[s];
    }
    inputs.push_back(input);
  }
  nlohmann::json overlaps = nlohmann::json::array();
  for (const MergeOverlap& overlap : merged.overlaps) {
    nlohmann::json entry = {{"a", segments[overlap.a].folder.string()},
                            {"b", segments[overlap.b].folder.string()},
                            {"kind", overlap.kind},
                            {"shared_frames", overlap.shared_frames},
                            {"inliers", overlap.inliers},
                            {"rms_rotation_deg", overlap.rms_rotation_deg},
                            {"rms_centre", overlap.rms_centre},
                            {"a_from_b", Sim3Json(overlap.a_from_b)},
                            {"verified", overlap.verified}};
    if (overlap.kind == "revisit") {
      entry["frame_a"] = overlap.frame_a;
      entry["frame_b"] = overlap.frame_b;
      entry["appearance_score"] = overlap.score;
      entry["matches"] = overlap.matches;
      entry["points_fused"] = overlap.point_pairs.size();
    }
    if (!overlap.verified) entry["refusal"] = overlap.refusal;
    overlaps.push_back(entry);
  }
  nlohmann::json drives = nlohmann::json::array();
  for (const MergedDrive& drive : merged.drives)
    drives.push_back({{"label", drive.label},
                      {"folder", drive.folder},
                      {"keyframes", drive.keyframes.size()},
                      {"frames", drive.frames.size()}});
  const bool complete = missing.empty() && segments_merged == segments.size();
  std::string failure;
  if (closed.triangles.empty()) failure = "the surface of the merged map is empty";
  const nlohmann::json summary = {
      {"status", !failure.empty() ? "not_usable"
                 : complete       ? "usable"
                                  : "partial"},
      {"outcome", !failure.empty() ? failure
                  : complete       ? "every input merged"
                                   : std::to_string(segments_merged) + " of " +
                                   std::to_string(o.inputs.size()) + " inputs merged"},
      {"inputs", inputs},
      {"missing", missing},
      {"overlaps", overlaps},
      {"drives", drives},
      {"pose_graph",
       {{"edges",
         std::count_if(merged.overlaps.begin(), merged.overlaps.end(),
                       [&](const MergeOverlap& x) { return x.verified && merged.merged[x.a]; })},
        {"iterations", merged.pose_graph.num_iterations},
        {"initial_cost", merged.pose_graph.initial_cost},
        {"final_cost", merged.pose_graph.final_cost}}},
      {"global_bundle_adjustment",
       {{"ran", merged.adjusted},
        {"skipped", merged.adjustment_skipped},
        {"iterations", merged.adjustment.num_iterations},
        {"rms_angle_before_deg", merged.adjustment.rms_angle_before * 180.0 / M_PI},
        {"rms_angle_after_deg", merged.adjustment.rms_angle_after * 180.0 / M_PI},
        {"observations_removed", merged.adjustment.removed_observations.size()},
        {"seconds", merged.adjustment_seconds}}},
      {"images", merged.model.images.size()},
      {"shared_images", merged.shared_images},
      {"points_in", merged.input_points},
      {"points", map_points},
      {"points_fused", merged.fused_points},
      {"frame_points", frame_points},
      {"keyframes", stream.size()},
      {"final_batch", {{"ran", batch.sculptor != nullptr}, {"seconds", batch.seconds}}},
      {"uncertain_rays", uncertain_rays},
      {"triangles", mesh.triangles.size()},
      {"manifold", manifold.ok},
      {"closed_triangles", closed.triangles.size()},
      {"closed_manifold", closed_manifold.ok},
      {"surface_ms_median", Quantile(surface_ms, 0.5)},  // null: no keyframe by keyframe
      {"surface_ms_p95", Quantile(surface_ms, 0.95)},
      {"seconds",
       {{"load", load_seconds},
        {"align_and_merge", align_seconds},
        {"surface", surface_seconds},
        {"total", SecondsSince(start)}}},
      {"warnings", WarningsLogged()},
  };
  WriteTextFileAtomically(out / "merge.json", summary.dump(2) + "\n");
  folder.Keep();
  std::printf(
      "merge: %zu of %zu inputs merged (%zu missing, %zu not joined), %zu overlaps verified; "
      "%zu images (%zu shared), %zu points (%zu fused from %zu) and %zu frame points; %zu "
      "keyframes sculpted, %zu "
      "observed triangles of %zu (manifold with boundary %s, closed %s) in %.1f s\n"
      "  wrote %s (merge.json says what was aligned with what)\n",
      segments_merged, o.inputs.size(), missing.size(), segments.size() - segments_merged,
      static_cast<size_t>(std::count_if(merged.overlaps.begin(), merged.overlaps.end(),
                                        [](const MergeOverlap& x) { return x.verified; })),
      merged.model.images.size(), merged.shared_images, map_points, merged.fused_points,
      merged.input_points, frame_points, stream.size(), mesh.triangles.size(),
      closed.triangles.size(), manifold.ok ? "yes" : "NO", closed_manifold.ok ? "yes" : "NO",
      SecondsSince(start), out.c_str());
  if (!failure.empty()) {
    ReportNotUsable(o.out + ": " + failure);
  } else {
    ReportSurfaceChecks("merge", closed_manifold, manifold);
  }
}

}  // namespace

void RegisterMergeCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<MergeCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "merge",
      "Merge reconstructions of segments of drives (reconstruct --frames A:B) into one map: "
      "aligned on their shared frames and the places they revisit in one pose graph, duplicate "
      "points fused, a global bundle adjustment, the surface sculpted again; inputs that are "
      "missing or do not overlap are reported in merge.json");
  command->add_option("reconstructions", o->inputs, "Reconstruction folders (reconstruct --out)")
      ->required();
  command
      ->add_option("--out", o->out,
                   "Output folder (poses.tum, frame_poses.tum, points.ply, sparse/, surface.ply, "
                   "surface_closed.ply, stats/, merge.json)")
      ->required();
  command->add_flag("--force", o->force, "Replace OUT if it holds a previous merge");
  command
      ->add_option("--init-keyframes", o->sculptor.init_keyframes,
                   "Keyframes measuring s and sculpted in the first batch (paper §5.1); the "
                   "later ones one step at a time")
      ->capture_default_str();
  command->add_flag("--final-batch,!--no-final-batch", o->final_batch,
                    "Write a final batch instead of the surface sculpted keyframe by keyframe: "
                    "every keyframe sculpted again at once at the first keyframes' s (the "
                    "default; --no-final-batch: the keyframe-by-keyframe surface)");
  command
      ->add_option("--min-shared-frames", o->merge.min_shared_frames,
                   "An overlap is verified when at least this many shared frames agree with one "
                   "similarity")
      ->capture_default_str();
  command->add_flag("!--no-revisits", o->merge.revisits.enabled,
                    "Align on shared frames only (no place recognition between segments)");
  command->add_flag("!--no-global-ba", o->merge.global_bundle_adjustment,
                    "No global bundle adjustment of the merged map (it runs for the segments "
                    "of one drive)");
  AddEnclosingOptions(command, &o->enclosing, &o->sculptor);
  AddCarvingOptions(command, &o->sculptor);
  AddObservedMeshOptions(command, &o->sculptor.observed);
  command->callback([o, &global] { RunMerge(*o, global); });
}

}  // namespace omni
