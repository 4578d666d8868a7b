// `omnisculpt reconstruct`: the whole pipeline on the short synthetic drive (fixture
// short_drive): outputs, manifold mesh, pose error, resume-safe output folder, a corrupt image
// skipped, loop closure.

#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>
#include <thread>

#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "eval/pose_eval.h"
#include "pipeline/reconstruction.h"
#include "surface/sculptor.h"
#include "tests/apps/point_colors_check.h"
#include "tests/apps/reconstruction_checks.h"
#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

namespace fs = std::filesystem;
using testing::PoseRms;
using testing::ReadTextFile;
using testing::RunOmnisculpt;
using testing::SplitText;

// surface.ply: an oriented 2-manifold with boundary.
MeshCheckReport CheckBounded(const TriangleMesh& mesh) {
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  return CheckMesh(mesh, bounded);
}

fs::path ScratchDir(const std::string& name) { return testing::ScratchDir("reconstruct", name); }

TEST(ReconstructCommand, RefusesAMissingOutAndABadDrive) {
  const fs::path scratch = ScratchDir("bad_input");
  EXPECT_EQ(RunOmnisculpt({"reconstruct", (scratch / "nothing").string()}, scratch).exit_code, 2);
  const auto result = RunOmnisculpt(
      {"reconstruct", (scratch / "nothing").string(), "--out", (scratch / "out").string()},
      scratch);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_FALSE(fs::exists(scratch / "out"));
  EXPECT_FALSE(fs::exists(scratch / "out.incomplete"));
  const auto enclosing = RunOmnisculpt({"reconstruct", (scratch / "nothing").string(), "--out",
                                        (scratch / "out").string(), "--enclosing", "cube"},
                                       scratch);
  EXPECT_EQ(enclosing.exit_code, 2);
  EXPECT_NE(enclosing.err.find("--enclosing"), std::string::npos) << enclosing.err;
  EXPECT_FALSE(fs::exists(scratch / "out.incomplete"));
  const auto steps = RunOmnisculpt({"reconstruct", OMNI_SHORT_DRIVE_DIR, "--out",
                                    (scratch / "out").string(), "--keyframes-per-step", "0"},
                                   scratch);
  EXPECT_EQ(steps.exit_code, 2);
  EXPECT_EQ(std::count(steps.err.begin(), steps.err.end(), '\n'), 1) << steps.err;
  EXPECT_NE(steps.err.find("keyframes_per_step"), std::string::npos) << steps.err;
  EXPECT_FALSE(fs::exists(scratch / "out.incomplete"));
}

// A drive with the first `frames` frames of the short drive (images linked, not copied).
fs::path LinkShortDrive(const fs::path& scratch, int frames) {
  const fs::path source(OMNI_SHORT_DRIVE_DIR);
  const fs::path drive = scratch / "drive";
  fs::create_directories(drive);
  fs::copy_file(source / "rig.json", drive / "rig.json");
  fs::create_directories(drive / "gt");
  fs::copy_file(source / "gt" / "poses.tum", drive / "gt" / "poses.tum");
  for (const auto& camera : fs::directory_iterator(source / "images")) {
    std::vector<fs::path> images;
    for (const auto& image : fs::directory_iterator(camera.path())) images.push_back(image.path());
    std::sort(images.begin(), images.end());
    const fs::path target = drive / "images" / camera.path().filename();
    fs::create_directories(target);
    for (int f = 0; f < frames && f < static_cast<int>(images.size()); ++f)
      fs::create_symlink(images[f], target / images[f].filename());
  }
  return drive;
}

// The integer column `name` of a CSV file's lines (`rows`, the header first), one value per row
// after the header; a failure and no values when there is no such column.
std::vector<int> IntColumn(const std::vector<std::string>& rows, const std::string& name) {
  const std::vector<std::string> header = SplitText(rows.at(0), ',');
  const size_t column = std::find(header.begin(), header.end(), name) - header.begin();
  std::vector<int> values;
  if (column == header.size()) {
    ADD_FAILURE() << "no column " << name << " in " << rows[0];
    return values;
  }
  for (size_t r = 1; r < rows.size(); ++r)
    values.push_back(std::stoi(SplitText(rows[r], ',').at(column)));
  return values;
}

