// `omnisculpt mesh-check`, `omnisculpt render` and `omnisculpt eval`: thin layers
// over eval/.

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>

#include "apps/commands.h"
#include "apps/output_folder.h"
#include "calib/error.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "eval/render.h"
#include "eval/report.h"
#include "raycast/raycast.h"

namespace omni {
namespace {

struct MeshCheckCommandOptions {
  std::string mesh_path;
  bool json = false;
  MeshCheckOptions check;
};

void RegisterMeshCheck(CLI::App& app) {
  auto options = std::make_shared<MeshCheckCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "mesh-check",
      "Topological checks of a PLY mesh: edges in other than two triangles, vertex links, "
      "orientation, components, Euler characteristic and genus, boundary loops, degenerate "
      "triangles. Exit code 1 when the mesh is not a closed oriented 2-manifold (with "
      "--allow-boundary: not an oriented 2-manifold, closed or with boundary).");
  command->add_option("MESH", options->mesh_path, "PLY mesh")->required();
  command->add_flag("--json", options->json, "Print the report as JSON");
  command->add_flag("--allow-boundary", options->check.allow_boundary,
                    "Accept a 2-manifold with boundary (surface.ply); the boundary loops are "
                    "counted either way");
  command->callback([options] {
    const TriangleMesh mesh = ReadPlyMesh(options->mesh_path);
    MeshCheckReport report;
    try {
      report = CheckMesh(mesh, options->check);
    } catch (const InputError& error) {
      throw InputError(options->mesh_path, error.field(), error.what());
    }
    const std::string text = options->json ? report.ToJson() + "\n" : report.ToText();
    std::fputs(text.c_str(), stdout);
    if (!report.ok) CommandExitCode() = 1;
  });
}

struct RenderCommandOptions {
  std::string mesh_path;
  std::string pose;  // "tx ty tz qx qy qz qw", world_from_rig
  std::string rig_path;
  std::string camera_name;
  bool bird = false;
  std::string out_path;
  int width = 0;
  int height = 0;
  bool force = false;
  RenderOptions render;
};

Rigid3d ParseTumPose(const std::string& text) {
  std::istringstream in(text);
  double v[7];
  for (double& x : v) {
    if (!(in >> x)) throw InputError("", "--pose", "expected 7 numbers \"tx ty tz qx qy qz qw\"");
  }
  std::string rest;
  if (in >> rest) throw InputError("", "--pose", "expected 7 numbers \"tx ty tz qx qy qz qw\"");
  const Eigen::Quaterniond q(v[6], v[3], v[4], v[5]);
  if (!(q.norm() > 0.0)) throw InputError("", "--pose", "the quaternion is zero");
  return Rigid3d(q.normalized(), Eigen::Vector3d(v[0], v[1], v[2]));
}

void RegisterRender(CLI::App& app) {
  auto options = std::make_shared<RenderCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "render",
      "Render a PLY mesh with Embree, coloured by triangle normal as the paper's Fig. 4 "
      "(ground white, walls by the direction of their normal, sky black): from a rig camera at "
      "a pose, or a bird's-eye view.");
  command->add_option("MESH", options->mesh_path, "PLY mesh")->required();
  auto* pose = command->add_option("--pose", options->pose,
                                   "world_from_rig as \"tx ty tz qx qy qz qw\" (TUM order)");
  auto* rig = command->add_option("--rig", options->rig_path, "rig.json of the camera");
  auto* camera = command->add_option("--camera", options->camera_name, "camera name in the rig");
  auto* bird = command->add_flag("--bird", options->bird, "orthographic view from above");
  pose->needs(rig)->needs(camera)->excludes(bird);
  command->add_option("--out", options->out_path, "PNG to write")->required();
  command->add_flag("--force", options->force, "Replace --out if it exists");
  command->add_option("--width", options->width, "image width (camera: scaled intrinsics)")
      ->check(CLI::PositiveNumber);
  command->add_option("--height", options->height, "image height")->check(CLI::PositiveNumber);
  command->callback([options] {
    if (options->pose.empty() == !options->bird) {
      throw InputError("", "render", "give either --pose (with --rig and --camera) or --bird");
    }
    CheckOutputFile(options->out_path, options->force, "--out");
    const TriangleMesh mesh = ReadPlyMesh(options->mesh_path);
    std::unique_ptr<RayCaster> caster;
    try {
      caster = std::make_unique<RayCaster>(mesh);
    } catch (const InputError& error) {
      throw InputError(options->mesh_path, error.field(), error.what());
    }
    cv::Mat image;
    if (options->bird) {
      image = RenderBirdsEye(*caster, options->width > 0 ? options->width : 1024, options->height,
                             options->render);
    } else {
      const Rig rig = ReadRigJson(options->rig_path);
      const auto index = rig.FindCamera(options->camera_name);
      if (!index) {
        throw InputError(options->rig_path, "cameras",
                         "no camera named \"" + options->camera_name + "\"");
      }
      Camera camera = rig.cameras[*index];
      if (options->width > 0 || options->height > 0) {
        const int width =
            options->width > 0 ? options->width : camera.width * options->height / camera.height;
        const int height =
            options->height > 0 ? options->height : camera.height * options->width / camera.width;
        camera = ScaleCamera(camera, width, height);
      }
      image = RenderCameraView(*caster, camera, ParseTumPose(options->pose), options->render);
    }
    WritePng(image, options->out_path);
    spdlog::info("wrote {} ({}x{})", options->out_path, image.cols, image.rows);
  });
}

