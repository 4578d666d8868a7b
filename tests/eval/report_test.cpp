// The eval report on small hand-made drives: errors against ground truth, plots, input errors
// naming their file, and the reconstruct summary's pipeline section.

#include "eval/report.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "calib/error.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "eval/primitives.h"
#include "tests/eval/eval_drive.h"

namespace omni {
namespace {
namespace fs = std::filesystem;
using testing::EvalTest;
using testing::kEstimatedFromGt;

TEST_F(EvalTest, GroundTruthAgainstItselfGivesZeroErrors) {
  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  const EvalSummary summary = RunEvaluation(drive_, rec_, root_ / "report", SmallOptions());
  EXPECT_EQ(summary.poses.matches.size(), 30u);
  EXPECT_LT(summary.poses.registration_rms, 1e-4);
  EXPECT_NEAR(summary.poses.gt_from_estimated.scale, 5.0, 1e-4);
  const RayErrorResult& r = summary.ray_errors;
  EXPECT_EQ(r.rays, 20000);
  EXPECT_DOUBLE_EQ(r.share_gt_hit, 1.0);  // closed scene
  EXPECT_DOUBLE_EQ(r.share_estimated_hit, 1.0);
  EXPECT_DOUBLE_EQ(r.share_both_hit, 1.0);
  EXPECT_LT(r.quantiles.back(), 0.01);  // q90 (float precision of the scaled mesh)
  EXPECT_NEAR(summary.surfaces.accuracy.median, 0.0, 1e-3);
  EXPECT_NEAR(summary.surfaces.completeness.median, 0.0, 1e-3);
  EXPECT_DOUBLE_EQ(summary.surfaces.precision_recall[0].f_score, 1.0);
  EXPECT_GT(summary.surfaces.gt_samples_seen, 0);
  EXPECT_LT(summary.surfaces.gt_samples_seen, summary.surfaces.gt_samples);  // roofs unseen
  EXPECT_TRUE(summary.has_points);
  EXPECT_LT(summary.points.distances.max, 1e-3);
  EXPECT_TRUE(summary.gt_mesh.closed_manifold);
  EXPECT_EQ(summary.gt_mesh.components, 11);

  const fs::path report = root_ / "report";
  std::ifstream json_file(report / "eval.json");
  const nlohmann::json json = nlohmann::json::parse(json_file);
  EXPECT_EQ(json["poses"]["matched"], 30);
  EXPECT_NEAR(json["ray_errors"]["share_both_hit"].get<double>(), 1.0, 1e-12);
  EXPECT_TRUE(json["ray_errors"]["quantiles_m"].contains("q50"));
  EXPECT_EQ(json["paper"]["triangles"], 182000);
  std::ifstream md_file(report / "report.md");
  std::stringstream md;
  md << md_file.rdbuf();
  EXPECT_NE(md.str().find("| q50 (cm) |"), std::string::npos);
  EXPECT_NE(md.str().find("| 28.0 |"), std::string::npos);  // the paper's median
  for (const std::string& image : summary.images) {
    EXPECT_TRUE(fs::exists(report / image)) << image;
  }
  EXPECT_TRUE(fs::exists(report / "bird_gt.png"));
  EXPECT_TRUE(fs::exists(report / "bird_estimated.png"));
  if (std::system("gnuplot --version >/dev/null 2>&1") == 0) {
    EXPECT_TRUE(fs::exists(report / "error_cdf.png"));
    EXPECT_TRUE(fs::exists(report / "trajectories.png"));
    EXPECT_TRUE(fs::exists(report / "keyframe_times.png"));
    EXPECT_TRUE(fs::exists(report / "keyframe_e.png"));
  }
}

TEST_F(EvalTest, PixelFiguresPerCameraAndInTotal) {
  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  EvalOptions options = SmallOptions();
  options.plots = false;
  options.renders = false;
  const EvalSummary summary = RunEvaluation(drive_, rec_, root_ / "report", options);
  const PixelScores& p = summary.ray_errors.pixel;
  EXPECT_EQ(p.rays, 20000);
  ASSERT_EQ(p.precision_recall.size(), 2u);
  EXPECT_DOUBLE_EQ(p.precision_recall[0].f_score, 1.0);  // errors of float precision only
  EXPECT_DOUBLE_EQ(p.precision_recall[1].f_score, 1.0);
  EXPECT_EQ(p.tail_count, 0);

  std::ifstream json_file(root_ / "report" / "eval.json");
  const nlohmann::json json = nlohmann::json::parse(json_file);
  ASSERT_TRUE(json.contains("pixel"));
  const nlohmann::json& pixel = json["pixel"];
  EXPECT_EQ(pixel["rays"], json["ray_errors"]["rays"]);
  EXPECT_DOUBLE_EQ(pixel["tail_error_m"].get<double>(), 1.0);
  ASSERT_EQ(pixel["precision_recall"].size(), 2u);
  EXPECT_DOUBLE_EQ(pixel["precision_recall"][0]["threshold_m"].get<double>(), 0.2);
  EXPECT_DOUBLE_EQ(pixel["precision_recall"][1]["threshold_m"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(pixel["precision_recall"][1]["f_score"].get<double>(), 1.0);
  for (const char* key : {"tail", "tail_front", "tail_behind", "tail_count", "tail_front_count",
                          "tail_behind_count", "estimated_hits", "gt_hits", "both_hits"}) {
    EXPECT_TRUE(pixel.contains(key)) << key;
  }
  EXPECT_FALSE(pixel.contains("labels"));  // the ground truth's triangles have no labels
  ASSERT_EQ(pixel["cameras"].size(), 4u);
  long rays = 0, within = 0;
  for (size_t c = 0; c < 4; ++c) {
    EXPECT_EQ(pixel["cameras"][c]["camera"], "cam" + std::to_string(c));
    rays += pixel["cameras"][c]["rays"].get<long>();
    within += pixel["cameras"][c]["precision_recall"][0]["within"].get<long>();
  }
  EXPECT_EQ(rays, 20000);
  EXPECT_EQ(within, pixel["precision_recall"][0]["within"].get<long>());
  // The existing figures stay.
  EXPECT_TRUE(json["surfaces"].contains("precision_recall"));
  EXPECT_TRUE(json["ray_errors"].contains("share_above_6m"));

  std::ifstream md_file(root_ / "report" / "report.md");
  std::stringstream md;
  md << md_file.rdbuf();
  EXPECT_NE(md.str().find("## Pixel precision / recall"), std::string::npos) << md.str();
  EXPECT_NE(md.str().find("P / R / F at 20.0 cm"), std::string::npos) << md.str();
  EXPECT_NE(md.str().find("| cam3 |"), std::string::npos) << md.str();
  EXPECT_NE(md.str().find("| **all** | 20000 |"), std::string::npos) << md.str();
}

// A ground truth whose triangles carry labels (as synth's do) and names in gt/scene.json: the
// pixel figures per label in eval.json and report.md. The estimate lacks the north row of
// blocks, so every pixel whose true hit is on it is behind the truth (the enclosure or the
// ground beyond); the south row is right.
TEST_F(EvalTest, PixelFiguresPerLabelOfTheGroundTruth) {
  TriangleMesh labelled = gt_mesh_;
  labelled.labels = testing::StreetLabels();
  WritePlyMesh(labelled, drive_ / "gt" / "mesh.ply");
  std::ofstream(drive_ / "gt" / "scene.json") << testing::kStreetLabelsJson;
  WriteReconstruction(kEstimatedFromGt, testing::StreetWithoutNorthRow());
  EvalOptions options = SmallOptions();
  options.plots = false;
  options.renders = false;
  const EvalSummary summary = RunEvaluation(drive_, rec_, root_ / "report", options);
  const RayErrorResult& r = summary.ray_errors;
  ASSERT_EQ(r.pixel_labels.size(), 3u);
  const PixelScores &north = r.pixel_labels[1], &south = r.pixel_labels[2];
  EXPECT_EQ(north.label, "north");
  EXPECT_GT(north.gt_hits, 1000);
  // All lost but the blocks' feet, whose pixels find the ground within a metre behind them.
  EXPECT_LT(north.precision_recall[1].recall, 0.05);
  EXPECT_GT(north.tail_behind, 0.9);
  EXPECT_EQ(north.tail_front_count, 0);
  EXPECT_GT(south.gt_hits, 1000);
  EXPECT_DOUBLE_EQ(south.precision_recall[1].recall, 1.0);
  EXPECT_EQ(south.tail_count, 0);
  EXPECT_EQ(north.tail_behind_count + r.pixel_labels[0].tail_behind_count,
            r.pixel.tail_behind_count);

  std::ifstream json_file(root_ / "report" / "eval.json");
  const nlohmann::json json = nlohmann::json::parse(json_file);
  ASSERT_EQ(json["pixel"]["labels"].size(), 3u);
  EXPECT_EQ(json["pixel"]["labels"][1]["label"], "north");
  EXPECT_EQ(json["pixel"]["labels"][1]["tail_behind_count"].get<long>(), north.tail_behind_count);
  std::ifstream md_file(root_ / "report" / "report.md");
  std::stringstream md;
  md << md_file.rdbuf();
  EXPECT_NE(md.str().find("By what the ground-truth ray hits"), std::string::npos) << md.str();
  EXPECT_NE(md.str().find("| north | " + std::to_string(north.gt_hits) + " |"), std::string::npos)
      << md.str();

  // Without the names the labels are numbered, and eval says why.
  fs::remove(drive_ / "gt" / "scene.json");
  const EvalSummary unnamed = RunEvaluation(drive_, rec_, root_ / "report2", options);
  ASSERT_EQ(unnamed.ray_errors.pixel_labels.size(), 3u);
  EXPECT_EQ(unnamed.ray_errors.pixel_labels[1].label, "label 1");
  EXPECT_EQ(unnamed.ray_errors.pixel_labels[1].tail_behind_count, north.tail_behind_count);
  bool warned = false;
  for (const std::string& warning : unnamed.warnings) {
    warned |= warning.find("mesh_labels") != std::string::npos;
  }
  EXPECT_TRUE(warned);
}

TEST_F(EvalTest, MissingGnuplotOnlyWarns) {
  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  EvalOptions options = SmallOptions();
  options.gnuplot = "no-such-gnuplot-program";
  options.renders = false;
  const EvalSummary summary = RunEvaluation(drive_, rec_, root_ / "report", options);
  ASSERT_FALSE(summary.warnings.empty());
  EXPECT_NE(summary.warnings[0].find("gnuplot"), std::string::npos);
  EXPECT_TRUE(fs::exists(root_ / "report" / "eval.json"));
  EXPECT_FALSE(fs::exists(root_ / "report" / "error_cdf.png"));
}

// The street of EvalTest with its blocks (boxes) shrunk by 10 cm on every face, and the
// enclosing box too (inwards, its normals' direction).
TriangleMesh ShrunkStreet() {
  TriangleMesh shifted = FlipOrientation(MakeBox({-19.9, -19.9, -0.9}, {79.9, 19.9, 29.9}));
  for (int i = 0; i < 5; ++i) {
    AppendMesh(MakeBox({i * 12.0 + 0.1, 6.1, -0.9}, {i * 12.0 + 8.9, 11.9, 7.9 + i}), &shifted);
    AppendMesh(MakeBox({i * 12.0 + 3.1, -11.9, -0.9}, {i * 12.0 + 10.9, -6.1, 9.9 - i}), &shifted);
  }
  return shifted;
}

TEST_F(EvalTest, SurfaceShiftedTenCentimetresAlongItsNormals) {
  const TriangleMesh shifted = ShrunkStreet();
  WriteReconstruction(kEstimatedFromGt, shifted);
  EvalOptions options = SmallOptions();
  options.plots = options.renders = false;
  const EvalSummary summary = RunEvaluation(drive_, rec_, root_ / "report", options);
  EXPECT_NEAR(summary.surfaces.accuracy.median, 0.1, 2e-3);
  EXPECT_NEAR(summary.surfaces.completeness.median, 0.1, 2e-3);
  EXPECT_NEAR(summary.ray_errors.quantiles[0], 0.1, 0.02);  // q10: rays that meet walls square
  EXPECT_GT(summary.ray_errors.quantiles[4], 0.1 - 2e-3);
  EXPECT_DOUBLE_EQ(summary.surfaces.precision_recall[1].precision, 1.0);  // all within 0.5 m
}

// surface_closed.ply, when the folder has it, is scored beside surface.ply: here surface.ply is
// the ground truth itself and surface_closed.ply its blocks shrunk by 10 cm.
TEST_F(EvalTest, ClosedSurfaceIsScoredBesideTheObservedOne) {
  TriangleMesh shifted = ShrunkStreet();
  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  for (auto& v : shifted.vertices) v = kEstimatedFromGt * v;
  WritePlyMesh(shifted, rec_ / "surface_closed.ply");
  EvalOptions options = SmallOptions();
  options.plots = options.renders = false;
  const EvalSummary summary = RunEvaluation(drive_, rec_, root_ / "report", options);
  ASSERT_TRUE(summary.has_closed);
  EXPECT_TRUE(summary.closed_mesh.ok);
  EXPECT_EQ(summary.closed_mesh.triangles, static_cast<long>(shifted.triangles.size()));
  EXPECT_NEAR(summary.surfaces.accuracy.median, 0.0, 2e-3);
  EXPECT_NEAR(summary.closed_surfaces.accuracy.median, 0.1, 2e-3);
  ASSERT_EQ(summary.closed_ray_errors.pixel.precision_recall.size(), 2u);
  // The observed one is exact; the closed one is about 10 cm off wherever a ray meets it.
  EXPECT_DOUBLE_EQ(summary.ray_errors.pixel.precision_recall[0].precision, 1.0);
  EXPECT_GT(summary.closed_ray_errors.quantiles[0], 0.1 - 0.02);
  const nlohmann::json json = nlohmann::json::parse(std::ifstream(root_ / "report" / "eval.json"));
  ASSERT_TRUE(json.contains("closed_surface"));
  EXPECT_NEAR(json["closed_surface"]["surfaces"]["accuracy_m"]["median"].get<double>(), 0.1, 2e-3);
  EXPECT_EQ(json["closed_surface"]["pixel"]["cameras"].size(), json["pixel"]["cameras"].size());
  std::ifstream md(root_ / "report" / "report.md");
  const std::string text((std::istreambuf_iterator<char>(md)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("surface.ply against surface_closed.ply"), std::string::npos);

  // Switched off, or without the file: no closed figures.
  options.closed_surface = false;
  EXPECT_FALSE(RunEvaluation(drive_, rec_, root_ / "report", options).has_closed);
  options.closed_surface = true;
  fs::remove(rec_ / "surface_closed.ply");
  const EvalSummary without = RunEvaluation(drive_, rec_, root_ / "report", options);
  EXPECT_FALSE(without.has_closed);
  EXPECT_FALSE(nlohmann::json::parse(std::ifstream(root_ / "report" / "eval.json"))
                   .contains("closed_surface"));
}

TEST_F(EvalTest, NoCommonTimestampsIsInputErrorNamingTheFile) {
  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  auto poses = ReadTum(rec_ / "poses.tum");
  for (auto& pose : poses) pose.timestamp += 1000.0;
  WriteTum(poses, rec_ / "poses.tum");
  try {
    RunEvaluation(drive_, rec_, root_ / "report", SmallOptions());
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_EQ(error.file(), rec_ / "poses.tum");
    EXPECT_FALSE(fs::exists(root_ / "report" / "eval.json"));
  }
}

TEST_F(EvalTest, EmptySurfaceIsInputError) {
  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  TriangleMesh empty;
  empty.vertices = {{0, 0, 0}};
  WritePlyMesh(empty, rec_ / "surface.ply");
  try {
    RunEvaluation(drive_, rec_, root_ / "report", SmallOptions());
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_EQ(error.file(), rec_ / "surface.ply");
    EXPECT_NE(std::string(error.what()).find("no triangle"), std::string::npos) << error.what();
  }
}

// `omnisculpt reconstruct`'s summary: a hand-made reconstruct.json with one loop closure and a
// stats/keyframes.csv with a replay after it.
TEST_F(EvalTest, ReconstructJsonGivesThePipelineSectionWithTheLoopClosures) {
  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  EvalOptions options = SmallOptions();
  options.plots = options.renders = false;
  // Without reconstruct.json (an `omnisculpt sfm` output): no pipeline section.
  EvalSummary summary = RunEvaluation(drive_, rec_, root_ / "report", options);
  EXPECT_FALSE(summary.pipeline.present);
  EXPECT_EQ(EvalSummaryToMarkdown(summary).find("## Pipeline"), std::string::npos);
  EXPECT_FALSE(nlohmann::json::parse(EvalSummaryToJson(summary)).contains("pipeline"));

  std::ofstream(rec_ / "reconstruct.json") << R"({
    "frames": 120, "keyframes": 30, "seconds": 12.0, "frames_per_second": 10.0,
    "surface_ms_median": 99.0, "surface_ms_p95": 999.0, "loop_closure": true,
    "surface_replay_seconds": 1.5,
    "loop_closures": [{"keyframe": 25, "frame": 100, "candidate_keyframe": 1,
      "candidate_frame": 2, "ring_shift": 0, "appearance_score": 0.8, "matches": 60,
      "inliers": 40, "relative_pose_inliers": 55, "correction_translation": 0.4,
      "correction_rotation_deg": 0.25,
      "correction_scale": 1.02, "ms": 350.0, "surface_replay_seconds": 1.5}]})";
  // Keyframes 3 (the batch of the first ones), 4..8 sculpted live, the replay of 3..8 after
  // the closure, then 9 live: the live times are 10, 20, 30, 40, 50 and 60 ms.
  std::ofstream(rec_ / "stats" / "keyframes.csv")
      << "keyframe,batch,cells_e,ms_enclose,ms_total,queue_ms,replay\n"
         "3,1,100,1,500,0,0\n4,0,100,1,10,0,0\n5,0,100,1,20,0,0\n6,0,100,1,30,0,0\n"
         "7,0,100,1,40,0,0\n8,0,100,1,50,0,0\n3,1,100,1,900,0,1\n4,0,100,1,999,0,1\n"
         "5,0,100,1,999,0,1\n6,0,100,1,999,0,1\n7,0,100,1,999,0,1\n8,0,100,1,999,0,1\n"
         "9,0,100,1,60,0,1\n";
  summary = RunEvaluation(drive_, rec_, root_ / "report", options);
  const EvalPipeline& pipeline = summary.pipeline;
  ASSERT_TRUE(pipeline.present);
  EXPECT_EQ(pipeline.frames, 120);
  EXPECT_DOUBLE_EQ(pipeline.frames_per_second, 10.0);
  EXPECT_EQ(pipeline.surface_keyframes, 6);
  EXPECT_DOUBLE_EQ(pipeline.surface_ms_median, 40.0);  // the element at floor(0.5 * 6)
  EXPECT_DOUBLE_EQ(pipeline.surface_ms_p95, 60.0);
  EXPECT_EQ(pipeline.surface_ms_source, "stats/keyframes.csv");
  ASSERT_EQ(pipeline.loop_closures.size(), 1u);
  const EvalLoopClosure& loop = pipeline.loop_closures[0];
  EXPECT_EQ(loop.frame, 100);
  EXPECT_EQ(loop.candidate_keyframe, 1);
  EXPECT_EQ(loop.relative_inliers, 55);
  EXPECT_DOUBLE_EQ(loop.rotation_deg, 0.25);
  EXPECT_DOUBLE_EQ(loop.replay_seconds, 1.5);

  std::ifstream json_file(root_ / "report" / "eval.json");
  const nlohmann::json json = nlohmann::json::parse(json_file);
  ASSERT_TRUE(json.contains("pipeline"));
  EXPECT_DOUBLE_EQ(json["pipeline"]["surface_ms_median"].get<double>(), 40.0);
  const nlohmann::json& json_loop = json["pipeline"]["loop_closures"][0];
  EXPECT_DOUBLE_EQ(json_loop["correction_rotation_deg"].get<double>(), 0.25);
  // In metres: the map's 0.4 times the scale of S (the estimate is the truth scaled by 0.2).
  EXPECT_NEAR(json_loop["correction_translation_m"].get<double>(), 2.0, 1e-3);
  std::ifstream md_file(root_ / "report" / "report.md");
  std::stringstream md;
  md << md_file.rdbuf();
  EXPECT_NE(md.str().find("## Pipeline"), std::string::npos);
  EXPECT_NE(md.str().find("| whole pipeline, seconds / frames per second (target 15) | 12.0 / "
                          "10.00 |"),
            std::string::npos)
      << md.str();
  EXPECT_NE(
      md.str().find("| 1 | 100 (25) | 2 (1) | 40 | 55 | 0.400 | 2.000 | 0.250 | 1.0200 | 350 | "
                    "1.50 |"),
      std::string::npos)
      << md.str();

  // Steps of several keyframes (the keyframes column): a step's time over its keyframes, which
  // all count. Live: 4-5 in 20 ms, 6-8 in 120, then the replay, then 9-10 in 100: 10, 40, 50.
  std::ofstream(rec_ / "stats" / "keyframes.csv")
      << "keyframe,batch,cells_e,ms_enclose,ms_total,keyframes,queue_ms,replay\n"
         "3,1,100,1,500,3,0,0\n5,0,100,1,20,2,0,0\n8,0,100,1,120,3,0,0\n"
         "8,1,100,1,900,6,0,1\n10,0,100,1,100,2,0,1\n";
  const EvalPipeline steps = ReadEvalPipeline(rec_);
  EXPECT_EQ(steps.surface_keyframes, 7);
  EXPECT_DOUBLE_EQ(steps.surface_ms_median, 40.0);
  EXPECT_DOUBLE_EQ(steps.surface_ms_p95, 50.0);
  std::ofstream(rec_ / "stats" / "keyframes.csv")
      << "keyframe,batch,cells_e,ms_enclose,ms_total,keyframes,queue_ms,replay\n"
         "3,1,100,1,500,3,0,0\n5,0,100,1,20,0,0,0\n";
  EXPECT_THROW(ReadEvalPipeline(rec_), InputError);  // a step of no keyframe

  // Without the CSV, reconstruct.json's own figures; a malformed file is an InputError.
  fs::remove(rec_ / "stats" / "keyframes.csv");
  EXPECT_DOUBLE_EQ(ReadEvalPipeline(rec_).surface_ms_median, 99.0);
  EXPECT_EQ(ReadEvalPipeline(rec_).surface_ms_source, "reconstruct.json");
  std::ofstream(rec_ / "reconstruct.json") << R"({"frames": 120, "loop_closures": [3]})";
  try {
    ReadEvalPipeline(rec_);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_EQ(error.file(), rec_ / "reconstruct.json");
  }
}

}  // namespace
}  // namespace omni