TEST(ReconstructShortDrive, EveryStageRunsAndTheSurfaceIsAManifold) {
  const fs::path scratch = ScratchDir("end_to_end");
  const fs::path drive(OMNI_SHORT_DRIVE_DIR);
  const fs::path out = scratch / "rec";
  const auto result = RunOmnisculpt(
      {"--quiet", "reconstruct", drive.string(), "--out", out.string(), "--snapshot-every", "20",
       "--sculpt-superseded"},  // rows for every keyframe, however far the surface fell behind
      scratch);
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_FALSE(fs::exists(fs::path(out.string() + ".incomplete")));
  EXPECT_FALSE(fs::exists(out / "INCOMPLETE"));
  // Every output of a drive folder's reconstruction (docs/design.md §4) that the pipeline writes.
  for (const char* file : {"poses.tum", "points.ply", "surface.ply", "surface_closed.ply",
                           "reconstruct.json", "stats/keyframes.csv", "stats/sfm_frames.csv",
                           "sparse/cameras.txt", "sparse/images.txt", "sparse/points3D.txt"})
    EXPECT_TRUE(fs::exists(out / file)) << file;
  // Each snapshot: δO, closed (surface_<keyframe>.ply), and its observed part
  // (observed_<keyframe>.ply), bounded, fewer triangles, a colour per vertex as surface.ply.
  size_t observed_snapshots = 0;
  for (const auto& entry : fs::directory_iterator(out / "snapshots")) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("observed_", 0) != 0) continue;
    ++observed_snapshots;
    const TriangleMesh observed_snapshot = ReadPlyMesh(entry.path());
    const MeshCheckReport observed_check = CheckBounded(observed_snapshot);
    EXPECT_TRUE(observed_check.ok) << name << ": " << observed_check.ToText();
    EXPECT_EQ(observed_snapshot.colors.size(), observed_snapshot.vertices.size()) << name;
    const TriangleMesh closed_snapshot =
        ReadPlyMesh(out / "snapshots" / ("surface_" + name.substr(9)));
    EXPECT_TRUE(CheckMesh(closed_snapshot).ok) << name;
    EXPECT_LT(observed_snapshot.triangles.size(), closed_snapshot.triangles.size()) << name;
    EXPECT_GT(observed_snapshot.triangles.size(), 0u) << name;
  }
  EXPECT_GE(observed_snapshots, 1u);

  // surface_closed.ply: δO, closed; surface.ply: its observed part, bounded, fewer triangles,
  // both with a colour per vertex (grey: the synthetic city is grey).
  const TriangleMesh closed = ReadPlyMesh(out / "surface_closed.ply");
  EXPECT_GT(closed.triangles.size(), 1000u);
  const MeshCheckReport check = CheckMesh(closed);
  EXPECT_TRUE(check.ok) << check.ToText();
  const TriangleMesh mesh = ReadPlyMesh(out / "surface.ply");
  EXPECT_GT(mesh.triangles.size(), closed.triangles.size() / 2);
  EXPECT_LT(mesh.triangles.size(), closed.triangles.size());
  const MeshCheckReport observed = CheckBounded(mesh);
  EXPECT_TRUE(observed.ok) << observed.ToText();
  EXPECT_GT(observed.boundary_loops, 0);
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  ASSERT_EQ(closed.colors.size(), closed.vertices.size());
  for (const Rgb8& color : mesh.colors) EXPECT_TRUE(color[0] == color[1] && color[1] == color[2]);

  const std::vector<StampedPose> poses = ReadTum(out / "poses.tum");
  const nlohmann::json summary = nlohmann::json::parse(ReadTextFile(out / "reconstruct.json"));
  EXPECT_EQ(summary["keyframes"].get<size_t>(), poses.size());
  EXPECT_GT(poses.size(), 20u);
  EXPECT_EQ(summary["frames_skipped"].get<int>(), 0);
  EXPECT_EQ(summary["triangles"].get<size_t>(), mesh.triangles.size());
  EXPECT_LE(summary["queue_max_size"].get<int>(), summary["queue_capacity"].get<int>());
  EXPECT_EQ(summary["surface_keyframes_skipped"].get<size_t>(), 0u);  // --sculpt-superseded
  // The short drive is ~105 m long: a pose error after similarity registration below 1 m
  // means the SfM tracked the whole drive.
  EXPECT_LT(PoseRms(out, drive), 1.0);

  // Per-keyframe stats: one row per sculpted keyframe (the batch one row), with queue_ms.
  const std::vector<std::string> rows = SplitText(ReadTextFile(out / "stats" / "keyframes.csv"));
  ASSERT_GE(rows.size(), 2u);
  EXPECT_NE(rows[0].find(",queue_ms"), std::string::npos);
  // Every keyframe reached the sculptor: the first 40 in one batch row (paper §5.1), then one
  // row each; and every point of points.ply was handed over.
  const size_t init = SculptorOptions().init_keyframes;
  ASSERT_GT(poses.size(), init);
  // Only the rows of the last sculpting count (after a loop closure the sculptor is replayed on
  // the corrected keyframes; the last column numbers the replays). A batch replay (the
  // default) sculpts all the keyframes of the corrected map in its batch row.
  const std::string last_replay = SplitText(rows.back(), ',').back();
  size_t batch_keyframes = init;
  if (last_replay != "0") {
    ASSERT_EQ(summary["loop_replay"].get<std::string>(), "batch");
    const size_t replay = std::stoul(last_replay);
    if (replay > summary["loop_closures"].size()) {
      // The final bundle adjustment's replay, after the loop closures': every keyframe.
      ASSERT_TRUE(summary["final_bundle_adjustment"]["ran"].get<bool>());
      EXPECT_EQ(replay, summary["loop_closures"].size() + 1);
      batch_keyframes = poses.size();
    } else {
      batch_keyframes =
          summary["loop_closures"][replay - 1]["surface_replay_keyframes"].get<size_t>();
    }
    EXPECT_GT(batch_keyframes, init);
  }
  size_t points_in = 0, final_rows = 0, final_batch_rows = 0;
  for (size_t r = 1; r < rows.size(); ++r) {
    const std::vector<std::string> columns = SplitText(rows[r], ',');
    if (columns.back() != last_replay) continue;
    if (columns[1] == "1") {
      EXPECT_EQ(final_rows, 0u) << "the batch row comes first";
      ++final_batch_rows;
    }
    ++final_rows;
    points_in += std::stoul(columns[2]);
  }
  EXPECT_EQ(final_batch_rows, 1u);
  EXPECT_EQ(final_rows, 1 + poses.size() - batch_keyframes);
  // The default enclosing set is the conflict zones (paper §6's future work), widened where the
  // shrink left O in them on some keyframes.
  EXPECT_EQ(summary["enclosing"].get<std::string>(), "conflict");
  const std::vector<int> rounds = IntColumn(rows, "enclose_rounds");
  EXPECT_GT(std::count_if(rounds.begin(), rounds.end(), [](int n) { return n > 0; }), 0);
  EXPECT_EQ(points_in, ReadPlyPoints(out / "points.ply").points.size());
  EXPECT_EQ(SplitText(ReadTextFile(out / "stats" / "sfm_frames.csv")).size(),
            1 + summary["frames"].get<size_t>());

  // The sfm command's statistics files, whose totals agree with reconstruct.json and the
  // other files.
  std::map<std::string, double> sfm_summary, sfm_stages;
  for (const auto& [file, values] :
       {std::pair{"sfm_summary.csv", &sfm_summary}, std::pair{"sfm_stages.csv", &sfm_stages}}) {
    const std::vector<std::string> lines = SplitText(ReadTextFile(out / "stats" / file));
    ASSERT_GE(lines.size(), 2u) << file;
    for (size_t i = 1; i < lines.size(); ++i) {
      const std::vector<std::string> columns = SplitText(lines[i], ',');
      ASSERT_GE(columns.size(), 2u) << lines[i];
      (*values)[columns[0]] = std::stod(columns[1]);
    }
  }
  EXPECT_EQ(sfm_summary["frames"], summary["frames"].get<double>());
  EXPECT_EQ(sfm_summary["frames_skipped"], summary["frames_skipped"].get<double>());
  EXPECT_EQ(sfm_summary["frames_not_tracked"], summary["frames_not_tracked"].get<double>());
  EXPECT_EQ(sfm_summary["keyframes"], static_cast<double>(poses.size()));
  EXPECT_EQ(sfm_summary["points"], summary["points"].get<double>());
  EXPECT_EQ(sfm_summary["points"], static_cast<double>(points_in));
  EXPECT_NEAR(sfm_summary["mean_reprojection_error_px"],
              summary["colmap_mean_reprojection_error_px"].get<double>(), 1e-4);
  EXPECT_GT(sfm_summary["mean_inliers_per_tracked_frame"], 30.0);
  EXPECT_GE(sfm_summary["mean_matched_per_frame"], sfm_summary["mean_inliers_per_tracked_frame"]);
  // Observations: the 2-D points with a 3-D point in images.txt.
  size_t observations = 0;
  {
    const std::vector<std::string> lines = SplitText(ReadTextFile(out / "sparse" / "images.txt"));
    size_t i = 0;
    while (i < lines.size() && lines[i].rfind('#', 0) == 0) ++i;
    for (i += 1; i < lines.size(); i += 2) {
      std::istringstream in(lines[i]);
      double x, y;
      long point;
      while (in >> x >> y >> point) observations += point >= 0;
    }
  }
  EXPECT_EQ(sfm_summary["observations"], static_cast<double>(observations));
  const double sfm_seconds = summary["sfm_seconds"].get<double>();
  EXPECT_NEAR(sfm_stages["total"], sfm_seconds, 1e-4 * sfm_seconds);
  double stages_sum = 0.0;
  for (const char* stage : {"load_wait", "detect", "match", "resect", "triangulate", "map_search",
                            "bundle_adjustment", "loop_closure", "final_bundle_adjustment",
                            "final_frame_refinement", "queue_wait", "other"}) {
    ASSERT_EQ(sfm_stages.count(stage), 1u) << stage;
    EXPECT_GE(sfm_stages[stage], 0.0) << stage;
    stages_sum += sfm_stages[stage];
  }
  // The corners are detected on the prefetch thread (detect_ahead, outside the total).
  EXPECT_EQ(sfm_stages["detect"], 0.0);
  EXPECT_GT(sfm_stages["detect_ahead"], 0.0);
  EXPECT_GT(sfm_stages["bundle_adjustment"], 0.0);
  // The stages are parts of the SfM thread's time, "other" the rest.
  EXPECT_NEAR(stages_sum, sfm_stages["total"], 1e-3 * sfm_stages["total"]);
  EXPECT_NEAR(sfm_stages["queue_wait"], summary["queue_blocked_seconds"].get<double>(), 1e-3);

  // Points coloured from the (grey) images: the mean pixel over each point's observations.
  testing::ExpectPointColoursAreImageMeans(drive, out, 300);

  // A second run refuses the non-empty folder, and --force does not touch a folder of other
  // files.
  EXPECT_EQ(
      RunOmnisculpt({"--quiet", "reconstruct", drive.string(), "--out", out.string()}, scratch)
          .exit_code,
      2);
  const fs::path mine = scratch / "mine";
  fs::create_directories(mine);
  std::ofstream(mine / "notes.txt") << "keep me\n";
  EXPECT_EQ(RunOmnisculpt({"--quiet", "reconstruct", drive.string(), "--out", mine.string(),
                           "--force", "--max-frames", "10"},
                          scratch)
                .exit_code,
            2);
  EXPECT_EQ(ReadTextFile(mine / "notes.txt"), "keep me\n");
}

