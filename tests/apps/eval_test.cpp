// End-to-end: `omnisculpt eval`, `mesh-check` and `render` on small hand-made drives.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "apps/eval/primitives.h"
#include "apps/eval/report.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"

namespace omni {
namespace {
namespace fs = std::filesystem;

Rig MakeRig() {
  Rig rig;
  rig.name = "ring";
  for (int k = 0; k < 4; ++k) {
    Camera camera;
    camera.name = "cam" + std::to_string(k);
    camera.width = 48;
    camera.height = 32;
    camera.params = {24.0, 24.0, 23.5, 15.5};
    Eigen::Matrix3d rig_from_cam;
    rig_from_cam << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    rig_from_cam = Eigen::AngleAxisd(k * M_PI / 2, Eigen::Vector3d::UnitZ()) * rig_from_cam;
    camera.cam_from_rig.rotation = Eigen::Quaterniond(rig_from_cam.transpose());
    camera.cam_from_rig.translation = -(rig_from_cam.transpose() * (0.05 * rig_from_cam.col(2)));
    rig.cameras.push_back(camera);
  }
  return rig;
}

// A street: ground, two rows of blocks, closed by a big box around (normals towards the drive).
TriangleMesh MakeStreet() {
  TriangleMesh mesh = FlipOrientation(MakeBox({-20, -20, -1}, {80, 20, 30}));
  for (int i = 0; i < 5; ++i) {
    AppendMesh(MakeBox({i * 12.0, 6, -1}, {i * 12.0 + 9, 12, 8.0 + i}), &mesh);
    AppendMesh(MakeBox({i * 12.0 + 3, -12, -1}, {i * 12.0 + 11, -6, 10.0 - i}), &mesh);
  }
  return mesh;
}

std::vector<StampedPose> MakeGtPoses(int frames) {
  std::vector<StampedPose> poses;
  for (int f = 0; f < frames; ++f) {
    StampedPose pose;
    pose.timestamp = f / 15.0;
    pose.world_from_rig.translation = Eigen::Vector3d(0.5 * f, 0.3 * std::sin(0.05 * f), 2.0);
    pose.world_from_rig.rotation =
        Eigen::AngleAxisd(0.02 * std::sin(0.1 * f), Eigen::Vector3d::UnitZ());
    poses.push_back(pose);
  }
  return poses;
}

class EvalTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            ("omni_eval_test_" +
             std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(root_);
    drive_ = root_ / "drive";
    rec_ = root_ / "rec";
    fs::create_directories(drive_ / "gt");
    fs::create_directories(rec_ / "stats");
    WriteRigJson(MakeRig(), drive_ / "rig.json");
    gt_poses_ = MakeGtPoses(120);
    WriteTum(gt_poses_, drive_ / "gt" / "poses.tum");
    gt_mesh_ = MakeStreet();
    WritePlyMesh(gt_mesh_, drive_ / "gt" / "mesh.ply");
  }
  void TearDown() override { fs::remove_all(root_); }

  // The reconstruction: every 4th frame, in a world frame related to GT by a similarity.
  void WriteReconstruction(const Sim3d& estimated_from_gt, const TriangleMesh& gt_frame_surface) {
    std::vector<StampedPose> keyframes;
    for (size_t f = 0; f < gt_poses_.size(); f += 4) {
      StampedPose pose = gt_poses_[f];
      pose.world_from_rig = TransformPose(estimated_from_gt, pose.world_from_rig);
      keyframes.push_back(pose);
    }
    WriteTum(keyframes, rec_ / "poses.tum");
    TriangleMesh surface = gt_frame_surface;
    for (auto& v : surface.vertices) v = estimated_from_gt * v;
    WritePlyMesh(surface, rec_ / "surface.ply");
    PointCloud cloud;
    for (const auto& v : gt_frame_surface.vertices) cloud.points.push_back(estimated_from_gt * v);
    WritePlyPoints(cloud, rec_ / "points.ply");
    std::ofstream(rec_ / "stats" / "keyframes.csv")
        << "keyframe,points_in,E,enclose_ms,grow_ms\n0,10,1000,1.5,2.0\n1,12,1100,1.7,2.2\n"
           "2,9,1050,1.6,2.1\n";
  }

