// `omnisculpt surface`: the incremental sculptor of surface/ fed by a simulated
// perfect SfM on a drive's ground truth (--from-gt) or by a COLMAP model (--colmap), writing
// surface.ply (the observed surface), surface_closed.ply (δO), points.ply,
// stats/keyframes.csv and surface.json (the run's summary and warnings).

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include "apps/commands.h"
#include "apps/output_folder.h"
#include "calib/atomic_file.h"
#include "calib/colmap_text.h"
#include "calib/drive.h"
#include "calib/error.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "pipeline/colmap_keyframes.h"
#include "pipeline/gt_keyframes.h"
#include "pipeline/point_colors.h"
#include "pipeline/reconstruction.h"
#include "surface/advancing_front.h"
#include "surface/sculptor.h"

namespace omni {
namespace {

struct SurfaceCommandOptions {
  std::string from_gt;
  std::string colmap;        // a COLMAP text model folder
  std::string drive;         // --colmap: the drive of the model's images (rig.json, frames.csv)
  double frame_rate = 15.0;  // --colmap: poses.tum stamps when the drive has no frames.csv
  std::string out;
  bool force = false;
  std::string method = "sculptor";  // or "advancing-front", the baseline on the same points
  std::string af_points = "all";    // advancing-front: all the stream's points, or "sculpted"
  AdvancingFrontOptions advancing_front;
  std::string enclosing = EnclosingName(SculptorOptions().enclosing);
  bool no_batch = false;
  // After the stream, every keyframe sculpted again in one batch at the scale s of the first
  // keyframes, as `reconstruct` does after the SfM's final adjustment; that surface is written.
  // With --colmap (SfM points) on unless --no-final-batch, and with the uncertain rays of
  // `reconstruct` unless --uncertain-ray-margin is given (F66); off with --from-gt (F54).
  bool final_batch = false;
  bool no_genus_refinement = false;  // step 6 (paper §4.6) parts switched off
  bool no_smoothing = false;
  // Write OUT/snapshots/surface_<keyframe>.ply and observed_<keyframe>.ply every K keyframes;
  // 0: none.
  int snapshot_every = 0;
  GtKeyframeOptions gt;
  SculptorOptions sculptor;
};

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

// The rig poses of a COLMAP model's keyframes stamped as `omnisculpt sfm` stamps poses.tum: the
// drive's frames.csv, else the frame's index in the drive / frame_rate.
std::vector<StampedPose> ColmapPosesOnDrive(const ColmapModel& model, const std::string& folder,
                                            double frame_rate) {
  const Drive drive = Drive::Open(folder);
  std::unordered_map<std::string, size_t> frame_of;
  for (size_t frame = 0; frame < drive.NumFrames(); ++frame)
    frame_of[drive.FrameName(frame)] = frame;
  const ColmapRigPoses rig_poses = ColmapKeyframeRigPoses(model, drive.rig());
  std::vector<StampedPose> poses;
  for (const ColmapKeyframePose& pose : rig_poses.keyframes) {
    const auto frame = frame_of.find(pose.frame_name);
    if (frame == frame_of.end()) {
      throw InputError(folder, "--drive",
                       "the model's frame '" + pose.frame_name + "' is not a frame of the drive");
    }
    const double stamp = drive.HasTimestamps() ? drive.FrameTimestamp(frame->second)
                                               : static_cast<double>(frame->second) / frame_rate;
    poses.push_back({stamp, pose.world_from_rig});
  }
  spdlog::info(
      "surface: {} keyframe rig poses from the model ({:.4f} model units per metre of the rig, "
      "from {} camera pairs)",
      poses.size(), rig_poses.model_units_per_metre, rig_poses.camera_pairs);
  if (rig_poses.camera_pairs == 0) {
    spdlog::warn(
        "surface: no frame has two registered images: the rig's offsets are taken in "
        "the model's units");
  }
  return poses;
}

// The points fed to the sculptor (points.ply), coloured when the colours are known.
PointCloud StreamPoints(const std::vector<SurfaceKeyframe>& stream,
                        const std::unordered_map<PointId, Rgb8>& point_colors) {
  PointCloud points;
  for (const SurfaceKeyframe& kf : stream) {
    for (const SurfacePoint& point : kf.points) {
      points.points.push_back(point.position);
      if (point_colors.empty()) continue;
      const auto color = point_colors.find(point.id);
      points.colors.push_back(color != point_colors.end() ? color->second : Rgb8(128, 128, 128));
    }
  }
  return points;
}

// --method advancing-front: CGAL's advancing front surface of every point of the stream (no ray,
// no filter of the sculptor) or of those the sculptor inserts (--af-points sculpted), written as
// surface.ply with points.ply, poses.tum and surface.json, a folder `omnisculpt eval` reads (no
// surface_closed.ply: the mesh has a boundary).
void WriteAdvancingFrontSurface(const SurfaceCommandOptions& o,
                                const std::vector<SurfaceKeyframe>& stream,
                                const std::unordered_map<PointId, Rgb8>& point_colors,
                                const std::vector<StampedPose>& keyframe_poses,
                                std::chrono::steady_clock::time_point start) {
  const std::filesystem::path out(o.out);
  OutputFolder folder(out, "surface.json", o.force, "surface");
  // An earlier sculptor output replaced (--force): no closed surface of another method is left.
  std::filesystem::remove(out / "surface_closed.ply");
  std::filesystem::remove(out / "stats" / "keyframes.csv");
  PointCloud points = StreamPoints(stream, point_colors);
  double sculptor_s = 0.0;
  if (o.af_points == "sculpted") {
    // The points the sculptor inserts: after its §5.1 filters and its free-space rejection.
    const auto sculptor_start = std::chrono::steady_clock::now();
    IncrementalSculptor sculptor(o.sculptor);
    for (const SurfaceKeyframe& kf : stream) sculptor.AddKeyframe(kf);
    sculptor.Finish();
    const std::vector<PointId> inserted = sculptor.InsertedPoints();
    const std::unordered_set<PointId> kept(inserted.begin(), inserted.end());
    PointCloud sculpted;
    size_t index = 0;
    for (const SurfaceKeyframe& kf : stream) {
      for (const SurfacePoint& point : kf.points) {
        if (kept.count(point.id) != 0) {
          sculpted.points.push_back(points.points[index]);
          if (!points.colors.empty()) sculpted.colors.push_back(points.colors[index]);
        }
        ++index;
      }
    }
    points = std::move(sculpted);
    sculptor_s =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - sculptor_start).count();
    spdlog::info("surface: {} points inserted by the sculptor ({:.1f} s)", points.points.size(),
                 sculptor_s);
  }
  const auto mesh_start = std::chrono::steady_clock::now();
  std::vector<size_t> input_of_vertex;
  TriangleMesh mesh = AdvancingFrontSurface(points.points, o.advancing_front, &input_of_vertex);
  const double mesh_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - mesh_start).count();
  if (!points.colors.empty()) {
    for (size_t input : input_of_vertex) mesh.colors.push_back(points.colors[input]);
  }
  WritePlyMesh(mesh, out / "surface.ply");
  WritePlyPoints(points, out / "points.ply");
  if (!keyframe_poses.empty()) WriteTum(keyframe_poses, out / "poses.tum");
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  const MeshCheckReport report = CheckMesh(mesh, bounded);
  const double total_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf(
      "surface: advancing front (beta %.2f, max edge %.3f) of %zu points (%s): %zu "
      "triangles on %zu vertices in %ld boundary loops, manifold with boundary %s (%.2f s, "
      "%.2f s in all)\n  wrote %s\n",
      o.advancing_front.beta, o.advancing_front.max_edge, points.points.size(), o.af_points.c_str(),
      mesh.triangles.size(), mesh.vertices.size(), report.boundary_loops, report.ok ? "yes" : "NO",
      mesh_s, total_s, (out / "surface.ply").c_str());
  const nlohmann::json summary = {
      {"input", o.colmap.empty() ? o.from_gt : o.colmap},
      {"source", o.colmap.empty() ? "ground truth" : "colmap"},
      {"method", "advancing-front"},
      {"status", mesh.triangles.empty() ? "not_usable" : "usable"},
      {"keyframes", stream.size()},
      {"points", points.points.size()},
      {"triangles", mesh.triangles.size()},
      {"vertices", mesh.vertices.size()},
      {"manifold", report.ok},
      {"boundary_loops", report.boundary_loops},
      {"max_edge", o.advancing_front.max_edge},
      {"points_from", o.af_points},
      {"sculptor_seconds", sculptor_s},
      {"beta", o.advancing_front.beta},
      {"mesh_seconds", mesh_s},
      {"seconds", total_s},
      {"warnings", WarningsLogged()},
  };
  WriteTextFileAtomically(out / "surface.json", summary.dump(2) + "\n");
  folder.Keep();
  if (mesh.triangles.empty()) {
    ReportNotUsable((o.colmap.empty() ? o.from_gt : o.colmap) +
                    ": the advancing front surface is empty (" +
                    std::to_string(points.points.size()) + " points)");
  }
}