TEST(ReconstructShortDrive, TheBallEnclosingSetGivesAManifoldToo) {
  // --enclosing ball (the paper's E, §4.1; the default is the conflict zones) through the
  // whole pipeline, loop closure and batch replay included.
  const fs::path scratch = ScratchDir("enclosing_ball");
  const fs::path drive(OMNI_SHORT_DRIVE_DIR);
  const fs::path out = scratch / "rec";
  const auto result = RunOmnisculpt(
      {"--quiet", "reconstruct", drive.string(), "--out", out.string(), "--enclosing", "ball"},
      scratch);
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const nlohmann::json summary = nlohmann::json::parse(ReadTextFile(out / "reconstruct.json"));
  EXPECT_EQ(summary["enclosing"].get<std::string>(), "ball");
  EXPECT_TRUE(summary["manifold"].get<bool>());
  EXPECT_TRUE(summary["closed_manifold"].get<bool>());
  const TriangleMesh mesh = ReadPlyMesh(out / "surface_closed.ply");
  EXPECT_GT(mesh.triangles.size(), 1000u);
  const MeshCheckReport check = CheckMesh(mesh);
  EXPECT_TRUE(check.ok) << check.ToText();
  EXPECT_TRUE(CheckBounded(ReadPlyMesh(out / "surface.ply")).ok);
  // The ball is what the keyframes used: it is never widened (the conflict zones are, on this
  // drive: ReconstructShortDrive.EveryStageRunsAndTheSurfaceIsAManifold).
  const std::vector<std::string> rows = SplitText(ReadTextFile(out / "stats" / "keyframes.csv"));
  const std::vector<int> rounds = IntColumn(rows, "enclose_rounds");
  const std::vector<int> keyframes = IntColumn(rows, "keyframes");  // sculpted in each row's step
  ASSERT_EQ(keyframes.size(), rounds.size());
  ASSERT_GT(std::accumulate(keyframes.begin(), keyframes.end(), 0), 9);
  for (size_t r = 0; r < rounds.size(); ++r) EXPECT_EQ(rounds[r], 0) << rows[r + 1];
}