  static EvalOptions SmallOptions() {
    EvalOptions options;
    options.ray_errors.pixels = 20000;
    options.surfaces.samples = 20000;
    options.surfaces.visibility_rays = 50000;
    options.render_width = 200;
    options.keyframe_views = 2;
    return options;
  }

  fs::path root_, drive_, rec_;
  std::vector<StampedPose> gt_poses_;
  TriangleMesh gt_mesh_;
};

const Sim3d kEstimatedFromGt(
    0.2, Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d(0.2, 0.3, 1).normalized())),
    Eigen::Vector3d(3, -4, 1));

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

TEST_F(EvalTest, SurfaceShiftedTenCentimetresAlongItsNormals) {
  // The street's blocks are boxes: shrink each by 10 cm on every face, and the enclosing box
  // too (inwards, its normals' direction).
  TriangleMesh shifted = FlipOrientation(MakeBox({-19.9, -19.9, -0.9}, {79.9, 19.9, 29.9}));
  for (int i = 0; i < 5; ++i) {
    AppendMesh(MakeBox({i * 12.0 + 0.1, 6.1, -0.9}, {i * 12.0 + 8.9, 11.9, 7.9 + i}), &shifted);
    AppendMesh(MakeBox({i * 12.0 + 3.1, -11.9, -0.9}, {i * 12.0 + 10.9, -6.1, 9.9 - i}), &shifted);
  }
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

// The command line.
int RunOmnisculpt(const std::string& arguments, std::string* output = nullptr) {
  const std::string command = std::string(OMNI_EXECUTABLE) + " " + arguments + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  std::string text;
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) text.append(buffer, n);
  const int status = pclose(pipe);
  if (output) *output = text;
  return WEXITSTATUS(status);
}

TEST_F(EvalTest, CommandLine) {
  std::string output;
  WritePlyMesh(MakeTorus(3, 1, 16, 8), root_ / "torus.ply");
  EXPECT_EQ(RunOmnisculpt("mesh-check " + (root_ / "torus.ply").string(), &output), 0) << output;
  EXPECT_NE(output.find("genus 1"), std::string::npos) << output;
  TriangleMesh cubes = MakeBox({0, 0, 0}, {1, 1, 1});
  AppendMesh(MakeBox({1, 1, 1}, {2, 2, 2}), &cubes);
  WritePlyMesh(WeldVertices(cubes), root_ / "cubes.ply");
  EXPECT_EQ(RunOmnisculpt("mesh-check --json " + (root_ / "cubes.ply").string(), &output), 1)
      << output;
  EXPECT_NE(output.find("\"nonmanifold_vertices\": 1"), std::string::npos) << output;
  EXPECT_EQ(RunOmnisculpt("mesh-check " + (root_ / "missing.ply").string(), &output), 2) << output;

  EXPECT_EQ(RunOmnisculpt("render " + (drive_ / "gt" / "mesh.ply").string() +
                              " --bird --width 64 --out " + (root_ / "bird.png").string(),
                          &output),
            0)
      << output;
  EXPECT_TRUE(fs::exists(root_ / "bird.png"));
  EXPECT_EQ(RunOmnisculpt("render " + (drive_ / "gt" / "mesh.ply").string() +
                              " --pose '5 0 2 0 0 0 1' --rig " + (drive_ / "rig.json").string() +
                              " --camera cam1 --width 24 --out " + (root_ / "view.png").string(),
                          &output),
            0)
      << output;
  EXPECT_TRUE(fs::exists(root_ / "view.png"));
  EXPECT_EQ(
      RunOmnisculpt("render " + (drive_ / "gt" / "mesh.ply").string() + " --out x.png", &output),
      2);

  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  EXPECT_EQ(RunOmnisculpt("eval --gt " + drive_.string() + " --rec " + rec_.string() +
                              " --pixels 5000 --samples 5000 --no-plots --no-renders",
                          &output),
            0)
      << output;
  EXPECT_TRUE(fs::exists(rec_ / "report" / "eval.json"));
  EXPECT_NE(output.find("pose registration RMS 0.0 cm over 30 keyframes"), std::string::npos)
      << output;
  EXPECT_EQ(RunOmnisculpt("eval --gt " + drive_.string() + " --rec " + (root_ / "nowhere").string(),
                          &output),
            2);
  EXPECT_NE(output.find("poses.tum"), std::string::npos) << output;
}

}  // namespace
}  // namespace omni