void RunSurface(SurfaceCommandOptions& o, const GlobalOptions& global) {
  if (o.from_gt.empty() == o.colmap.empty()) {
    throw InputError("", "--from-gt/--colmap", "exactly one input is required");
  }
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  if (!o.drive.empty() && o.colmap.empty()) throw InputError("", "--drive", "needs --colmap");
  if (!(o.frame_rate > 0.0)) throw InputError("", "--frame-rate", "must be > 0");
  ApplyEnclosingOption(o.enclosing, &o.sculptor);
  o.sculptor.batch_init = !o.no_batch;
  if (o.no_genus_refinement) o.sculptor.genus.enabled = false;
  if (o.no_smoothing) o.sculptor.smoothing.enabled = false;
  if (o.snapshot_every < 0) throw InputError("", "--snapshot-every", "must be >= 0");
  if (o.method != "sculptor" && o.method != "advancing-front") {
    throw InputError("", "--method",
                     "expected sculptor or advancing-front, got '" + o.method + "'");
  }
  ThrowIfInvalid(o.advancing_front.Check(), "AdvancingFrontOptions");
  if (o.af_points != "all" && o.af_points != "sculpted") {
    throw InputError("", "--af-points", "expected all or sculpted, got '" + o.af_points + "'");
  }
  ThrowIfInvalid(o.sculptor.Check(), "SculptorOptions");
  ThrowIfInvalid(o.gt.Check(), "GtKeyframeOptions");
  const auto start = std::chrono::steady_clock::now();
  std::vector<StampedPose> keyframe_poses;  // known for --from-gt only
  std::vector<size_t> keyframe_frames;      // known for --from-gt only
  std::unordered_map<PointId, Rgb8> point_colors;
  Eigen::Vector3d colmap_up = Eigen::Vector3d::UnitZ();
  double model_pixel_angle = 0.0;
  std::vector<SurfaceKeyframe> stream;
  if (o.colmap.empty()) {
    stream = LoadGtKeyframes(o.from_gt, o.gt, nullptr, &keyframe_poses, &keyframe_frames);
  } else {
    const ColmapModel model = ReadColmapModel(o.colmap);
    stream = ColmapKeyframes(model, &point_colors, &colmap_up);
    model_pixel_angle = ColmapFinestPixelAngle(model);
    if (!o.drive.empty()) keyframe_poses = ColmapPosesOnDrive(model, o.drive, o.frame_rate);
  }
  if (o.colmap.empty()) point_colors = GtPointColors(o.from_gt, stream, keyframe_frames);
  o.sculptor.pixel_angle =
      o.colmap.empty() ? Drive::Open(o.from_gt).rig().FinestPixelAngle() : model_pixel_angle;
  // A COLMAP world has no up axis: the ground filter's up from its cameras.
  if (!o.colmap.empty()) {
    o.sculptor.up = colmap_up;
    spdlog::info("surface: up direction from the model's cameras ({:.3f}, {:.3f}, {:.3f})",
                 colmap_up.x(), colmap_up.y(), colmap_up.z());
  }
  const double gen_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  size_t num_points = 0;
  for (const auto& kf : stream) num_points += kf.points.size();
  spdlog::info(
      "surface: {} keyframes, {} points from {} ({:.1f} s)", stream.size(), num_points,
      o.colmap.empty() ? "the ground truth of " + o.from_gt : "the COLMAP model " + o.colmap,
      gen_s);

  const std::filesystem::path out(o.out);
  if (o.method == "advancing-front") {
    WriteAdvancingFrontSurface(o, stream, point_colors, keyframe_poses, start);
    return;
  }
  OutputFolder folder(out, "stats/keyframes.csv", o.force, "surface");
  IncrementalSculptor sculptor(o.sculptor);
  std::vector<KeyframeStats> stats;
  size_t processed = 0;  // keyframes sculpted so far (a batch counts its keyframes)
  // After each call: a snapshot when a multiple of K keyframes was passed (only the state after
  // the call exists, so a batch gives one snapshot, named after its last keyframe).
  auto snapshot = [&](const std::vector<KeyframeStats>& new_stats) {
    stats.insert(stats.end(), new_stats.begin(), new_stats.end());
    const size_t before = processed;
    processed = sculptor.NumProcessedKeyframes();
    const size_t k = static_cast<size_t>(o.snapshot_every);
    if (k == 0 || new_stats.empty() || processed / k == before / k) return;
    std::filesystem::create_directories(out / "snapshots");
    // The closed δO and its observed part, coloured as surface.ply.
    const ColoredSurfaces surfaces = ExtractColoredSurfaces(sculptor, point_colors);
    const std::string keyframe = std::to_string(new_stats.back().keyframe.value);
    WritePlyMesh(surfaces.closed, out / "snapshots" / ("surface_" + keyframe + ".ply"));
    WritePlyMesh(surfaces.observed, out / "snapshots" / ("observed_" + keyframe + ".ply"));
  };
  // --final-batch: every keyframe sculpted again in one batch; its surface is the one written.
  // On a COLMAP model without snapshots the batch alone (SculptBatchOnly, as `merge`): the
  // keyframe-by-keyframe sculpting would give only its rows of stats/keyframes.csv. With
  // --from-gt it runs first (SculptFinalBatch): its times per keyframe are the measure.
  FinalBatch batch = o.final_batch && !o.colmap.empty() && o.snapshot_every == 0
                         ? SculptBatchOnly(o.sculptor, stream)
                         : FinalBatch{};
  const bool batch_only = batch.sculptor != nullptr;
  if (batch_only) {
    stats = batch.stats;
  } else {
    for (size_t i = 0; i < stream.size(); ++i) {
      snapshot(sculptor.AddKeyframe(stream[i]));
      if (!global.quiet && (i + 1) % 50 == 0) {
        spdlog::info("surface: keyframe {}/{}", i + 1, stream.size());
      }
    }
    snapshot(sculptor.Finish());
    if (o.final_batch) batch = SculptFinalBatch(o.sculptor, sculptor, stats, stream);
  }
  const IncrementalSculptor& written = batch.sculptor ? *batch.sculptor : sculptor;
  // The counts of the points of the surface written: the batch's, or the stream's.
  const std::vector<KeyframeStats>& written_stats = batch.sculptor ? batch.stats : stats;
  // s, and the keyframe spacing it was measured from.
  const double scale = batch_only ? written.scale() : sculptor.scale();
  const double spacing = batch_only ? batch.keyframe_spacing : sculptor.keyframe_spacing();

  std::filesystem::create_directories(out / "stats");
  // The closed δO and its observed part, each vertex coloured as its point.
  const ColoredSurfaces surfaces = ExtractColoredSurfaces(written, point_colors);
  const TriangleMesh& closed = surfaces.closed;
  const TriangleMesh& mesh = surfaces.observed;
  const ObservedMeshStats& observed_stats = surfaces.observed_stats;
  WritePlyMesh(mesh, out / "surface.ply");
  WritePlyMesh(closed, out / "surface_closed.ply");
  std::ostringstream csv;
  csv << KeyframeStatsCsvHeader() << "\n";
  for (const KeyframeStats& st : stats) csv << KeyframeStatsCsvRow(st) << "\n";
  WriteTextFileAtomically(out / "stats" / "keyframes.csv", csv.str());
  // The input side of the reconstruction folder (docs/design.md, "Data"), so that `omnisculpt eval`
  // reads it like the pipeline's: the points fed to the sculptor and, from --from-gt, the keyframe
  // poses of the simulated SfM.
  WritePlyPoints(StreamPoints(stream, point_colors), out / "points.ply");
  if (!keyframe_poses.empty()) WriteTum(keyframe_poses, out / "poses.tum");

  // The smoothing that waited for the surface to be taken (SmoothingOptions::every_keyframe
  // off), in the extractions above and the snapshots.
  const IncrementalSculptor::DeferredSmoothing smoothing = written.DeferredSmoothingStats();
  std::vector<double> ms;  // the keyframes sculpted one step at a time (the stream's)
  size_t max_e = 0, added = 0, rejected = 0;
  for (const KeyframeStats& st : stats) {
    if (!st.batch) ms.push_back(MsPerKeyframe(st));
    max_e = std::max(max_e, st.cells_e);
  }
  for (const KeyframeStats& st : written_stats) {
    added += st.points_added;
    rejected += st.points_rejected;
  }
  size_t filtered[4] = {0, 0, 0, 0};
  size_t uncertain_rays = 0;
  for (const KeyframeStats& st : written_stats) {
    filtered[0] += st.points_invalid;
    filtered[1] += st.points_filtered_ground;
    filtered[2] += st.points_filtered_length;
    filtered[3] += st.points_filtered_aperture;
    uncertain_rays += st.rays_uncertain;
  }
  std::printf(
      "surface: s = %.3f (keyframe spacing %.3f), r = %.2f, ground bound %.2f; points filtered "
      "(paper §5.1): %zu invalid, %zu below the ground, %zu too far, %zu narrow aperture (%zu "
      "of their rays carve short of them)\n",
      scale, spacing, written.ray_length_bound(), written.ground_bound(), filtered[0], filtered[1],
      filtered[2], filtered[3], uncertain_rays);
  if (batch.sculptor) {
    std::printf(
        "surface: the final batch of all %zu keyframes at that s: %.2f s (the surface "
        "written)\n",
        stream.size(), batch.seconds);
  }
  const MeshCheckReport closed_report = CheckMesh(closed);
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  bounded.allow_empty = !closed.triangles.empty();
  const MeshCheckReport report = CheckMesh(mesh, bounded);
  std::printf(
      "surface: %zu keyframes, %zu points added, %zu rejected (%.2f%%), %zu triangles of δO, "
      "closed manifold %s\n"
      "  observed: %zu triangles in %ld boundary loops, manifold with boundary %s; left out: "
      "%zu with a Steiner vertex, %zu long, %zu sparse, %zu unseen, %zu around touching "
      "boundaries, %zu in small components; %zu long ones grown back\n"
      "  ms per incremental keyframe%s: median %.1f, p95 %.1f, max %.1f; max |E| %zu; smoothing "
      "when the surface was taken: %.1f ms (%zu vertices)\n"
      "  wrote %s, %s and %s\n",
      stream.size(), added, rejected, 100.0 * rejected / std::max<size_t>(1, added + rejected),
      closed.triangles.size(), closed_report.ok ? "yes" : "NO", mesh.triangles.size(),
      report.boundary_loops, report.ok ? "yes" : "NO", observed_stats.steiner,
      observed_stats.long_edges, observed_stats.sparse, observed_stats.unseen,
      observed_stats.manifold_repair, observed_stats.small_components, observed_stats.grown,
      batch_only ? " (none: the batch alone)" : "", Quantile(ms, 0.5), Quantile(ms, 0.95),
      ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end()), max_e, 1e3 * smoothing.seconds,
      smoothing.vertices, (out / "surface.ply").c_str(), (out / "surface_closed.ply").c_str(),
      (out / "stats" / "keyframes.csv").c_str());
  // The run's summary (docs/errors.md, rule 3: its warnings too), written last.
  const nlohmann::json summary = {
      {"input", o.colmap.empty() ? o.from_gt : o.colmap},
      {"source", o.colmap.empty() ? "ground truth" : "colmap"},
      {"status", closed.triangles.empty() ? "not_usable" : "usable"},
      {"keyframes", stream.size()},
      {"points_added", added},
      {"points_rejected", rejected},
      {"points_invalid", filtered[0]},
      {"points_filtered_ground", filtered[1]},
      {"points_filtered_length", filtered[2]},
      {"points_filtered_aperture", filtered[3]},
      {"uncertain_rays", uncertain_rays},
      {"triangles", mesh.triangles.size()},
      {"manifold", report.ok},
      {"boundary_loops", report.boundary_loops},
      {"closed_triangles", closed.triangles.size()},
      {"closed_manifold", closed_report.ok},
      {"ms_median", ms.empty() ? nlohmann::json() : nlohmann::json(Quantile(ms, 0.5))},
      {"ms_p95", ms.empty() ? nlohmann::json() : nlohmann::json(Quantile(ms, 0.95))},
      {"smoothing",
       {{"every_keyframe", o.sculptor.smoothing.every_keyframe},
        {"at_extraction_runs", smoothing.runs},
        {"at_extraction_vertices", smoothing.vertices},
        {"at_extraction_seconds", smoothing.seconds}}},
      {"max_cells_e", max_e},
      {"final_batch", {{"ran", batch.sculptor != nullptr}, {"seconds", batch.seconds}}},
      {"warnings", WarningsLogged()},
  };
  WriteTextFileAtomically(out / "surface.json", summary.dump(2) + "\n");
  folder.Keep();
  if (closed.triangles.empty()) {
    ReportNotUsable((o.colmap.empty() ? o.from_gt : o.colmap) + ": the surface is empty (" +
                    std::to_string(stream.size()) + " keyframes, " + std::to_string(added) +
                    " points added)");
  } else if (ReportSurfaceChecks("surface", closed_report, report) && mesh.triangles.empty()) {
    spdlog::warn("surface: no triangle of δO is observed: surface.ply is empty");
  }
}

}  // namespace