// The rays of the points that the aperture bound drops carve short of them by default
// (SculptorOptions::uncertain_ray_margin_deg): against the same run without them (the SfM is
// the same to the last bit, only the surface differs), surface.ply has fewer pixels whose
// surface lies more than 1 m in front of the ground truth (1.7 % against 2.6 % when measured)
// and a higher pixel F-score at 0.2 m, scored by `omnisculpt eval`; both surfaces manifolds.
TEST(ReconstructShortDrive, TheRaysOfNarrowAperturePointsLowerTheFalseMatterInFront) {
  const fs::path scratch = ScratchDir("uncertain_rays");
  const fs::path drive(OMNI_SHORT_DRIVE_DIR);
  auto reconstruct_and_eval = [&](const std::string& name, std::vector<std::string> extra) {
    const fs::path out = scratch / name;
    std::vector<std::string> args = {"--quiet", "reconstruct", drive.string(), "--out",
                                     out.string()};
    args.insert(args.end(), extra.begin(), extra.end());
    auto run = RunOmnisculpt(args, scratch);
    EXPECT_EQ(run.exit_code, 0) << run.err;
    EXPECT_TRUE(CheckBounded(ReadPlyMesh(out / "surface.ply")).ok) << name;
    EXPECT_TRUE(CheckMesh(ReadPlyMesh(out / "surface_closed.ply")).ok) << name;
    const nlohmann::json summary = nlohmann::json::parse(ReadTextFile(out / "reconstruct.json"));
    EXPECT_EQ(summary["uncertain_rays"].get<size_t>() > 0, extra.empty()) << name;
    run = RunOmnisculpt({"--quiet", "eval", "--gt", drive.string(), "--rec", out.string(),
                         "--no-plots", "--no-renders"},
                        scratch);
    EXPECT_EQ(run.exit_code, 0) << run.err;
    return nlohmann::json::parse(ReadTextFile(out / "report" / "eval.json"))["pixel"];
  };
  const nlohmann::json with = reconstruct_and_eval("default", {});
  const nlohmann::json without = reconstruct_and_eval("without", {"--uncertain-ray-margin", "0"});
  const double front_with = with["tail_front"].get<double>();
  const double front_without = without["tail_front"].get<double>();
  const double f_with = with["precision_recall"][0]["f_score"].get<double>();
  const double f_without = without["precision_recall"][0]["f_score"].get<double>();
  ASSERT_EQ(with["precision_recall"][0]["threshold_m"].get<double>(), 0.2);
  std::printf("in front above 1 m %.2f %% -> %.2f %%, pixel F@0.2 %.3f -> %.3f\n",
              100 * front_without, 100 * front_with, f_without, f_with);
  EXPECT_LT(front_with, front_without - 0.002);
  EXPECT_GT(f_with, f_without);
}