struct EvalCommandOptions {
  std::string drive;
  std::string rec;
  std::string out;
  bool by_frame_index = false;
  bool force = false;
  EvalOptions eval;
};

void RegisterEval(CLI::App& app) {
  auto options = std::make_shared<EvalCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "eval",
      "Evaluate a reconstruction folder against a drive's ground truth (paper 5.2 and more): "
      "pose registration, ATE, RPE, scale drift, ray-traced surface error, accuracy / "
      "completeness / F-score, point distances, mesh checks; writes eval.json, report.md, plots "
      "and renders.");
  command->add_option("--gt", options->drive, "drive folder with rig.json and gt/")->required();
  command
      ->add_option("--rec", options->rec,
                   "reconstruction folder (poses.tum, surface.ply, points.ply)")
      ->required();
  command->add_option("--out", options->out,
                      "report folder (default REC/report), new or empty; --force replaces an "
                      "earlier report (a folder with eval.json)");
  command->add_flag("--force", options->force, "Replace an earlier report in --out");
  command
      ->add_option("--pixels", options->eval.ray_errors.pixels,
                   "pixels sampled for the ray-traced error (paper: 769k)")
      ->check(CLI::PositiveNumber);
  command
      ->add_option("--samples", options->eval.surfaces.samples,
                   "area samples per surface for accuracy / completeness")
      ->check(CLI::PositiveNumber);
  command->add_option("--max-ray-length", options->eval.surfaces.max_ray_length,
                      "visibility reach of the drive for completeness (m)");
  command
      ->add_option("--pixel-thresholds", options->eval.ray_errors.pixel_thresholds,
                   "distances (m) of the pixel precision / recall, comma-separated")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  command->add_option("--seed", options->eval.ray_errors.seed, "random seed");
  command->add_flag("--by-frame-index", options->by_frame_index,
                    "match poses by frame index (timestamp = index) instead of timestamp");
  command->add_flag("!--no-plots", options->eval.plots, "skip the gnuplot plots");
  command->add_flag("!--no-renders", options->eval.renders, "skip the renders");
  command->add_flag("!--no-closed", options->eval.closed_surface,
                    "skip the figures of REC/surface_closed.ply (the closed surface)");
  command->callback([options] {
    EvalOptions eval = options->eval;
    eval.surfaces.seed = eval.ray_errors.seed + 1;
    if (options->by_frame_index) eval.poses.matching = PoseMatching::kFrameIndex;
    const std::filesystem::path out = options->out.empty()
                                          ? std::filesystem::path(options->rec) / "report"
                                          : std::filesystem::path(options->out);
    OutputFolder folder(out, "eval.json", options->force, "eval");
    const EvalSummary summary = RunEvaluation(options->drive, options->rec, out, eval);
    folder.Keep();
    const RayErrorResult& r = summary.ray_errors;
    std::printf("pose registration RMS %.1f cm over %zu keyframes\n",
                100.0 * summary.poses.registration_rms, summary.poses.matches.size());
    std::printf("ray-traced error (cm) q10..q90:");
    for (double q : r.quantiles) std::printf(" %.0f", 100.0 * q);
    std::printf(", above 600 cm %.1f %%, hits est %.1f %% gt %.1f %% both %.1f %%\n",
                100.0 * r.share_above_large, 100.0 * r.share_estimated_hit, 100.0 * r.share_gt_hit,
                100.0 * r.share_both_hit);
    for (const PrecisionRecall& pr : summary.surfaces.precision_recall) {
      std::printf("F-score at %.2f m: %.3f (precision %.3f, recall %.3f)\n", pr.threshold,
                  pr.f_score, pr.precision, pr.recall);
    }
    for (const PixelPrecisionRecall& pr : r.pixel.precision_recall) {
      std::printf("pixel F-score at %.2f m: %.3f (precision %.3f, recall %.3f)\n", pr.threshold,
                  pr.f_score, pr.precision, pr.recall);
    }
    std::printf(
        "pixel tail above %.2f m: %.1f %% of both hits (in front %.1f %%, behind %.1f %%)\n",
        r.pixel_tail_error, 100.0 * r.pixel.tail, 100.0 * r.pixel.tail_front,
        100.0 * r.pixel.tail_behind);
    if (!r.pixel_labels.empty() && r.pixel.tail_behind_count > 0) {
      // What the pixels behind the truth should have hit, the largest shares first.
      std::vector<const PixelScores*> by_behind;
      for (const PixelScores& p : r.pixel_labels) {
        if (p.tail_behind_count > 0) by_behind.push_back(&p);
      }
      std::sort(by_behind.begin(), by_behind.end(), [](const PixelScores* a, const PixelScores* b) {
        return a->tail_behind_count > b->tail_behind_count;
      });
      std::printf("behind the truth, what the true ray hits:");
      for (size_t i = 0; i < std::min<size_t>(by_behind.size(), 5); ++i) {
        std::printf("%s %s %.0f %% (%.0f %% of its both-hit pixels)", i == 0 ? "" : ",",
                    by_behind[i]->label.c_str(),
                    100.0 * by_behind[i]->tail_behind_count / r.pixel.tail_behind_count,
                    100.0 * by_behind[i]->tail_behind);
      }
      std::printf("\n");
    }
    if (summary.has_closed) {
      const RayErrorResult& c = summary.closed_ray_errors;
      std::printf("surface_closed.ply: q90 %.0f cm, above 600 cm %.1f %%, pixel F-score",
                  100.0 * (c.quantiles.empty() ? 0.0 : c.quantiles.back()),
                  100.0 * c.share_above_large);
      for (const PixelPrecisionRecall& pr : c.pixel.precision_recall) {
        std::printf(" %.3f at %.2f m", pr.f_score, pr.threshold);
      }
      std::printf(", tail %.1f %% (in front %.1f %%)\n", 100.0 * c.pixel.tail,
                  100.0 * c.pixel.tail_front);
    }
    if (summary.pipeline.present) {
      const EvalPipeline& pipeline = summary.pipeline;
      std::printf(
          "pipeline: %.2f frames/s, surface ms per keyframe median %.1f p95 %.1f, %zu loop "
          "closure(s), surface replays %.1f s\n",
          pipeline.frames_per_second, pipeline.surface_ms_median, pipeline.surface_ms_p95,
          pipeline.loop_closures.size(), pipeline.surface_replay_seconds);
    }
    std::printf("report: %s\n", (out / "report.md").string().c_str());
  });
}

}  // namespace

void RegisterEvalCommands(CLI::App& app, const GlobalOptions& /*global*/) {
  RegisterMeshCheck(app);
  RegisterRender(app);
  RegisterEval(app);
}

}  // namespace omni