std::string EnclosingName(EnclosingMode mode) {
  return mode == EnclosingMode::kBall ? "ball" : "conflict";
}

void ApplyEnclosingOption(const std::string& enclosing, SculptorOptions* sculptor) {
  if (enclosing == "ball") {
    sculptor->enclosing = EnclosingMode::kBall;
  } else if (enclosing == "conflict") {
    sculptor->enclosing = EnclosingMode::kConflictZones;
  } else {
    throw InputError("", "--enclosing", "expected ball or conflict, got '" + enclosing + "'");
  }
}

void AddEnclosingOptions(CLI::App* command, std::string* enclosing, SculptorOptions* sculptor) {
  command
      ->add_option("--enclosing", *enclosing,
                   "Enclosing set E: conflict (the default: the new points' conflict zones + "
                   "margin, widened by vertex stars; on the paper drive steps 1-5 1.4-1.8x faster "
                   "than the ball, higher F-scores, fewer errors > 6 m) | ball (paper §4.1, "
                   "B_{r+l} around the keyframe)")
      ->capture_default_str();
  command
      ->add_option("--enclosing-margin", sculptor->enclosing_margin,
                   "conflict E: rings of cells added around the conflict zones")
      ->capture_default_str();
  command
      ->add_option("--enclosing-rounds", sculptor->enclosing_rounds,
                   "conflict E: rounds of widening where O still meets a conflict zone after "
                   "the shrink (0: the fixed margin only)")
      ->capture_default_str();
  command
      ->add_option("--enclosing-star-rings", sculptor->enclosing_star_rings,
                   "conflict E: a widening round adds the cells of O around the vertices of "
                   "the cells still in a conflict zone, this many vertex rings (+1 per round)")
      ->capture_default_str();
  command->add_flag_callback(
      "--ring-widening", [sculptor] { sculptor->enclosing_widening = EnclosingWidening::kRings; },
      "conflict E: widen by facet rings through O (enclosing_round_rings · 2^k) instead of the "
      "vertex stars");
}