TEST(ReconstructShortDrive, AKilledRunLeavesNothingThatLooksComplete) {
  const fs::path scratch = ScratchDir("killed");
  const fs::path out = scratch / "rec";
  const fs::path partial = scratch / "rec.incomplete";
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    const int null = open("/dev/null", O_WRONLY);
    dup2(null, 1);
    dup2(null, 2);
    execl(OMNI_EXECUTABLE, OMNI_EXECUTABLE, "--quiet", "reconstruct", OMNI_SHORT_DRIVE_DIR, "--out",
          out.c_str(), static_cast<char*>(nullptr));
    _exit(127);
  }
  // Kill it once it has started writing (the keyframes' snapshots need a while).
  for (int i = 0; i < 200 && !fs::exists(partial / "INCOMPLETE"); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  std::this_thread::sleep_for(std::chrono::milliseconds(1500));
  kill(child, SIGKILL);
  int status = 0;
  waitpid(child, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status)) << "the run finished before it was killed";
  EXPECT_FALSE(fs::exists(out));
  EXPECT_TRUE(fs::exists(partial / "INCOMPLETE"));
  EXPECT_FALSE(fs::exists(partial / "reconstruct.json"));

  // The next run reuses the interrupted folder and publishes a complete one.
  const auto result = RunOmnisculpt(
      {"--quiet", "reconstruct", OMNI_SHORT_DRIVE_DIR, "--out", out.string(), "--max-frames", "24"},
      scratch);
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_TRUE(fs::exists(out / "reconstruct.json"));
  EXPECT_FALSE(fs::exists(partial));
}

