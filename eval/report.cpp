#include "eval/report.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <sstream>
#include <unordered_set>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"

namespace omni {
namespace fs = std::filesystem;
namespace {

// The paper's synthetic sequence (§5.2), in metres.
constexpr double kPaperPoseRms = 0.14;
constexpr double kPaperQuantiles[9] = {0.12, 0.16, 0.18, 0.22, 0.28, 0.48, 0.76, 1.12, 1.74};
constexpr double kPaperShareAbove6m = 0.03;
constexpr long kPaperTriangles = 182000;

// Runs `call` and rethrows an InputError without a file as one naming `file`.
template <typename Call>
auto WithFile(const fs::path& file, Call&& call) {
  try {
    return call();
  } catch (const InputError& error) {
    if (!error.file().empty()) throw;
    throw InputError(file, error.field(), error.what());
  }
}

nlohmann::json StatsJson(const ErrorStats& s) {
  return {
      {"count", s.count}, {"rmse", s.rmse}, {"mean", s.mean}, {"median", s.median}, {"max", s.max}};
}

nlohmann::json PixelScoresJson(const PixelScores& p) {
  nlohmann::json prf = nlohmann::json::array();
  for (const PixelPrecisionRecall& x : p.precision_recall) {
    prf.push_back({{"threshold_m", x.threshold},
                   {"within", x.within},
                   {"precision", x.precision},
                   {"recall", x.recall},
                   {"f_score", x.f_score}});
  }
  nlohmann::json json = {{"rays", p.rays},
                         {"estimated_hits", p.estimated_hits},
                         {"gt_hits", p.gt_hits},
                         {"both_hits", p.both_hits},
                         {"precision_recall", prf},
                         {"tail", p.tail},
                         {"tail_front", p.tail_front},
                         {"tail_behind", p.tail_behind},
                         {"tail_count", p.tail_count},
                         {"tail_front_count", p.tail_front_count},
                         {"tail_behind_count", p.tail_behind_count}};
  if (!p.camera.empty()) json["camera"] = p.camera;
  if (!p.label.empty()) json["label"] = p.label;
  return json;
}

nlohmann::json RayErrorsJson(const RayErrorResult& r) {
  nlohmann::json quantiles = nlohmann::json::object();
  for (size_t i = 0; i < r.quantile_levels.size(); ++i) {
    quantiles["q" + std::to_string(std::lround(100 * r.quantile_levels[i]))] = r.quantiles[i];
  }
  return {{"sampled_pixels", r.sampled_pixels}, {"rays", r.rays},
          {"estimated_hits", r.estimated_hits}, {"gt_hits", r.gt_hits},
          {"both_hits", r.both_hits},           {"share_estimated_hit", r.share_estimated_hit},
          {"share_gt_hit", r.share_gt_hit},     {"share_both_hit", r.share_both_hit},
          {"quantiles_m", quantiles},           {"share_above_6m", r.share_above_large},
          {"errors_m", StatsJson(r.errors)}};
}

// The pixel figures of all cameras, with those of each camera under "cameras".
nlohmann::json PixelJson(const RayErrorResult& r) {
  nlohmann::json json = PixelScoresJson(r.pixel);
  json["tail_error_m"] = r.pixel_tail_error;
  json["cameras"] = nlohmann::json::array();
  for (const PixelScores& camera : r.pixel_cameras)
    json["cameras"].push_back(PixelScoresJson(camera));
  if (!r.pixel_labels.empty()) {
    json["labels"] = nlohmann::json::array();
    for (const PixelScores& label : r.pixel_labels)
      json["labels"].push_back(PixelScoresJson(label));
  }
  return json;
}

nlohmann::json SurfacesJson(const SurfaceCompareResult& s) {
  nlohmann::json prf = nlohmann::json::array();
  for (const PrecisionRecall& x : s.precision_recall) {
    prf.push_back({{"threshold_m", x.threshold},
                   {"precision", x.precision},
                   {"recall", x.recall},
                   {"f_score", x.f_score}});
  }
  return {{"estimated_samples", s.estimated_samples},    {"gt_samples", s.gt_samples},
          {"gt_samples_seen", s.gt_samples_seen},        {"accuracy_m", StatsJson(s.accuracy)},
          {"completeness_m", StatsJson(s.completeness)}, {"precision_recall", prf}};
}

nlohmann::json Sim3Json(const Sim3d& s) {
  return {{"scale", s.scale},
          {"q_wxyz", {s.rotation.w(), s.rotation.x(), s.rotation.y(), s.rotation.z()}},
          {"t", {s.translation.x(), s.translation.y(), s.translation.z()}}};
}

std::string Cm(double metres) {
  if (!std::isfinite(metres)) return "–";
  std::ostringstream out;
  out << std::fixed << std::setprecision(1) << 100.0 * metres;
  return out.str();
}

std::string Fixed(double value, int digits) {
  if (!std::isfinite(value)) return "–";
  std::ostringstream out;
  out << std::fixed << std::setprecision(digits) << value;
  return out.str();
}

// Header names of a CSV file's first line.
std::vector<std::string> CsvHeader(const fs::path& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  std::vector<std::string> names;
  std::stringstream stream(line);
  std::string name;
  while (std::getline(stream, name, ',')) {
    name.erase(
        std::remove_if(name.begin(), name.end(), [](char c) { return c == ' ' || c == '\r'; }),
        name.end());
    names.push_back(name);
  }
  return names;
}

bool GnuplotAvailable(const std::string& program) {
  const std::string command = program + " --version >/dev/null 2>&1";
  return std::system(command.c_str()) == 0;
}

// Writes the data files and the script, runs gnuplot; returns the PNG files it made.
std::vector<std::string> MakePlots(const EvalSummary& summary, const fs::path& rec,
                                   const fs::path& dir, const EvalOptions& options,
                                   std::vector<std::string>* warnings) {
  std::vector<std::string> images;
  if (!GnuplotAvailable(options.gnuplot)) {
    warnings->push_back("gnuplot not found: plots skipped");
    spdlog::warn("gnuplot not found ('{}'): plots skipped", options.gnuplot);
    return images;
  }
  const fs::path data = dir / "plot_data";
  fs::create_directories(data);
  std::ostringstream script;
  script << "if (strstrt(GPVAL_TERMINALS, 'pngcairo') > 0) {\n"
            "  set terminal pngcairo size 900,600\n} else {\n  set terminal png size 900,600\n}\n"
            "set termoption noenhanced\nset grid\n";

  // Error CDF (at most 2000 points).
  const auto& errors = summary.ray_errors.sorted_errors;
  if (!errors.empty()) {
    std::ostringstream cdf;
    const size_t step = std::max<size_t>(1, errors.size() / 2000);
    for (size_t i = 0; i < errors.size(); i += step) {
      cdf << 100.0 * errors[i] << ' ' << static_cast<double>(i + 1) / errors.size() << '\n';
    }
    cdf << 100.0 * errors.back() << " 1\n";
    WriteTextFileAtomically(data / "error_cdf.dat", cdf.str());
    std::ostringstream paper;
    for (int i = 0; i < 9; ++i) paper << 100.0 * kPaperQuantiles[i] << ' ' << 0.1 * (i + 1) << '\n';
    WriteTextFileAtomically(data / "paper_quantiles.dat", paper.str());
    script << "set output '" << (dir / "error_cdf.png.tmp").string() << "'\n"
           << "set title 'Ray-traced surface error (paper 5.2)'\nset xlabel 'error (cm)'\n"
              "set ylabel 'share of pixels with both hits'\nset logscale x\nset key bottom right\n"
              "set yrange [0:1]\nset xrange [0.1:*]\n"
           << "plot '" << (data / "error_cdf.dat").string()
           << "' using 1:2 with lines lw 2 title 'this reconstruction', '"
           << (data / "paper_quantiles.dat").string()
           << "' using 1:2 with points pt 7 ps 1.5 title 'paper q10..q90'\n"
              "unset logscale x\nset yrange [*:*]\nset xrange [*:*]\n";
    images.push_back("error_cdf.png");
  }

  // Top view of the trajectories (first two world axes).
  {
    std::ostringstream gt, est;
    for (const MatchedPose& m : summary.poses.matches) {
      gt << m.gt_world_from_rig.translation.x() << ' ' << m.gt_world_from_rig.translation.y()
         << '\n';
      est << m.registered_world_from_rig.translation.x() << ' '
          << m.registered_world_from_rig.translation.y() << '\n';
    }
    WriteTextFileAtomically(data / "trajectory_gt.dat", gt.str());
    WriteTextFileAtomically(data / "trajectory_estimated.dat", est.str());
    script << "set output '" << (dir / "trajectories.png.tmp").string() << "'\n"
           << "set title 'Keyframe trajectories, top view (estimate registered by S)'\n"
              "set xlabel 'x (m)'\nset ylabel 'y (m)'\nset size ratio -1\nset key top left\n"
           << "plot '" << (data / "trajectory_gt.dat").string()
           << "' using 1:2 with lines lw 3 lc rgb '#888888' title 'ground truth', '"
           << (data / "trajectory_estimated.dat").string()
           << "' using 1:2 with lines lw 1 lc rgb '#d62728' title 'estimated'\nset size noratio\n";
    images.push_back("trajectories.png");
  }

  // Per-keyframe time by step and |E| (paper Fig. 5), when the stats exist.
  const fs::path stats = rec / "stats" / "keyframes.csv";
  if (fs::exists(stats)) {
    const std::vector<std::string> names = CsvHeader(stats);
    std::vector<int> time_columns;
    int e_column = -1;
    for (size_t i = 0; i < names.size(); ++i) {
      std::string lower = names[i];
      std::transform(lower.begin(), lower.end(), lower.begin(), ::tolower);
      const bool ends_ms = lower.size() > 3 && lower.compare(lower.size() - 3, 3, "_ms") == 0;
      const bool starts_ms = lower.rfind("ms_", 0) == 0;
      if ((ends_ms || starts_ms) && lower.find("total") == std::string::npos) {
        time_columns.push_back(static_cast<int>(i) + 1);
      }
      if (lower == "e" || lower == "|e|" || lower == "e_cells" || lower == "cells_e" ||
          lower == "cells_in_e" || lower == "enclosed_cells" || lower == "e_size") {
        e_column = static_cast<int>(i) + 1;
      }
    }
    script << "set datafile separator ','\nset key top left\nunset title\n";
    if (!time_columns.empty()) {
      script << "set output '" << (dir / "keyframe_times.png.tmp").string() << "'\n"
             << "set title 'Time per keyframe by step (paper Fig. 5 left)'\n"
                "set xlabel 'keyframe'\nset ylabel 'ms'\nplot ";
      for (size_t k = 0; k < time_columns.size(); ++k) {
        script << (k ? ", " : "") << "'" << stats.string() << "' using 0:" << time_columns[k]
               << " with lines title columnhead";
      }
      script << "\n";
      images.push_back("keyframe_times.png");
    } else {
      warnings->push_back("stats/keyframes.csv has no ms_* / *_ms column: no time plot");
    }
    if (e_column > 0) {
      script << "set output '" << (dir / "keyframe_e.png.tmp").string() << "'\n"
             << "set title '|E| per keyframe (paper Fig. 5 right)'\nset xlabel 'keyframe'\n"
                "set ylabel 'cells in E'\nplot '"
             << stats.string() << "' using 0:" << e_column << " with lines title '|E|'\n";
      images.push_back("keyframe_e.png");
    } else {
      warnings->push_back("stats/keyframes.csv has no |E| column: no |E| plot");
    }
    script << "set datafile separator whitespace\n";
  }

  script << "unset output\n";  // closes the last file
  WriteTextFileAtomically(data / "plots.gp", script.str());
  const std::string command = options.gnuplot + " '" + (data / "plots.gp").string() + "' >'" +
                              (data / "gnuplot.log").string() + "' 2>&1";
  if (std::system(command.c_str()) != 0) {
    warnings->push_back("gnuplot failed (see plot_data/gnuplot.log): plots may be missing");
    spdlog::warn("gnuplot failed, see {}", (data / "gnuplot.log").string());
  }
  // gnuplot wrote "<name>.tmp" files: renamed only when whole, as every output.
  std::vector<std::string> made;
  for (const std::string& image : images) {
    const fs::path written = dir / (image + ".tmp");
    if (!fs::exists(written)) continue;
    if (fs::file_size(written) > 0) {
      fs::rename(written, dir / image);
      made.push_back(image);
    } else {
      fs::remove(written);
    }
  }
  return made;
}

// q-quantile as reconstruct.json's: the element at floor(q n) of the sorted values.
double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

// The live per-keyframe surface times of stats/keyframes.csv (see EvalPipeline): a step's
// ms_total over its keyframes (the keyframes column; 1 when absent); false when the file or its
// keyframe / ms_total columns are missing. *keyframes: the keyframes of those steps.
bool LiveSurfaceTimes(const fs::path& csv, std::vector<double>* ms, long* keyframes_sculpted) {
  *keyframes_sculpted = 0;
  if (!fs::exists(csv)) return false;
  const std::vector<std::string> names = CsvHeader(csv);
  auto column = [&names](const char* name) {
    const auto it = std::find(names.begin(), names.end(), name);
    return it == names.end() ? -1 : static_cast<int>(it - names.begin());
  };
  const int keyframe_column = column("keyframe"), ms_column = column("ms_total"),
            batch_column = column("batch"), keyframes_column = column("keyframes");
  if (keyframe_column < 0 || ms_column < 0) return false;
  std::ifstream in(csv);
  std::string line;
  std::getline(in, line);  // header
  std::unordered_set<std::string> seen;
  while (std::getline(in, line)) {
    std::vector<std::string> fields;
    std::stringstream stream(line);
    std::string field;
    while (std::getline(stream, field, ',')) fields.push_back(field);
    if (static_cast<int>(fields.size()) <=
        std::max({keyframe_column, ms_column, batch_column, keyframes_column}))
      continue;
    if (!seen.insert(fields[keyframe_column]).second) continue;  // a replay's row
    if (batch_column >= 0 && fields[batch_column] != "0") continue;
    double ms_total = 0.0, keyframes = 1.0;
    try {
      ms_total = std::stod(fields[ms_column]);
    } catch (const std::exception&) {
      throw InputError(csv, "ms_total", "not a number: \"" + fields[ms_column] + "\"");
    }
    if (keyframes_column >= 0) {
      try {
        keyframes = std::stod(fields[keyframes_column]);
      } catch (const std::exception&) {
        keyframes = std::numeric_limits<double>::quiet_NaN();
      }
      if (!(keyframes >= 1.0))
        throw InputError(csv, "keyframes",
                         "not a count of keyframes: \"" + fields[keyframes_column] + "\"");
    }
    ms->push_back(ms_total / keyframes);
    *keyframes_sculpted += static_cast<long>(keyframes);
  }
  return true;
}

// A number field of a JSON object; NaN when missing or not a number (NaN is written as null).
double NumberOr(const nlohmann::json& object, const char* key) {
  const auto it = object.find(key);
  return it != object.end() && it->is_number() ? it->get<double>()
                                               : std::numeric_limits<double>::quiet_NaN();
}

// The names of the ground truth's triangle labels (gt/scene.json "mesh_labels", written by
// synth); empty, with a warning, when the file or the list is missing or unreadable.
std::vector<std::string> ReadLabelNames(const fs::path& drive, std::vector<std::string>* warnings) {
  const fs::path path = drive / "gt" / "scene.json";
  std::vector<std::string> names;
  try {
    std::ifstream in(path);
    const nlohmann::json json = nlohmann::json::parse(in);
    for (const nlohmann::json& name : json.at("mesh_labels"))
      names.push_back(name.get<std::string>());
  } catch (const std::exception&) {
    warnings->push_back(path.string() +
                        ": no list of names for gt/mesh.ply's labels (mesh_labels); labels named "
                        "by number");
    names.clear();
  }
  return names;
}

}  // namespace

EvalPipeline ReadEvalPipeline(const fs::path& rec) {
  EvalPipeline pipeline;
  const fs::path path = rec / "reconstruct.json";
  if (!fs::exists(path)) return pipeline;
  try {
    std::ifstream in(path);
    const nlohmann::json json = nlohmann::json::parse(in);
    if (!json.is_object()) throw InputError(path, "", "expected a JSON object");
    pipeline.present = true;
    pipeline.frames = json.value("frames", 0L);
    pipeline.keyframes = json.value("keyframes", 0L);
    pipeline.seconds = NumberOr(json, "seconds");
    pipeline.frames_per_second = NumberOr(json, "frames_per_second");
    pipeline.loop_closure_enabled = json.value("loop_closure", false);
    pipeline.surface_replay_seconds = NumberOr(json, "surface_replay_seconds");
    for (const nlohmann::json& loop : json.value("loop_closures", nlohmann::json::array())) {
      EvalLoopClosure e;
      e.keyframe = loop.value("keyframe", -1);
      e.frame = loop.value("frame", -1);
      e.candidate_keyframe = loop.value("candidate_keyframe", -1);
      e.candidate_frame = loop.value("candidate_frame", -1);
      e.inliers = loop.value("inliers", 0);
      e.relative_inliers = loop.value("relative_pose_inliers", 0);
      e.translation = NumberOr(loop, "correction_translation");
      e.rotation_deg = NumberOr(loop, "correction_rotation_deg");
      e.scale = NumberOr(loop, "correction_scale");
      e.ms = NumberOr(loop, "ms");
      e.replay_seconds = NumberOr(loop, "surface_replay_seconds");
      pipeline.loop_closures.push_back(e);
    }
    std::vector<double> ms;
    long keyframes_sculpted = 0;
    if (LiveSurfaceTimes(rec / "stats" / "keyframes.csv", &ms, &keyframes_sculpted)) {
      pipeline.surface_keyframes = keyframes_sculpted;
      pipeline.surface_ms_median = Quantile(ms, 0.5);
      pipeline.surface_ms_p95 = Quantile(ms, 0.95);
      pipeline.surface_ms_source = "stats/keyframes.csv";
    } else if (json.contains("surface_ms_median")) {
      pipeline.surface_ms_median = NumberOr(json, "surface_ms_median");
      pipeline.surface_ms_p95 = NumberOr(json, "surface_ms_p95");
      pipeline.surface_ms_source = "reconstruct.json";
    }
  } catch (const nlohmann::json::exception& error) {
    throw InputError(path, "", std::string("malformed: ") + error.what());
  }
  return pipeline;
}

std::string EvalOptions::Check() const {
  for (const std::string& problem :
       {poses.Check(), ray_errors.Check(), surfaces.Check(), render.Check()}) {
    if (!problem.empty()) return problem;
  }
  if (render_width <= 0) return "render_width: must be > 0";
  if (keyframe_views < 0) return "keyframe_views: must be >= 0";
  return {};
}

EvalSummary RunEvaluation(const fs::path& drive, const fs::path& rec, const fs::path& report_dir,
                          const EvalOptions& options) {
  if (const std::string problem = options.Check(); !problem.empty()) {
    throw InputError("", "eval options", problem);
  }
  EvalSummary summary;
  const Rig rig = ReadRigJson(drive / "rig.json");
  const fs::path gt_poses_path = drive / "gt" / "poses.tum";
  const fs::path gt_mesh_path = drive / "gt" / "mesh.ply";
  const fs::path poses_path = rec / "poses.tum";
  const fs::path surface_path = rec / "surface.ply";
  const fs::path points_path = rec / "points.ply";
  for (const fs::path& path : {gt_poses_path, gt_mesh_path, poses_path, surface_path}) {
    if (!fs::exists(path)) throw InputError(path, "", "missing (needed by eval)");
  }

  // Poses (paper 5.2: keyframe centre = mean of the camera centres).
  PoseEvalOptions pose_options = options.poses;
  pose_options.center_in_rig = rig.CentralCenterInRig();
  const std::vector<StampedPose> gt_poses = ReadTum(gt_poses_path);
  const std::vector<StampedPose> estimated_poses = ReadTum(poses_path);
  summary.poses =
      WithFile(poses_path, [&] { return EvaluatePoses(estimated_poses, gt_poses, pose_options); });
  const Sim3d& gt_from_estimated = summary.poses.gt_from_estimated;
  spdlog::info("poses: {} matched, registration RMS {:.3f} m, scale {:.4f}",
               summary.poses.matches.size(), summary.poses.registration_rms,
               gt_from_estimated.scale);

  // Surfaces, the estimate registered by S.
  const TriangleMesh gt_mesh = ReadPlyMesh(gt_mesh_path);
  TriangleMesh estimated_mesh = ReadPlyMesh(surface_path);
  summary.gt_mesh = WithFile(gt_mesh_path, [&] { return CheckMesh(gt_mesh); });
  // surface.ply is the observed surface: a 2-manifold with boundary (docs/design.md §6).
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  summary.estimated_mesh =
      WithFile(surface_path, [&] { return CheckMesh(estimated_mesh, bounded); });
  for (Eigen::Vector3d& v : estimated_mesh.vertices) v = gt_from_estimated * v;
  const RayCaster gt_caster = WithFile(gt_mesh_path, [&] { return RayCaster(gt_mesh); });
  const RayCaster estimated_caster =
      WithFile(surface_path, [&] { return RayCaster(estimated_mesh); });

  std::vector<KeyframePoses> keyframes;
  std::vector<Rigid3d> gt_keyframes;
  for (const MatchedPose& m : summary.poses.matches) {
    keyframes.push_back({m.registered_world_from_rig, m.gt_world_from_rig});
    gt_keyframes.push_back(m.gt_world_from_rig);
  }
  // The ground truth's triangles by kind of surface (a synth drive's poles, cars, walls...): the
  // pixel figures per kind.
  GtLabels labels;
  if (!gt_mesh.labels.empty()) {
    labels.per_triangle = gt_mesh.labels;
    labels.names = ReadLabelNames(drive, &summary.warnings);
  }
  summary.ray_errors =
      EvaluateRayErrors(rig, keyframes, estimated_caster, gt_caster, options.ray_errors, labels);
  spdlog::info("ray-traced error: {} pixels, both hits {:.1f} %, median {:.3f} m",
               summary.ray_errors.rays, 100.0 * summary.ray_errors.share_both_hit,
               summary.ray_errors.errors.median);
  summary.surfaces = CompareSurfaces(estimated_mesh, estimated_caster, gt_mesh, gt_caster, rig,
                                     gt_keyframes, options.surfaces);
  const fs::path closed_path = rec / "surface_closed.ply";
  if (options.closed_surface && fs::exists(closed_path)) {
    TriangleMesh closed_mesh = ReadPlyMesh(closed_path);
    summary.closed_mesh = WithFile(closed_path, [&] { return CheckMesh(closed_mesh); });
    for (Eigen::Vector3d& v : closed_mesh.vertices) v = gt_from_estimated * v;
    const RayCaster closed_caster = WithFile(closed_path, [&] { return RayCaster(closed_mesh); });
    summary.closed_ray_errors =
        EvaluateRayErrors(rig, keyframes, closed_caster, gt_caster, options.ray_errors);
    summary.closed_surfaces = CompareSurfaces(closed_mesh, closed_caster, gt_mesh, gt_caster, rig,
                                              gt_keyframes, options.surfaces);
    summary.has_closed = true;
  }
  if (fs::exists(points_path)) {
    PointCloud cloud = ReadPlyPoints(points_path);
    for (Eigen::Vector3d& p : cloud.points) p = gt_from_estimated * p;
    summary.points = PointDistances(cloud.points, gt_caster);
    summary.has_points = true;
  } else {
    summary.warnings.push_back("no points.ply: point distances skipped");
  }

  summary.pipeline = ReadEvalPipeline(rec);

  fs::create_directories(report_dir);
  if (options.plots) {
    const auto plots = MakePlots(summary, rec, report_dir, options, &summary.warnings);
    summary.images.insert(summary.images.end(), plots.begin(), plots.end());
  }
  if (options.renders) {
    WritePng(RenderBirdsEye(estimated_caster, options.render_width, 0, options.render),
             report_dir / "bird_estimated.png");
    WritePng(RenderBirdsEye(gt_caster, options.render_width, 0, options.render),
             report_dir / "bird_gt.png");
    summary.images.push_back("bird_estimated.png");
    summary.images.push_back("bird_gt.png");
    const int views = std::min<int>(options.keyframe_views, static_cast<int>(keyframes.size()));
    for (int k = 0; k < views && !rig.cameras.empty(); ++k) {
      const size_t index =
          views == 1 ? keyframes.size() / 2 : k * (keyframes.size() - 1) / (views - 1);
      const Camera& camera = rig.cameras[0];
      const std::string stem = "keyframe" + std::to_string(index) + "_" + camera.name;
      WritePng(RenderCameraView(estimated_caster, camera, keyframes[index].estimated_world_from_rig,
                                options.render),
               report_dir / (stem + "_estimated.png"));
      WritePng(
          RenderCameraView(gt_caster, camera, keyframes[index].gt_world_from_rig, options.render),
          report_dir / (stem + "_gt.png"));
      summary.images.push_back(stem + "_estimated.png");
      summary.images.push_back(stem + "_gt.png");
    }
  }
  WriteTextFileAtomically(report_dir / "eval.json", EvalSummaryToJson(summary) + "\n");
  WriteTextFileAtomically(report_dir / "report.md", EvalSummaryToMarkdown(summary));
  return summary;
}

std::string EvalSummaryToJson(const EvalSummary& s) {
  nlohmann::json json;
  const PoseEvalResult& p = s.poses;
  nlohmann::json rpe = nlohmann::json::array();
  for (const RpeResult& r : p.rpe) {
    rpe.push_back({{"segment_length_m", r.segment_length},
                   {"pairs", r.pairs},
                   {"translation_percent", r.translation_percent},
                   {"rotation_deg_per_100m", r.rotation_deg_per_100m}});
  }
  nlohmann::json drift = nlohmann::json::array();
  for (const ScaleSegment& d : p.scale_drift) {
    drift.push_back({{"gt_distance_start_m", d.gt_distance_start},
                     {"gt_length_m", d.gt_length},
                     {"relative_scale", d.relative_scale}});
  }
  json["poses"] = {{"estimated_poses", p.estimated_poses},
                   {"gt_poses", p.gt_poses},
                   {"matched", p.matches.size()},
                   {"gt_from_estimated", Sim3Json(p.gt_from_estimated)},
                   {"registration_rms_m", p.registration_rms},
                   {"ate_translation_m", StatsJson(p.ate_translation)},
                   {"ate_rotation_deg", StatsJson(p.ate_rotation_deg)},
                   {"gt_length_m", p.gt_length},
                   {"rpe", rpe},
                   {"scale_drift", drift},
                   {"scale_drift_min", p.scale_drift_min},
                   {"scale_drift_max", p.scale_drift_max}};
  json["ray_errors"] = RayErrorsJson(s.ray_errors);
  json["pixel"] = PixelJson(s.ray_errors);
  json["surfaces"] = SurfacesJson(s.surfaces);
  if (s.has_closed) {
    json["closed_surface"] = {{"file", "surface_closed.ply"},
                              {"mesh",
                               {{"ok", s.closed_mesh.ok},
                                {"closed_manifold", s.closed_mesh.closed_manifold},
                                {"vertices", s.closed_mesh.vertices},
                                {"triangles", s.closed_mesh.triangles}}},
                              {"ray_errors", RayErrorsJson(s.closed_ray_errors)},
                              {"pixel", PixelJson(s.closed_ray_errors)},
                              {"surfaces", SurfacesJson(s.closed_surfaces)}};
  }
  if (s.has_points) {
    nlohmann::json q = nlohmann::json::object();
    for (size_t i = 0; i < s.points.quantile_levels.size(); ++i) {
      q["q" + std::to_string(std::lround(100 * s.points.quantile_levels[i]))] =
          s.points.quantiles[i];
    }
    json["points"] = {{"points", s.points.points},
                      {"distance_quantiles_m", q},
                      {"distances_m", StatsJson(s.points.distances)}};
  }
  if (s.pipeline.present) {
    // NaN (not given) as null.
    auto number = [](double x) { return std::isfinite(x) ? nlohmann::json(x) : nlohmann::json(); };
    const EvalPipeline& pl = s.pipeline;
    nlohmann::json loops = nlohmann::json::array();
    for (const EvalLoopClosure& e : pl.loop_closures) {
      loops.push_back(
          {{"frame", e.frame},
           {"keyframe", e.keyframe},
           {"candidate_frame", e.candidate_frame},
           {"candidate_keyframe", e.candidate_keyframe},
           {"inliers", e.inliers},
           {"relative_pose_inliers", e.relative_inliers},
           {"correction_translation", number(e.translation)},
           {"correction_translation_m", number(e.translation * s.poses.gt_from_estimated.scale)},
           {"correction_rotation_deg", number(e.rotation_deg)},
           {"correction_scale", number(e.scale)},
           {"ms", number(e.ms)},
           {"surface_replay_seconds", number(e.replay_seconds)}});
    }
    json["pipeline"] = {{"frames", pl.frames},
                        {"keyframes", pl.keyframes},
                        {"seconds", number(pl.seconds)},
                        {"frames_per_second", number(pl.frames_per_second)},
                        {"surface_keyframes", pl.surface_keyframes},
                        {"surface_ms_median", number(pl.surface_ms_median)},
                        {"surface_ms_p95", number(pl.surface_ms_p95)},
                        {"surface_ms_source", pl.surface_ms_source},
                        {"loop_closure", pl.loop_closure_enabled},
                        {"loop_closures", loops},
                        {"surface_replay_seconds", number(pl.surface_replay_seconds)}};
  }
  json["estimated_mesh"] = nlohmann::json::parse(s.estimated_mesh.ToJson());
  json["gt_mesh"] = nlohmann::json::parse(s.gt_mesh.ToJson());
  json["paper"] = {{"registration_rms_m", kPaperPoseRms},
                   {"quantiles_m", kPaperQuantiles},
                   {"share_above_6m", kPaperShareAbove6m},
                   {"triangles", kPaperTriangles}};
  json["warnings"] = s.warnings;
  json["images"] = s.images;
  return json.dump(2);
}

namespace {

// The pixel figures by what the ground-truth ray hits (the labels of gt/mesh.ply's triangles).
void LabelsMarkdown(const RayErrorResult& r, std::ostringstream& md) {
  // Every ground-truth hit has a label, so the labels' pixels behind add up to the total's.
  const long behind_total = r.pixel.tail_behind_count;
  md << "\nBy what the ground-truth ray hits (gt/mesh.ply's labels): of the pixels whose "
        "ground-truth hit is on such triangles, the recall, the tail as a share of those with "
        "both hits, and the label's share of all the pixels behind the truth.\n\n"
     << "| hits | ground-truth hits | both hits |";
  for (const PixelPrecisionRecall& x : r.pixel.precision_recall) {
    md << " R at " << Cm(x.threshold) << " cm |";
  }
  md << " tail | in front | behind | of all behind |\n|---|---|---|";
  for (size_t i = 0; i < r.pixel.precision_recall.size(); ++i) md << "---|";
  md << "---|---|---|---|\n";
  for (const PixelScores& p : r.pixel_labels) {
    md << "| " << p.label << " | " << p.gt_hits << " | " << p.both_hits << " |";
    for (const PixelPrecisionRecall& x : p.precision_recall)
      md << " " << Fixed(x.recall, 3) << " |";
    md << " " << Fixed(100.0 * p.tail, 1) << " % | " << Fixed(100.0 * p.tail_front, 1) << " % | "
       << Fixed(100.0 * p.tail_behind, 1) << " % | "
       << Fixed(behind_total > 0 ? 100.0 * p.tail_behind_count / behind_total : 0.0, 1) << " % |\n";
  }
}

// The observed surface (surface.ply) beside the closed δO (surface_closed.ply).
void ClosedSurfaceMarkdown(const EvalSummary& s, std::ostringstream& md) {
  const RayErrorResult &o = s.ray_errors, &c = s.closed_ray_errors;
  md << "\n## surface.ply against surface_closed.ply\n\n"
     << "surface.ply is the observed surface, surface_closed.ply the closed δO it is cut from "
        "(its ceiling over the streets and its caps are hit by every pixel).\n\n"
     << "| figure | surface.ply | surface_closed.ply |\n|---|---|---|\n";
  auto both = [&md](const std::string& name, const std::string& a, const std::string& b) {
    md << "| " << name << " | " << a << " | " << b << " |\n";
  };
  both("triangles", std::to_string(s.estimated_mesh.triangles),
       std::to_string(s.closed_mesh.triangles));
  both("oriented 2-manifold (surface.ply: with boundary allowed; closed: closed)",
       s.estimated_mesh.ok ? "yes" : "no", s.closed_mesh.ok ? "yes" : "no");
  both("pixels with an estimated hit", Fixed(100.0 * o.share_estimated_hit, 1) + " %",
       Fixed(100.0 * c.share_estimated_hit, 1) + " %");
  for (size_t i = 0; i < o.quantile_levels.size() && i < c.quantiles.size(); ++i) {
    const long level = std::lround(100 * o.quantile_levels[i]);
    if (level != 50 && level != 90) continue;
    both("q" + std::to_string(level) + " (cm)", Cm(o.quantiles[i]), Cm(c.quantiles[i]));
  }
  both("errors above 600 cm", Fixed(100.0 * o.share_above_large, 1) + " %",
       Fixed(100.0 * c.share_above_large, 1) + " %");
  for (size_t i = 0; i < o.pixel.precision_recall.size() && i < c.pixel.precision_recall.size();
       ++i) {
    const PixelPrecisionRecall &a = o.pixel.precision_recall[i], &b = c.pixel.precision_recall[i];
    both("pixel P / R / F at " + Cm(a.threshold) + " cm",
         Fixed(a.precision, 3) + " / " + Fixed(a.recall, 3) + " / " + Fixed(a.f_score, 3),
         Fixed(b.precision, 3) + " / " + Fixed(b.recall, 3) + " / " + Fixed(b.f_score, 3));
  }
  both("pixel tail (in front / behind)",
       Fixed(100.0 * o.pixel.tail, 1) + " % (" + Fixed(100.0 * o.pixel.tail_front, 1) + " / " +
           Fixed(100.0 * o.pixel.tail_behind, 1) + ")",
       Fixed(100.0 * c.pixel.tail, 1) + " % (" + Fixed(100.0 * c.pixel.tail_front, 1) + " / " +
           Fixed(100.0 * c.pixel.tail_behind, 1) + ")");
  const auto &so = s.surfaces.precision_recall, &sc = s.closed_surfaces.precision_recall;
  for (size_t i = 0; i < so.size() && i < sc.size(); ++i) {
    both("surface F-score at " + Cm(so[i].threshold) + " cm", Fixed(so[i].f_score, 3),
         Fixed(sc[i].f_score, 3));
  }
}

}  // namespace

std::string EvalSummaryToMarkdown(const EvalSummary& s) {
  std::ostringstream md;
  const RayErrorResult& r = s.ray_errors;
  md << "# Evaluation against ground truth\n\n"
     << "Paper figures: the synthetic sequence of Litvinov & Lhuillier (BMVC 2013, §5.2). All "
        "lengths in ground-truth units (metres), errors in centimetres.\n\n"
     << "| figure | this reconstruction | paper |\n|---|---|---|\n"
     << "| pose registration RMS (cm) | " << Cm(s.poses.registration_rms) << " | "
     << Cm(kPaperPoseRms) << " |\n";
  for (size_t i = 0; i < r.quantile_levels.size(); ++i) {
    const long level = std::lround(100 * r.quantile_levels[i]);
    std::string paper = "–";
    if (level % 10 == 0 && level >= 10 && level <= 90) paper = Cm(kPaperQuantiles[level / 10 - 1]);
    md << "| q" << level << " (cm) | " << Cm(r.quantiles[i]) << " | " << paper << " |\n";
  }
  md << "| errors above 600 cm | " << Fixed(100.0 * r.share_above_large, 1) << " % | "
     << Fixed(100.0 * kPaperShareAbove6m, 0) << " % |\n"
     << "| triangles | " << s.estimated_mesh.triangles << " | " << kPaperTriangles << " |\n\n";
  md << "In 3-D: [the viewer](../viewer/index.html) (written beside this report's folder by "
        "`omnisculpt view REC`; the surface, the trajectory, the sculpting played back).\n\n";

  md << "## Poses\n\n"
     << "| | |\n|---|---|\n"
     << "| keyframes matched | " << s.poses.matches.size() << " of " << s.poses.estimated_poses
     << " (ground truth " << s.poses.gt_poses << " poses) |\n"
     << "| scale of S | " << Fixed(s.poses.gt_from_estimated.scale, 5) << " |\n"
     << "| ATE RMSE / median / max (cm) | " << Cm(s.poses.ate_translation.rmse) << " / "
     << Cm(s.poses.ate_translation.median) << " / " << Cm(s.poses.ate_translation.max) << " |\n"
     << "| rotation error after S, median / max (°) | " << Fixed(s.poses.ate_rotation_deg.median, 3)
     << " / " << Fixed(s.poses.ate_rotation_deg.max, 3) << " |\n"
     << "| ground-truth length (m) | " << Fixed(s.poses.gt_length, 1) << " |\n";
  for (const RpeResult& rpe : s.poses.rpe) {
    md << "| RPE " << Fixed(rpe.segment_length, 0) << " m: translation % / rotation °/100 m ("
       << rpe.pairs << " pairs) | " << Fixed(rpe.translation_percent, 3) << " / "
       << Fixed(rpe.rotation_deg_per_100m, 3) << " |\n";
  }
  md << "| local scale relative to S, min / max | " << Fixed(s.poses.scale_drift_min, 4) << " / "
     << Fixed(s.poses.scale_drift_max, 4) << " |\n\n";

  md << "## Ray-traced surface error (paper §5.2)\n\n"
     << "| | |\n|---|---|\n"
     << "| sampled pixels (rays) | " << r.sampled_pixels << " (" << r.rays << ") |\n"
     << "| with an estimated hit | " << Fixed(100.0 * r.share_estimated_hit, 1) << " % |\n"
     << "| with a ground-truth hit | " << Fixed(100.0 * r.share_gt_hit, 1) << " % |\n"
     << "| with both | " << Fixed(100.0 * r.share_both_hit, 1) << " % |\n"
     << "| error mean / median (cm) | " << Cm(r.errors.mean) << " / " << Cm(r.errors.median)
     << " |\n\n";

  md << "## Surface against surface\n\n"
     << "| | |\n|---|---|\n"
     << "| accuracy (estimated → GT) median / mean (cm) | " << Cm(s.surfaces.accuracy.median)
     << " / " << Cm(s.surfaces.accuracy.mean) << " |\n"
     << "| completeness (seen GT → estimated) median / mean (cm) | "
     << Cm(s.surfaces.completeness.median) << " / " << Cm(s.surfaces.completeness.mean) << " |\n"
     << "| GT samples seen by the drive | " << s.surfaces.gt_samples_seen << " of "
     << s.surfaces.gt_samples << " |\n";
  for (const PrecisionRecall& x : s.surfaces.precision_recall) {
    md << "| at " << Cm(x.threshold) << " cm: precision / recall / F-score | "
       << Fixed(x.precision, 3) << " / " << Fixed(x.recall, 3) << " / " << Fixed(x.f_score, 3)
       << " |\n";
  }
  if (s.has_points) {
    md << "| SfM points to GT surface (" << s.points.points << "): ";
    for (size_t i = 0; i < s.points.quantile_levels.size(); ++i) {
      md << (i ? " / " : "") << "q" << std::lround(100 * s.points.quantile_levels[i]);
    }
    md << " (cm) | ";
    for (size_t i = 0; i < s.points.quantiles.size(); ++i) {
      md << (i ? " / " : "") << Cm(s.points.quantiles[i]);
    }
    md << " |\n";
  }

  md << "\n## Pixel precision / recall (ray-traced)\n\n"
     << "From the rays of the ray-traced error: a pixel is right at τ when its estimated and "
        "ground-truth hits both exist and are less than τ apart; precision is over the pixels "
        "with an estimated hit, recall over those with a ground-truth hit. Tail: the pixels with "
        "both hits whose error is above "
     << Cm(r.pixel_tail_error)
     << " cm, split by whether the estimated hit is nearer the camera (in front) or not "
        "(behind), as shares of the pixels with both hits.\n\n"
     << "| camera | rays | estimated hits | ground-truth hits |";
  for (const PixelPrecisionRecall& x : r.pixel.precision_recall) {
    md << " P / R / F at " << Cm(x.threshold) << " cm |";
  }
  md << " tail | in front | behind |\n|---|---|---|---|";
  for (size_t i = 0; i < r.pixel.precision_recall.size(); ++i) md << "---|";
  md << "---|---|---|\n";
  auto pixel_row = [&md](const std::string& name, const PixelScores& p) {
    md << "| " << name << " | " << p.rays << " | " << p.estimated_hits << " | " << p.gt_hits
       << " |";
    for (const PixelPrecisionRecall& x : p.precision_recall) {
      md << " " << Fixed(x.precision, 3) << " / " << Fixed(x.recall, 3) << " / "
         << Fixed(x.f_score, 3) << " |";
    }
    md << " " << Fixed(100.0 * p.tail, 1) << " % | " << Fixed(100.0 * p.tail_front, 1) << " % | "
       << Fixed(100.0 * p.tail_behind, 1) << " % |\n";
  };
  for (const PixelScores& camera : r.pixel_cameras) pixel_row(camera.camera, camera);
  pixel_row("**all**", r.pixel);
  if (!r.pixel_labels.empty()) LabelsMarkdown(r, md);
  if (s.has_closed) ClosedSurfaceMarkdown(s, md);
  if (s.pipeline.present) {
    const EvalPipeline& pl = s.pipeline;
    md << "\n## Pipeline (reconstruct.json)\n\n"
       << "| | |\n|---|---|\n"
       << "| frames / keyframes | " << pl.frames << " / " << pl.keyframes << " |\n"
       << "| whole pipeline, seconds / frames per second (target 15) | " << Fixed(pl.seconds, 1)
       << " / " << Fixed(pl.frames_per_second, 2) << " |\n";
    if (!pl.surface_ms_source.empty())
      md << "| surface ms per keyframe, median / p95 (" << pl.surface_ms_source
         << (pl.surface_keyframes > 0 ? ", " + std::to_string(pl.surface_keyframes) + " keyframes"
                                      : std::string())
         << ") | " << Fixed(pl.surface_ms_median, 1) << " / " << Fixed(pl.surface_ms_p95, 1)
         << " |\n";
    md << "| loop closure | " << (pl.loop_closure_enabled ? "on" : "off") << ", "
       << pl.loop_closures.size() << " closed |\n"
       << "| surface replay after the closures (s) | " << Fixed(pl.surface_replay_seconds, 2)
       << " |\n\n";
    if (!pl.loop_closures.empty()) {
      md << "### Loop closures\n\n"
         << "The correction is the move of the revisiting keyframe (pose graph and global "
            "adjustment); its translation in map units and in metres (× the scale of S).\n\n"
         << "| # | revisit frame (keyframe) | place frame (keyframe) | inliers (3-D similarity) | "
            "inliers (relative pose) | translation (map) | translation (m) | rotation (°) | scale "
            "| time (ms) | surface replay (s) |\n|---|---|---|---|---|---|---|---|---|---|---|\n";
      for (size_t i = 0; i < pl.loop_closures.size(); ++i) {
        const EvalLoopClosure& e = pl.loop_closures[i];
        md << "| " << i + 1 << " | " << e.frame << " (" << e.keyframe << ") | " << e.candidate_frame
           << " (" << e.candidate_keyframe << ") | " << e.inliers << " | " << e.relative_inliers
           << " | " << Fixed(e.translation, 3) << " | "
           << Fixed(e.translation * s.poses.gt_from_estimated.scale, 3) << " | "
           << Fixed(e.rotation_deg, 3) << " | " << Fixed(e.scale, 4) << " | " << Fixed(e.ms, 0)
           << " | " << Fixed(e.replay_seconds, 2) << " |\n";
      }
      md << "\n";
    }
  }
  md << "\n## Meshes\n\n| | estimated | ground truth |\n|---|---|---|\n";
  auto row = [&md](const char* name, long a, long b) {
    md << "| " << name << " | " << a << " | " << b << " |\n";
  };
  const MeshCheckReport &e = s.estimated_mesh, &g = s.gt_mesh;
  row("vertices", e.vertices, g.vertices);
  row("triangles", e.triangles, g.triangles);
  row("boundary edges", e.boundary_edges, g.boundary_edges);
  row("boundary loops", e.boundary_loops, g.boundary_loops);
  row("edges in more than two triangles", e.nonmanifold_edges, g.nonmanifold_edges);
  row("vertices whose link is not one cycle", e.vertices_link_not_cycle, g.vertices_link_not_cycle);
  row("misoriented edges", e.misoriented_edges, g.misoriented_edges);
  row("degenerate triangles", e.degenerate_triangles, g.degenerate_triangles);
  row("components", e.components, g.components);
  row("Euler characteristic", e.euler_characteristic, g.euler_characteristic);
  row("genus (-1: undefined)", e.genus, g.genus);
  md << "| oriented 2-manifold (estimated: with boundary allowed; ground truth: closed) | "
     << (e.ok ? "yes" : "no") << " | " << (g.ok ? "yes" : "no") << " |\n\n";

  if (!s.images.empty()) {
    md << "## Figures\n\n";
    for (const std::string& image : s.images) md << "![" << image << "](" << image << ")\n\n";
  }
  if (!s.warnings.empty()) {
    md << "## Warnings\n\n";
    for (const std::string& w : s.warnings) md << "- " << w << "\n";
  }
  return md.str();
}

}  // namespace omni