void AddCarvingOptions(CLI::App* command, SculptorOptions* sculptor) {
  command
      ->add_option("--keyframes-per-step", sculptor->keyframes_per_step,
                   "Sculpt the keyframes after the first ones this many at a time (their points "
                   "inserted together, their rays traced once); the surface lags by up to this "
                   "many keyframes less one")
      ->capture_default_str();
  command->add_flag("--smooth-every-keyframe", sculptor->smoothing.every_keyframe,
                    "Smooth δO after every keyframe (the paper's incremental smoothing; default: "
                    "once, when the surface is taken at the end or for a snapshot)");
  command
      ->add_option("--smoothing-steps", sculptor->smoothing.taubin_steps,
                   "Taubin λ|μ pairs of the smoothing of δO (0: peak removal only)")
      ->capture_default_str();
  command
      ->add_option("--min-aperture", sculptor->min_aperture_deg,
                   "Aperture filter: keep a point only when two of its rays are more than this "
                   "many degrees apart (its triangulation angle)")
      ->capture_default_str();
  command
      ->add_option("--uncertain-ray-margin", sculptor->uncertain_ray_margin_deg,
                   "The rays of a point the aperture filter drops carve short of it, up to the "
                   "fraction 1 - this / its aperture (degrees; 0: they do not carve; an SfM's "
                   "points, surface --colmap included: 0.1 unless given)")
      ->capture_default_str();
  command
      ->add_option("--min-point-separation", sculptor->min_point_separation_factor,
                   "A point closer than this times s to a vertex is that vertex (0: exact "
                   "duplicates only)")
      ->capture_default_str();
  command
      ->add_option("--min-point-separation-pixels", sculptor->min_point_separation_pixels,
                   "A point is also a vertex less than this many pixels from it, as the "
                   "nearest camera that sees the point sees them (the finest camera's pixel; 0: "
                   "off)")
      ->capture_default_str();
  command->add_flag_callback(
      "--drop-duplicate-rays", [sculptor] { sculptor->duplicate_rays = false; },
      "A point merged into a vertex (--min-point-separation, --min-point-separation-pixels) is "
      "dropped with its rays (default: its rays are traced from that vertex)");
  command
      ->add_option("--reach-quantile", sculptor->reach_quantile,
                   "s is at least the first keyframes' points' distance to their keyframe at "
                   "this quantile (those with a wide aperture) over the ray-length factor 15, so "
                   "that r follows the points' reach and not only the keyframe spacing (0: s is "
                   "the keyframe spacing, the paper)")
      ->capture_default_str();
  command
      ->add_option("--ground-quantile", sculptor->ground_quantile,
                   "The ground filter drops points more than max(3 s, g + s) below their "
                   "keyframe, g the depth of the ground: the first keyframes' points' height at "
                   "this quantile (0: 3 s, the paper)")
      ->capture_default_str();
  command
      ->add_option("--enclosed-free", sculptor->enclosed_free_neighbours,
                   "A cell that no ray crossed with this many of its 4 neighbours crossed joins "
                   "the free space before the growth (0: off; 2, 3 or 4)")
      ->capture_default_str();
  command
      ->add_option("--enclosed-free-rounds", sculptor->enclosed_free_rounds,
                   "--enclosed-free: rounds, each over the neighbours of the cells the last one "
                   "freed")
      ->capture_default_str();
}