TEST(ReconstructShortDrive, ACorruptImageIsReportedAndItsFrameSkipped) {
  const fs::path scratch = ScratchDir("corrupt");
  const fs::path drive = LinkShortDrive(scratch, 30);
  fs::path victim;
  for (const auto& image : fs::directory_iterator(drive / "images" / "cam2"))
    if (image.path().stem() == "000012") victim = image.path();
  ASSERT_FALSE(victim.empty());
  fs::remove(victim);
  std::ofstream(victim, std::ios::binary) << "not a png at all";
  const fs::path out = scratch / "rec";
  const auto result =
      RunOmnisculpt({"--quiet", "reconstruct", drive.string(), "--out", out.string()}, scratch);
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE((result.out + result.err).find("000012"), std::string::npos) << result.err;
  const nlohmann::json summary = nlohmann::json::parse(ReadTextFile(out / "reconstruct.json"));
  EXPECT_EQ(summary["frames_skipped"].get<int>(), 1);
  const std::vector<std::string> rows = SplitText(ReadTextFile(out / "stats" / "sfm_frames.csv"));
  ASSERT_EQ(rows.size(), 31u);
  EXPECT_EQ(rows[13].rfind("12,000012,0,", 0), 0u) << rows[13];
  // The frames around it were tracked.
  const std::vector<int> loaded = IntColumn(rows, "loaded"), tracked = IntColumn(rows, "tracked");
  ASSERT_EQ(loaded.size(), 30u);
  ASSERT_EQ(tracked.size(), 30u);
  for (int f : {11, 14}) {
    EXPECT_EQ(loaded[f], 1) << rows[f + 1];
    EXPECT_EQ(tracked[f], 1) << rows[f + 1];
  }
  EXPECT_TRUE(CheckMesh(ReadPlyMesh(out / "surface_closed.ply")).ok);
  EXPECT_TRUE(CheckBounded(ReadPlyMesh(out / "surface.ply")).ok);
}

// Registered start-to-end offset error: how far apart the first and last keyframes are,
// compared with the ground truth, after the similarity registration (0 when the loop meets as
// it should).
double LoopGap(const fs::path& rec, const fs::path& drive) {
  const PoseEvalResult eval =
      EvaluatePoses(ReadTum(rec / "poses.tum"), ReadTum(drive / "gt" / "poses.tum"));
  const MatchedPose& first = eval.matches.front();
  const MatchedPose& last = eval.matches.back();
  return ((last.registered_world_from_rig.translation -
           first.registered_world_from_rig.translation) -
          (last.gt_world_from_rig.translation - first.gt_world_from_rig.translation))
      .norm();
}

TEST(ReconstructShortDrive, LoopClosureLowersThePoseErrorAndTheLoopMeets) {
  const fs::path scratch = ScratchDir("loop");
  const fs::path drive(OMNI_SHORT_DRIVE_DIR);
  const fs::path with = scratch / "with", without = scratch / "without";
  auto run = RunOmnisculpt(
      {"--quiet", "reconstruct", drive.string(), "--out", with.string(), "--loop-replay", "batch",
       "--sculpt-superseded"},  // rows for every keyframe, however far the surface fell behind
      scratch);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  run = RunOmnisculpt(
      {"--quiet", "reconstruct", drive.string(), "--out", without.string(), "--no-loop-closure"},
      scratch);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const nlohmann::json summary = nlohmann::json::parse(ReadTextFile(with / "reconstruct.json"));
  ASSERT_GE(summary["loop_closures"].size(), 1u) << summary.dump(2);
  const nlohmann::json& loop = summary["loop_closures"][0];
  // The drive passes its start again at its end: the revisit is late, the place is early, and
  // the two frames are truly close (ground truth).
  const int revisit = loop["frame"].get<int>(), place = loop["candidate_frame"].get<int>();
  EXPECT_GT(revisit, 90);
  EXPECT_LT(place, 30);
  const std::vector<StampedPose> truth = ReadTum(drive / "gt" / "poses.tum");
  EXPECT_LT(
      (truth.at(revisit).world_from_rig.translation - truth.at(place).world_from_rig.translation)
          .norm(),
      3.0);
  EXPECT_GT(summary["surface_replay_seconds"].get<double>(), 0.0);
  EXPECT_EQ(
      nlohmann::json::parse(ReadTextFile(without / "reconstruct.json"))["loop_closures"].size(),
      0u);

  // After the closure (pose graph, fused loop points, global adjustment) the trajectory is
  // more accurate than without it, and the start and end of the loop meet.
  const double rms_with = PoseRms(with, drive), rms_without = PoseRms(without, drive);
  const double gap_with = LoopGap(with, drive), gap_without = LoopGap(without, drive);
  std::printf(
      "without -> with loop closure: pose RMS %.3f -> %.3f m, start-end gap %.3f -> "
      "%.3f m\n",
      rms_without, rms_with, gap_without, gap_with);
  EXPECT_LT(rms_with, rms_without);
  EXPECT_LT(rms_with, 0.25);
  // The short drive drifts little: over runs the start-end gap was 6 to 17 cm without the
  // closure and 3 to 6 cm with it, so comparing the two gaps is within the SfM's run-to-run
  // noise (it failed once that way); the gap with the closure must be small in itself.
  EXPECT_LT(gap_with, 0.1);

  // The final surface is the corrected map's: a replay row in the stats, and a manifold.
  const std::vector<std::string> rows = SplitText(ReadTextFile(with / "stats" / "keyframes.csv"));
  EXPECT_NE(rows[0].find(",queue_ms,replay"), std::string::npos);
  const std::string replays = std::to_string(summary["loop_closures"].size());
  // The last sculpting is the final bundle adjustment's replay, one batch of every keyframe.
  ASSERT_TRUE(summary["final_bundle_adjustment"]["ran"].get<bool>());
  EXPECT_EQ(SplitText(rows.back(), ',').back(),
            std::to_string(summary["loop_closures"].size() + 1));
  EXPECT_EQ(SplitText(rows.back(), ',').at(1), "1");  // batch
  const MeshCheckReport check = CheckMesh(ReadPlyMesh(with / "surface_closed.ply"));
  EXPECT_TRUE(check.ok) << check.ToText();
  EXPECT_TRUE(CheckBounded(ReadPlyMesh(with / "surface.ply")).ok);
  EXPECT_TRUE(summary["manifold"].get<bool>());
  EXPECT_TRUE(summary["closed_manifold"].get<bool>());
  // The batch replay: the corrected keyframes handed over before the closure (all but the
  // local window, so more than the 40 of §5.1 and at most up to the revisit) in the first row
  // of the last sculpting, a batch row with all their points; then one row per keyframe.
  EXPECT_EQ(summary["loop_replay"].get<std::string>(), "batch");
  const nlohmann::json& last_loop = summary["loop_closures"].back();
  const size_t replayed = last_loop["surface_replay_keyframes"].get<size_t>();
  EXPECT_GT(replayed, static_cast<size_t>(SculptorOptions().init_keyframes));
  EXPECT_LE(replayed, last_loop["keyframe"].get<size_t>() + 1);
  std::vector<std::vector<std::string>> last_rows;
  for (size_t r = 1; r < rows.size(); ++r) {
    std::vector<std::string> columns = SplitText(rows[r], ',');
    if (columns.back() == replays) last_rows.push_back(std::move(columns));
  }
  ASSERT_FALSE(last_rows.empty());
  EXPECT_EQ(last_rows[0][1], "1");  // batch
  for (size_t r = 1; r < last_rows.size(); ++r) EXPECT_EQ(last_rows[r][1], "0");
  // The batch row holds the replayed keyframes, each later row a step of keyframes_per_step; the
  // final replay takes over with fewer than a step waiting.
  const std::vector<std::string> header = SplitText(rows[0], ',');
  const size_t keyframes_column =
      std::find(header.begin(), header.end(), "keyframes") - header.begin();
  ASSERT_LT(keyframes_column, header.size());
  const size_t per_step = static_cast<size_t>(PipelineOptions().sculptor.keyframes_per_step);
  EXPECT_EQ(std::stoul(last_rows[0][keyframes_column]), replayed);
  size_t sculpted = 0;
  for (size_t r = 0; r < last_rows.size(); ++r) {
    if (r > 0) {
      EXPECT_EQ(std::stoul(last_rows[r][keyframes_column]), per_step);
    }
    sculpted += std::stoul(last_rows[r][keyframes_column]);
  }
  const size_t keyframes = summary["keyframes"].get<size_t>();
  EXPECT_LE(sculpted, keyframes);
  EXPECT_GT(sculpted + per_step, keyframes);
  EXPECT_GT(std::stoul(last_rows[0][2]), 0u);  // points_in
}

}  // namespace
}  // namespace omni