void AddObservedMeshOptions(CLI::App* command, ObservedMeshOptions* observed) {
  command
      ->add_option("--observed-max-edge", observed->max_edge_factor,
                   "surface.ply: leave out the triangles of δO with an edge longer than this "
                   "times s (the ceiling over the streets, the caps; 0: no bound)")
      ->capture_default_str();
  command
      ->add_option("--observed-max-edge-angle", observed->max_edge_angle,
                   "surface.ply: keep a triangle whose longest edge subtends at most this angle "
                   "(radians) from the nearest ray centre of its vertices, whatever its length "
                   "(0: off)")
      ->capture_default_str();
  command
      ->add_option("--observed-grow-max-edge", observed->grow_max_edge_factor,
                   "surface.ply: a triangle left out by --observed-max-edge alone comes back "
                   "when it continues a kept neighbour's plane (--observed-grow-angle) and its "
                   "edges are at most this times s (0: off)")
      ->capture_default_str();
  command
      ->add_option("--observed-grow-angle", observed->grow_max_normal_angle,
                   "surface.ply: --observed-grow-max-edge's largest angle between the normals "
                   "of neighbours (radians)")
      ->capture_default_str();
  command
      ->add_option("--observed-max-spacing", observed->max_spacing_factor,
                   "surface.ply: leave out the triangles with an edge longer than this times "
                   "the local point spacing (0: no bound)")
      ->capture_default_str();
  command
      ->add_option("--observed-min-view-cos", observed->min_view_cosine,
                   "surface.ply: a triangle is seen when a ray centre of one of its vertices is "
                   "in front of it at a cosine above this")
      ->capture_default_str();
  command->add_flag_callback(
      "--observed-keep-unseen", [observed] { observed->require_seen = false; },
      "surface.ply: keep the triangles that no ray centre of their vertices sees from the front");
  command
      ->add_option("--observed-min-component", observed->min_component_triangles,
                   "surface.ply: leave out the components with fewer triangles (0: none)")
      ->capture_default_str();
}

void RegisterSurfaceCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<SurfaceCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "surface",
      "Incremental 2-manifold surface (Litvinov & Lhuillier 2013) from a keyframe stream; "
      "--from-gt simulates a perfect SfM on a drive's ground truth");
  command->add_option("--from-gt", o->from_gt,
                      "Drive folder with rig.json, gt/poses.tum, gt/mesh.ply");
  command->add_option("--colmap", o->colmap,
                      "COLMAP text model folder (cameras.txt, images.txt, points3D.txt); images "
                      "sharing a file name in different folders form one rig keyframe");
  command->add_option("--drive", o->drive,
                      "--colmap: the drive of the model's images (rig.json, frames.csv): write "
                      "the keyframes' rig poses to poses.tum as `omnisculpt sfm` does, so that "
                      "`omnisculpt eval` reads the folder");
  command
      ->add_option("--frame-rate", o->frame_rate,
                   "--colmap --drive: poses.tum stamps (frame index / rate) when the drive has "
                   "no frames.csv")
      ->capture_default_str();
  command->add_option(
      "--out", o->out,
      "Output folder (surface.ply, surface_closed.ply, points.ply, poses.tum with --from-gt or "
      "--colmap --drive, stats/keyframes.csv), new or empty");
  command->add_flag("--force", o->force,
                    "Write into --out if it holds an earlier surface output (stats/keyframes.csv, "
                    "or surface.json for --method advancing-front)");
  command
      ->add_option("--method", o->method,
                   "sculptor (the incremental 2-manifold of the rays) | advancing-front (a "
                   "baseline: CGAL's advancing front surface of the same points, every point of "
                   "the input, no ray and no filter; surface.ply only)")
      ->capture_default_str();
  command
      ->add_option("--af-points", o->af_points,
                   "advancing-front: all (every point of the input) | sculpted (only those the "
                   "sculptor inserts: after its filters and its free-space rejection; the "
                   "sculptor runs first, its surface is not written)")
      ->capture_default_str();
  command
      ->add_option("--af-max-edge", o->advancing_front.max_edge,
                   "advancing-front: never take a facet with an edge longer than this, in the "
                   "model's units (0: no bound)")
      ->capture_default_str();
  command
      ->add_option("--af-beta", o->advancing_front.beta,
                   "advancing-front: largest angle (radians) between a candidate facet and its "
                   "neighbour on the front")
      ->capture_default_str();
  AddEnclosingOptions(command, &o->enclosing, &o->sculptor);
  AddObservedMeshOptions(command, &o->sculptor.observed);
  AddCarvingOptions(command, &o->sculptor);
  command
      ->add_option("--grow-closure-rounds", o->sculptor.grow_closure_rounds,
                   "conflict E: rounds of growth over the free cells around the vertices whose "
                   "surface changed in the keyframe (0: E, N and the new rays' cells only)")
      ->capture_default_str();
  command->add_flag_callback(
      "--untargeted-shrink", [o] { o->sculptor.targeted_shrink = false; },
      "conflict E: the several-at-once shrink tries the vertices of all of O ∩ E, not only "
      "those of the cells of O in a conflict zone");
  command->add_flag_callback(
      "--reference-manifold-tests", [o] { o->sculptor.reference_manifold_tests = true; },
      "Steps 2 and 5 without the memos of failed manifold tests and the star counts (the test "
      "reference: the same surface, slower)");
  command
      ->add_option("--ray-grid-step", o->sculptor.ray_grid_step_factor,
                   "Voxel side of the grid of old rays (paper §4.4), in units of s")
      ->capture_default_str();
  CLI::Option* final_batch = command->add_flag(
      "--final-batch,!--no-final-batch", o->final_batch,
      "Write a final batch instead of the surface sculpted keyframe by keyframe: every keyframe "
      "sculpted again at once at the first keyframes' s (as reconstruct after its final "
      "adjustment); the default with --colmap, not with --from-gt");
  command->add_flag("--no-batch", o->no_batch,
                    "Sculpt the first keyframes one by one instead of in one batch (§5.1)");
  command->add_flag("--no-genus-refinement", o->no_genus_refinement,
                    "Skip the genus refinement of step 6 (paper §4.6)");
  command->add_flag("--no-smoothing", o->no_smoothing,
                    "Skip the incremental smoothing of step 6 (paper §4.6): the surface keeps "
                    "the Delaunay vertices' positions");
  command
      ->add_option("--init-keyframes", o->sculptor.init_keyframes,
                   "Keyframes measuring s (and sculpted in batch), paper §5.1")
      ->capture_default_str();
  command->add_option("--keyframe-spacing", o->gt.keyframe_spacing, "Metres between keyframes")
      ->capture_default_str();
  command->add_option("--points-per-keyframe", o->gt.points_per_keyframe, "New points per keyframe")
      ->capture_default_str();
  command
      ->add_option("--max-point-distance-factor", o->gt.max_distance_factor,
                   "--from-gt: largest point–keyframe distance, in units of --keyframe-spacing")
      ->capture_default_str();
  command->add_option("--max-keyframes", o->gt.max_keyframes, "0: the whole drive")
      ->capture_default_str();
  command->add_option("--point-noise", o->gt.point_noise, "Gaussian noise on points, metres")
      ->capture_default_str();
  command
      ->add_option("--pose-noise", o->gt.pose_noise,
                   "Gaussian noise on the keyframe centres and their rays' origins, metres")
      ->capture_default_str();
  command
      ->add_option("--pose-noise-deg", o->gt.pose_noise_deg,
                   "Gaussian noise on the keyframe orientations written to poses.tum, degrees")
      ->capture_default_str();
  command
      ->add_option(
          "--snapshot-every", o->snapshot_every,
          "Write OUT/snapshots/surface_<keyframe>.ply (closed) and observed_<keyframe>.ply "
          "every K keyframes (0: none)")
      ->capture_default_str();
  command->add_option("--seed", o->gt.seed, "Seed of the point sampling")->capture_default_str();
  command
      ->add_option("--sky-rays", o->gt.sky_rays_per_camera,
                   "--from-gt: free rays from each keyframe along about this many pixels per "
                   "camera that see nothing (the sky); they carve up to --free-ray-length · r")
      ->capture_default_str();
  command
      ->add_option("--free-ray-length", o->sculptor.free_ray_length_factor,
                   "Free rays (the sky) carve up to this times r (0: ignored)")
      ->capture_default_str();
  command->add_flag(
      "--frame-rays", o->gt.frame_rays,
      "--from-gt: also the rays from every drive frame between a point's first keyframe and its "
      "own that sees it (an SfM tracking it through every frame; not the SfM's contract today)");
  command->add_flag_callback(
      "--uniform-points", [o] { o->gt.corner_points = false; },
      "--from-gt: sample points in uniform directions, not at the Harris corners "
      "of the keyframe images (the default when the drive has images)");
  command->callback([o, &global, command, final_batch] {
    // An SfM's points (a COLMAP model): sculpted as reconstruct sculpts its own, a final batch
    // with the rays of the uncertain points (docs/figures.md F66), unless asked otherwise.
    if (!o->colmap.empty()) {
      if (final_batch->count() == 0) o->final_batch = true;
      if (command->count("--uncertain-ray-margin") == 0) {
        o->sculptor.uncertain_ray_margin_deg =
            PipelineOptions::DefaultSculptor().uncertain_ray_margin_deg;
      }
    }
    RunSurface(*o, global);
  });
}

}  // namespace omni
