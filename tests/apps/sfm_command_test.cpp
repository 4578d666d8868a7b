// `omnisculpt sfm` end to end on the short synthetic drive (fixture short_drive):
// every frame tracked, the keyframe trajectory within 1 % of the distance driven after
// similarity registration to the ground truth, the points on the ground-truth surface, the
// outputs present, and the COLMAP text model read back by pipeline/colmap_keyframes; bad
// arguments are one error line with exit code 2.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "calib/colmap_text.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "eval/pose_eval.h"
#include "pipeline/colmap_keyframes.h"
#include "raycast/raycast.h"
#include "tests/apps/point_colors_check.h"
#include "tests/apps/run_omnisculpt.h"
#include "tests/apps/short_drive.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

class SfmCommandShortDrive : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { dir_ = new testing::TempDir("sfm_command_test"); }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    std::string error;
    drive_ = testing::ShortDrive(&error);
    ASSERT_FALSE(drive_.empty()) << error;
  }
  static testing::CommandResult Run(const std::vector<std::string>& arguments) {
    return testing::RunOmnisculpt(arguments, dir_->path());
  }

  // Runs the SfM on the drive's first `frames` frames (0: all) and checks the end-to-end
  // contract: outputs present, every frame tracked, ATE below 1 % of the distance driven.
  void CheckEndToEnd(const std::string& mode, int frames, fs::path* out_folder = nullptr) {
    const fs::path out = dir_->path() / ("sfm" + mode);
    if (out_folder) *out_folder = out;
    std::vector<std::string> arguments = {"--quiet", "sfm",        drive_.string(),
                                          "--out",   out.string(), mode};
    if (frames > 0) {
      arguments.push_back("--max-frames");
      arguments.push_back(std::to_string(frames));
    }
    const testing::CommandResult result = Run(arguments);
    ASSERT_EQ(result.exit_code, 0) << result.out << result.err;
    for (const char* file : {"poses.tum", "points.ply", "stats/sfm_frames.csv",
                             "stats/sfm_stages.csv", "stats/sfm_summary.csv", "sparse/cameras.txt",
                             "sparse/images.txt", "sparse/points3D.txt"})
      ASSERT_TRUE(fs::exists(out / file)) << file;

    // Every frame tracked (the tracked column of stats/sfm_frames.csv).
    const std::vector<std::string> rows =
        testing::SplitText(testing::ReadTextFile(out / "stats" / "sfm_frames.csv"));
    ASSERT_GE(rows.size(), 2u);
    const std::vector<std::string> header = testing::SplitText(rows[0], ',');
    const auto tracked_column = std::find(header.begin(), header.end(), "tracked");
    ASSERT_NE(tracked_column, header.end()) << rows[0];
    const size_t column = tracked_column - header.begin();
    const std::vector<StampedPose> gt = ReadTum(drive_ / "gt" / "poses.tum");
    const size_t expected_frames = frames > 0 ? static_cast<size_t>(frames) : gt.size();
    EXPECT_EQ(rows.size() - 1, expected_frames);
    for (size_t r = 1; r < rows.size(); ++r) {
      const std::vector<std::string> fields = testing::SplitText(rows[r], ',');
      ASSERT_GT(fields.size(), column) << rows[r];
      EXPECT_EQ(fields[column], "1") << "frame not tracked: " << rows[r];
    }

    // ATE of the keyframes after similarity registration, against the distance driven.
    const std::vector<StampedPose> estimated = ReadTum(out / "poses.tum");
    ASSERT_GE(estimated.size(), 3u);
    const PoseEvalResult eval = EvaluatePoses(estimated, gt);
    EXPECT_EQ(eval.matches.size(), estimated.size());
    double driven = 0.0;
    for (size_t i = 1; i < expected_frames; ++i)
      driven += (gt[i].world_from_rig.translation - gt[i - 1].world_from_rig.translation).norm();
    EXPECT_LT(eval.ate_translation.rmse, 0.01 * driven)
        << "ATE RMSE " << eval.ate_translation.rmse << " m over " << driven << " m";

    // The points, registered with the same similarity, lie on the ground-truth surface: half of
    // them within 10 cm (1 % of a typical 10 m depth; the scene is 5–20 m away).
    const PointCloud cloud = ReadPlyPoints(out / "points.ply");
    ASSERT_GE(cloud.points.size(), 500u);
    std::vector<Eigen::Vector3d> registered;
    for (const Eigen::Vector3d& p : cloud.points) registered.push_back(eval.gt_from_estimated * p);
    const RayCaster mesh(ReadPlyMesh(drive_ / "gt" / "mesh.ply"));
    std::vector<double> distances = mesh.DistancesTo(registered);
    std::sort(distances.begin(), distances.end());
    EXPECT_LT(distances[distances.size() / 2], 0.1) << "median point-to-surface distance";
  }

  static testing::TempDir* dir_;
  fs::path drive_;
};
testing::TempDir* SfmCommandShortDrive::dir_ = nullptr;

// A value of stats/sfm_summary.csv (-1 when missing).
double SummaryValue(const fs::path& out, const std::string& name) {
  for (const std::string& line :
       testing::SplitText(testing::ReadTextFile(out / "stats" / "sfm_summary.csv")))
    if (line.rfind(name + ",", 0) == 0) return std::stod(line.substr(name.size() + 1));
  return -1.0;
}

// The COLMAP text model read back by `surface --colmap`'s reader: one keyframe per keyframe of
// poses.tum with its centre (the mean camera centre), every point of points.ply, the frame
// points (TrackerOptions::frame_points, which no keyframe sees) from sparse/frame_rays.txt.
void CheckColmapModel(const fs::path& drive, const fs::path& out) {
  const std::vector<SurfaceKeyframe> colmap = LoadColmapKeyframes(out / "sparse");
  const std::vector<StampedPose> poses = ReadTum(out / "poses.tum");
  const Rig rig = ReadRigJson(drive / "rig.json");
  Eigen::Vector3d center_in_rig = Eigen::Vector3d::Zero();
  for (const Camera& camera : rig.cameras) center_in_rig += camera.CenterInRig();
  center_in_rig /= static_cast<double>(rig.cameras.size());
  ASSERT_EQ(colmap.size(), poses.size());
  size_t points = 0;
  for (size_t k = 0; k < poses.size(); ++k) {
    EXPECT_LT((colmap[k].centre - poses[k].world_from_rig * center_in_rig).norm(), 1e-6) << k;
    points += colmap[k].points.size();
  }
  const double frame_points = SummaryValue(out, "frame_points");
  EXPECT_GT(frame_points, 0.0);
  EXPECT_EQ(points, ReadPlyPoints(out / "points.ply").points.size());
  const ColmapModel model = ReadColmapModel(out / "sparse");
  EXPECT_EQ(std::count_if(model.frame_rays.begin(), model.frame_rays.end(),
                          [](const ColmapFrameRayPoint& line) { return line.point3d_id == 0; }),
            static_cast<long>(frame_points));

  // images.txt and points3D.txt agree: every (IMAGE_ID, POINT2D_IDX) of a track is a 2-D point
  // of that image naming the track's point; one image per camera per keyframe.
  std::map<long, std::vector<long>> image_points;  // image id -> POINT3D_ID of each 2-D point
  const std::vector<std::string> image_lines =
      testing::SplitText(testing::ReadTextFile(out / "sparse" / "images.txt"));
  size_t i = 0;
  while (i < image_lines.size() && image_lines[i].rfind("#", 0) == 0) ++i;
  for (; i < image_lines.size(); i += 2) {
    std::istringstream header(image_lines[i]);
    long id;
    ASSERT_TRUE(header >> id) << image_lines[i];
    std::istringstream in(i + 1 < image_lines.size() ? image_lines[i + 1] : "");
    double x, y;
    long point;
    std::vector<long>& ids = image_points[id];
    while (in >> x >> y >> point) ids.push_back(point);
  }
  EXPECT_EQ(image_points.size(), poses.size() * rig.cameras.size());
  std::vector<double> errors;  // mean reprojection error of each point, pixels
  for (const std::string& line :
       testing::SplitText(testing::ReadTextFile(out / "sparse" / "points3D.txt"))) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    long id, image, index;
    double x, y, z, r, g, b, error;
    ASSERT_TRUE(in >> id >> x >> y >> z >> r >> g >> b >> error) << line;
    errors.push_back(error);
    int observations = 0;
    while (in >> image >> index) {
      ASSERT_TRUE(image_points.count(image)) << line;
      ASSERT_LT(index, static_cast<long>(image_points[image].size())) << line;
      EXPECT_EQ(image_points[image][index], id) << line;
      ++observations;
    }
    EXPECT_GE(observations, 2) << line;
  }
  ASSERT_EQ(errors.size() + static_cast<size_t>(frame_points), points);
  std::sort(errors.begin(), errors.end());
  EXPECT_LT(errors[errors.size() / 2], 1.0);
  EXPECT_LT(errors[errors.size() * 99 / 100], 3.0);
}

TEST_F(SfmCommandShortDrive, CentralTracksEveryFrameWithinOnePercent) {
  fs::path out;
  CheckEndToEnd("--central", 0, &out);
  if (HasFatalFailure()) return;
  CheckColmapModel(drive_, out);
  // Points coloured from the (grey) images: the mean pixel over each point's observations.
  testing::ExpectPointColoursAreImageMeans(drive_, out, 300);
}

TEST_F(SfmCommandShortDrive, NonCentralTracksEveryFrameWithinOnePercent) {
  CheckEndToEnd("--non-central", 50);
}

// Non-central mode on the short drive's first 60 frames (45 m, no loop; 4-6 cm offsets, so the
// map's scale settles over the first keyframes' adjustments): every frame's pose, keyframe or
// not, within 0.05 % of the distance (measured 0.015 %). A frame that followed only the keyframe
// it was tracked from kept the scale of the map when it was tracked: the frames tracked before
// the scale settled were up to 2 m off, 0.6 % of the distance (`--no-frames-between-keyframes`).
TEST_F(SfmCommandShortDrive, NonCentralFramePosesFollowTheirKeyframes) {
  const fs::path out = dir_->path() / "sfm_frames_between_keyframes";
  const testing::CommandResult result = Run({"--quiet", "sfm", drive_.string(), "--non-central",
                                             "--max-frames", "60", "--out", out.string()});
  ASSERT_EQ(result.exit_code, 0) << result.err;
  std::vector<StampedPose> gt = ReadTum(drive_ / "gt" / "poses.tum");
  gt.resize(60);
  const std::vector<StampedPose> posed = ReadTum(out / "frame_poses.tum");
  ASSERT_EQ(posed.size(), 60u);
  const PoseEvalResult eval = EvaluatePoses(posed, gt);
  ASSERT_EQ(eval.matches.size(), posed.size());
  EXPECT_GT(eval.gt_length, 40.0);
  EXPECT_LT(eval.ate_translation.rmse, 0.0005 * eval.gt_length)
      << "ATE RMSE " << eval.ate_translation.rmse << " m over " << eval.gt_length << " m";
}

// Non-central mode on the first 60 frames: the frames between keyframes adjusted with the final
// map (the default: in the final adjustment itself, every one of them here) are as accurate as the
// keyframes, and more than their pose between their keyframes (`--no-final-frame-refinement
// --no-final-ba-frames`). Measured, seven runs each (docs/figures.md
// F39): frames 0.46 to 0.57 cm with keyframes 0.45 to 0.59 cm; without, frames 0.66 to 0.91 cm,
// 1.1 to 1.6 times the keyframes'. Non-central runs of this drive move by more than that with
// the last bits of the arithmetic (figures.md F48: frames 0.54, 0.67 and 0.96 cm from three
// builds that differ only in rounding), so the absolute bound is 1.2 cm (0.025 % of the length).
TEST_F(SfmCommandShortDrive, NonCentralFramesRefinedOnTheFinalMapAreAsAccurateAsKeyframes) {
  std::vector<StampedPose> gt = ReadTum(drive_ / "gt" / "poses.tum");
  gt.resize(60);
  // ATE RMSE (m) of frame_poses.tum and of poses.tum.
  const auto run = [&](const std::string& name, std::vector<std::string> extra, double* frames,
                       double* keyframes, int* adjusted_frames) {
    const fs::path out = dir_->path() / name;
    std::vector<std::string> arguments = {"--quiet",      "sfm", drive_.string(), "--non-central",
                                          "--max-frames", "60",  "--out",         out.string()};
    arguments.insert(arguments.end(), extra.begin(), extra.end());
    const testing::CommandResult result = Run(arguments);
    ASSERT_EQ(result.exit_code, 0) << result.err;
    const std::vector<StampedPose> posed = ReadTum(out / "frame_poses.tum");
    ASSERT_EQ(posed.size(), 60u);
    const PoseEvalResult frame_eval = EvaluatePoses(posed, gt);
    ASSERT_EQ(frame_eval.matches.size(), posed.size());
    const PoseEvalResult keyframe_eval = EvaluatePoses(ReadTum(out / "poses.tum"), gt);
    *frames = frame_eval.ate_translation.rmse;
    *keyframes = keyframe_eval.ate_translation.rmse;
    const nlohmann::json summary = nlohmann::json::parse(testing::ReadTextFile(out / "sfm.json"));
    ASSERT_TRUE(summary.contains("final_frame_refinement")) << summary.dump();
    *adjusted_frames = summary.at("final_bundle_adjustment").at("adjusted_frames").get<int>();
  };
  double refined = 0.0, refined_keyframes = 0.0, blended = 0.0, blended_keyframes = 0.0;
  int adjusted = 0, adjusted_blended = -1;
  run("sfm_frames_refined", {}, &refined, &refined_keyframes, &adjusted);
  if (HasFatalFailure()) return;
  run("sfm_frames_blended", {"--no-final-frame-refinement", "--no-final-ba-frames"}, &blended,
      &blended_keyframes, &adjusted_blended);
  if (HasFatalFailure()) return;
  const nlohmann::json keyframes_only = nlohmann::json::parse(
      testing::ReadTextFile(dir_->path() / "sfm_frames_refined" / "sfm.json"));
  const int frames_between = 60 - keyframes_only.at("keyframes").get<int>();
  EXPECT_EQ(adjusted, frames_between);
  EXPECT_EQ(adjusted_blended, 0);
  EXPECT_LT(refined, blended) << "frames refined " << refined << " m, between keyframes " << blended
                              << " m";
  EXPECT_LT(refined, 1.15 * refined_keyframes)
      << "frames " << refined << " m, keyframes " << refined_keyframes << " m";
  EXPECT_LT(refined, 0.012) << "frames " << refined << " m";
}

// --profile on the first 60 frames in non-central mode: accurate doubles the corners, offline
// also makes nearly every frame a keyframe; every profile poses every frame, realtime (the
// default) and accurate within three times the error COLMAP 3.8 reaches on the same 60 frames
// (0.26 cm, docs/figures.md F33), offline within twice that. The profiles' gains are those of a
// mean, not of every start: over 30 starts of 60 frames of this drive (with 6-pixel epipolar
// bands throughout), accurate's keyframes were closer to the truth than realtime's on 15
// (geometric mean of the ATE 0.69 against 0.79 cm) and offline's on 28 (0.37 cm), figures.md
// F71. sfm.json names the profile and what it set.
TEST_F(SfmCommandShortDrive, TheProfilesPoseEveryFrameAndOfflineIsWithinTwiceColmap) {
  std::vector<StampedPose> gt = ReadTum(drive_ / "gt" / "poses.tum");
  gt.resize(60);
  struct Outcome {
    double keyframes_ate = 0.0;
    size_t keyframes = 0;
    nlohmann::json front_end;
  };
  const auto run = [&](const std::string& profile, Outcome* outcome) {
    const fs::path out = dir_->path() / ("sfm_profile_" + profile);
    const testing::CommandResult result =
        Run({"--quiet", "sfm", drive_.string(), "--non-central", "--max-frames", "60", "--profile",
             profile, "--out", out.string()});
    ASSERT_EQ(result.exit_code, 0) << result.err;
    ASSERT_EQ(ReadTum(out / "frame_poses.tum").size(), 60u);
    const std::vector<StampedPose> keyframes = ReadTum(out / "poses.tum");
    outcome->keyframes = keyframes.size();
    outcome->keyframes_ate = EvaluatePoses(keyframes, gt).ate_translation.rmse;
    const nlohmann::json summary = nlohmann::json::parse(testing::ReadTextFile(out / "sfm.json"));
    EXPECT_EQ(summary["profile"], profile);
    outcome->front_end = summary["front_end"];
  };
  Outcome realtime, accurate, offline;
  run("realtime", &realtime);
  if (HasFatalFailure()) return;
  run("accurate", &accurate);
  if (HasFatalFailure()) return;
  run("offline", &offline);
  if (HasFatalFailure()) return;
  EXPECT_EQ(realtime.front_end["corners_per_image"], 350);
  EXPECT_EQ(accurate.front_end["corners_per_image"], 700);
  EXPECT_EQ(offline.front_end["corners_per_image"], 700);
  EXPECT_DOUBLE_EQ(accurate.front_end["min_tracked_share"].get<double>(), 0.3);
  EXPECT_DOUBLE_EQ(offline.front_end["min_tracked_share"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(realtime.front_end["min_followed_track_share"].get<double>(), 0.25);
  EXPECT_GT(offline.keyframes, 3 * realtime.keyframes / 2)
      << offline.keyframes << " keyframes, realtime " << realtime.keyframes;
  EXPECT_LT(realtime.keyframes_ate, 3 * 0.0026) << "realtime " << realtime.keyframes_ate << " m";
  EXPECT_LT(accurate.keyframes_ate, 3 * 0.0026) << "accurate " << accurate.keyframes_ate << " m";
  EXPECT_LT(offline.keyframes_ate, 2 * 0.0026) << "offline " << offline.keyframes_ate << " m";
}

TEST_F(SfmCommandShortDrive, BadArgumentsAreOneErrorLine) {
  const testing::CommandResult both =
      Run({"sfm", drive_.string(), "--out", (dir_->path() / "x").string(), "--central",
           "--non-central"});
  EXPECT_EQ(both.exit_code, 2);
  EXPECT_EQ(testing::SplitText(both.err).size(), 1u) << both.err;
  const testing::CommandResult hypotheses =
      Run({"sfm", drive_.string(), "--out", (dir_->path() / "z").string(), "--resection-hypotheses",
           "p4p"});
  EXPECT_EQ(hypotheses.exit_code, 2);
  EXPECT_EQ(testing::SplitText(hypotheses.err).size(), 1u) << hypotheses.err;
  EXPECT_FALSE(fs::exists(dir_->path() / "z"));
  // A bad value of `option`: one error line naming it, exit 2, no output folder.
  const auto expect_refused = [&](const std::string& option, const std::string& value,
                                  const std::string& folder) {
    SCOPED_TRACE(option + " " + value);
    const testing::CommandResult result =
        Run({"sfm", drive_.string(), "--out", (dir_->path() / folder).string(), option, value});
    EXPECT_EQ(result.exit_code, 2);
    EXPECT_EQ(testing::SplitText(result.err).size(), 1u) << result.err;
    EXPECT_NE(result.err.find(option), std::string::npos) << result.err;
    EXPECT_FALSE(fs::exists(dir_->path() / folder));
  };
  expect_refused("--resection-consensus", "0.5", "c");
  expect_refused("--corner-quality", "1", "q");
  expect_refused("--profile", "fast", "p");
  expect_refused("--min-tracked-share", "1", "m");
  expect_refused("--min-followed-share", "1", "f");
  expect_refused("--epipolar-min-depth", "-1", "e");
  expect_refused("--epipolar-search-radius", "0", "r");
  expect_refused("--epipolar-max-search-radius", "5", "w");
  const testing::CommandResult missing = Run(
      {"sfm", (dir_->path() / "no_such_drive").string(), "--out", (dir_->path() / "y").string()});
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_EQ(testing::SplitText(missing.err).size(), 1u) << missing.err;
}

// Makes a synthetic drive in dir/drive (`omnisculpt synth` with `arguments`); empty, with the
// failure recorded, when synth fails.
fs::path SynthDrive(const fs::path& dir, std::vector<std::string> arguments) {
  const fs::path drive = dir / "drive";
  arguments.insert(arguments.begin(), {"--quiet", "synth"});
  arguments.insert(arguments.end(), {"--out", drive.string()});
  const testing::CommandResult result = testing::RunOmnisculpt(arguments, dir);
  if (result.exit_code != 0) {
    ADD_FAILURE() << "synth failed: " << result.err;
    return {};
  }
  return drive;
}

// One phone-like pinhole camera (the pinhole rig preset, 1024x768, 65 degrees across) on the
// short drive's path through its first turn (70 frames, 54 m): the few matches that nearly all
// agree in the turn are enough, so every frame is posed, within 1 % of the distance driven.
TEST(SfmCommand, PinholePresetPosesEveryFrameThroughTheFirstTurn) {
  const testing::TempDir dir("sfm_pinhole_test");
  const fs::path drive = dir.path() / "drive", out = dir.path() / "out";
  ASSERT_EQ(testing::RunOmnisculpt({"--quiet", "synth", "--preset", "short", "--rig-preset",
                                    "pinhole", "--out", drive.string()},
                                   dir.path())
                .exit_code,
            0);
  const testing::CommandResult result = testing::RunOmnisculpt(
      {"--quiet", "sfm", drive.string(), "--max-frames", "70", "--out", out.string()}, dir.path());
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const std::vector<StampedPose> gt = ReadTum(drive / "gt" / "poses.tum");
  const std::vector<StampedPose> posed = ReadTum(out / "frame_poses.tum");
  EXPECT_EQ(posed.size(), 70u) << result.err;
  const PoseEvalResult eval = EvaluatePoses(posed, gt);
  ASSERT_EQ(eval.matches.size(), posed.size());
  EXPECT_GT(eval.gt_length, 40.0);
  EXPECT_LT(eval.ate_translation.rmse, 0.01 * eval.gt_length)
      << "ATE RMSE " << eval.ate_translation.rmse << " m over " << eval.gt_length << " m";
  // One camera: central mode, 2000 corners per image, the pool of both modes.
  const nlohmann::json summary = nlohmann::json::parse(testing::ReadTextFile(out / "sfm.json"));
  EXPECT_EQ(summary.at("mode").get<std::string>(), "central");
  EXPECT_EQ(summary.at("front_end").at("corners_per_image").get<int>(), 2000);
  EXPECT_EQ(summary.at("front_end").at("continuation_pool").get<double>(), 2.0);
}

// Every frame of `drive` posed by `command` (sfm or reconstruct: frame_poses.tum against
// gt/poses.tum), within 1 % of the distance driven after similarity registration; *scale, if
// given, is that similarity's scale (1: metric).
void ExpectEveryFramePosedWithinOnePercent(const std::string& command, const fs::path& drive,
                                           const fs::path& out, const fs::path& scratch,
                                           double* scale = nullptr,
                                           const std::vector<std::string>& options = {}) {
  std::vector<std::string> arguments = {"--quiet", command, drive.string(), "--out", out.string()};
  arguments.insert(arguments.end(), options.begin(), options.end());
  const testing::CommandResult result = testing::RunOmnisculpt(arguments, scratch);
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const std::vector<StampedPose> gt = ReadTum(drive / "gt" / "poses.tum");
  const std::vector<StampedPose> posed = ReadTum(out / "frame_poses.tum");
  EXPECT_EQ(posed.size(), gt.size()) << result.err;
  const PoseEvalResult eval = EvaluatePoses(posed, gt);
  ASSERT_EQ(eval.matches.size(), posed.size());
  EXPECT_LT(eval.ate_translation.rmse, 0.01 * eval.gt_length)
      << command << ": ATE RMSE " << eval.ate_translation.rmse << " m over " << eval.gt_length
      << " m";
  if (scale) *scale = eval.gt_from_estimated.scale;
}

// The default tiny drive (30 frames 3 to 4.4 m apart, turns of up to 42 degrees between two
// frames): the image-motion model loses it in the first turn; matching by descriptors at
// several scales, the retry and the relative-motion fallback pose every frame, in `sfm` and in
// `reconstruct`.
TEST(SfmCommand, TheDefaultTinyDrivePosesEveryFrame) {
  const testing::TempDir dir("sfm_tiny_test");
  const fs::path drive = SynthDrive(dir.path(), {"--preset", "tiny"});
  ASSERT_FALSE(drive.empty());
  ExpectEveryFramePosedWithinOnePercent("sfm", drive, dir.path() / "sfm", dir.path());
  ExpectEveryFramePosedWithinOnePercent("reconstruct", drive, dir.path() / "rec", dir.path());
}

// Two runs of `sfm` on the same drive write the same poses, byte for byte, in either mode: what
// a run computes does not depend on its threads' timing (images decoded ahead, cameras matched
// and RANSAC hypotheses scored in parallel) nor on where the allocator put things (the order of
// the adjustments' parameters).
TEST(SfmCommand, TwoRunsWriteTheSamePosesByteForByte) {
  const testing::TempDir dir("sfm_repeat_test");
  const fs::path drive = SynthDrive(dir.path(), {"--preset", "tiny"});
  ASSERT_FALSE(drive.empty());
  for (const std::string mode : {"--central", "--non-central"}) {
    std::vector<std::string> poses, frame_poses;
    for (int run = 0; run < 2; ++run) {
      const fs::path out = dir.path() / ("sfm" + mode + std::to_string(run));
      const testing::CommandResult result = testing::RunOmnisculpt(
          {"--quiet", "sfm", drive.string(), "--out", out.string(), mode, "--max-frames", "16"},
          dir.path());
      ASSERT_EQ(result.exit_code, 0) << result.err;
      poses.push_back(testing::ReadTextFile(out / "poses.tum"));
      frame_poses.push_back(testing::ReadTextFile(out / "frame_poses.tum"));
    }
    EXPECT_GT(poses[0].size(), 500u) << mode;
    EXPECT_EQ(poses[0], poses[1]) << mode;
    EXPECT_EQ(frame_poses[0], frame_poses[1]) << mode;
  }
}

// The demo drive thinned to one frame in ten (1.5 frames/s: 40 frames 3.7 to 5.5 m apart,
// 20 to 31 degrees of turn between two frames in its four corners): every frame posed, within
// 1 % of the distance driven.
TEST(SfmCommand, AThinnedDrivePosesEveryFrameWithinOnePercent) {
  const testing::TempDir dir("sfm_thinned_test");
  const fs::path drive = SynthDrive(dir.path(), {"--preset", "demo", "--frame-step", "10"});
  ASSERT_FALSE(drive.empty());
  ExpectEveryFramePosedWithinOnePercent("sfm", drive, dir.path() / "sfm", dir.path());
}

// The short drive thinned to one frame in ten (13 frames 7 m apart, 30 to 45 degrees of turn
// in its corners): the map stays thin, and frames whose resection keeps too few inliers are
// posed by their relative motion (at least 20 inliers, 8 map points agreeing on its scale);
// every frame posed within 1 % of the distance (measured 0.03 %; 5 of 13 with 50 inliers).
TEST(SfmCommand, TheShortDriveThinnedToOneFrameInTenPosesEveryFrame) {
  const testing::TempDir dir("sfm_short_thinned_test");
  const fs::path drive = SynthDrive(dir.path(), {"--preset", "short", "--frame-step", "10"});
  ASSERT_FALSE(drive.empty());
  ExpectEveryFramePosedWithinOnePercent("sfm", drive, dir.path() / "sfm", dir.path());
}

// The five-camera fisheye rig (a forward stereo pair 10 cm apart, offsets up to 6 cm) on the
// tiny drive: the stereo map of the first frame holds only near points, which the next frames
// barely see again; the two-frame initialisation replaces it, every frame is posed within 1 %
// of the distance, and the offsets give the map its scale (measured 1.008, earlier versions
// 1.07; with the first two keyframes fixed at the initialisation's unit step it was 1.23, the
// first keyframe 1.8 m off). Offsets of 6 cm for points 17 m away (0.36 %) fix the scale only
// to a few per cent: sfm.json says the scale is arbitrary, near metres, and why.
TEST(SfmCommand, TheFisheyeRigOnTheTinyDrivePosesEveryFrame) {
  const testing::TempDir dir("sfm_fisheye_tiny_test");
  const fs::path drive = SynthDrive(dir.path(), {"--preset", "tiny", "--rig-preset", "fisheye5"});
  ASSERT_FALSE(drive.empty());
  double scale = 0.0;
  ExpectEveryFramePosedWithinOnePercent("sfm", drive, dir.path() / "sfm", dir.path(), &scale);
  EXPECT_NEAR(scale, 1.0, 0.15);
  const nlohmann::json summary =
      nlohmann::json::parse(testing::ReadTextFile(dir.path() / "sfm" / "sfm.json"));
  const nlohmann::json& scale_json = summary.at("scale");
  EXPECT_FALSE(scale_json.at("metric").get<bool>()) << scale_json;
  EXPECT_LT(scale_json.at("offset_depth_ratio").get<double>(), 0.01) << scale_json;
  EXPECT_NE(scale_json.at("source").get<std::string>().find("arbitrary, near metres"),
            std::string::npos)
      << scale_json;
  const std::string frames = testing::ReadTextFile(dir.path() / "sfm" / "stats" / "sfm_frames.csv");
  EXPECT_NE(frames.find("the stereo map too thin to track"), std::string::npos) << frames;
}

// The ladybug-like rig (offsets of 4 to 6 cm, points about 10 m away) on the short drive of seed
// 3 from its second frame, 60 frames: the first two keyframes barely observe the scale, and
// their adjustment takes the initialisation's unit step to 3,700 (the map was 5,000 times
// metric, which no later adjustment undid: scale 0.0002). Such a change is not taken: that
// adjustment is solved again with the scale held, and the later ones, over three keyframes and
// more, bring it near metres (measured 1.002). sfm.json calls it arbitrary, near metres: such
// offsets fix it only roughly.
TEST(SfmCommand, TheLadybugLikeRigsMapStartsNearMetres) {
  const testing::TempDir dir("sfm_ladybug_scale_test");
  const fs::path drive = SynthDrive(dir.path(), {"--preset", "short", "--seed", "3"});
  ASSERT_FALSE(drive.empty());
  const fs::path out = dir.path() / "sfm";
  const testing::CommandResult result = testing::RunOmnisculpt(
      {"--quiet", "sfm", drive.string(), "--frames", "1:61", "--out", out.string()}, dir.path());
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const std::vector<StampedPose> posed = ReadTum(out / "frame_poses.tum");
  EXPECT_EQ(posed.size(), 60u);
  const PoseEvalResult eval = EvaluatePoses(posed, ReadTum(drive / "gt" / "poses.tum"));
  EXPECT_NEAR(eval.gt_from_estimated.scale, 1.0, 0.1);
  EXPECT_LT(eval.ate_translation.rmse, 0.01 * eval.gt_length);
  const nlohmann::json summary = nlohmann::json::parse(testing::ReadTextFile(out / "sfm.json"));
  const nlohmann::json& scale_json = summary.at("scale");
  EXPECT_EQ(summary.at("mode").get<std::string>(), "non-central");
  EXPECT_FALSE(scale_json.at("metric").get<bool>()) << scale_json;
  EXPECT_NE(scale_json.at("source").get<std::string>().find("arbitrary, near metres"),
            std::string::npos)
      << scale_json;
}

// The car rig (six cameras 1 to 1.5 m from the rig's centre, images at a quarter of their
// size) on the tiny drive, non-central as its rig.json says: every frame posed within 1 % of
// the distance, and the map in metres within 2 % (measured 0.2 %); the same with the
// resection's hypotheses from one camera's P3P (--resection-hypotheses camera-p3p).
TEST(SfmCommand, TheCarRigOnTheTinyDriveIsMetric) {
  const testing::TempDir dir("sfm_car_tiny_test");
  const fs::path drive =
      SynthDrive(dir.path(), {"--preset", "tiny", "--rig-preset", "car", "--image-scale", "0.25"});
  ASSERT_FALSE(drive.empty());
  double scale = 0.0;
  ExpectEveryFramePosedWithinOnePercent("sfm", drive, dir.path() / "sfm", dir.path(), &scale);
  EXPECT_NEAR(scale, 1.0, 0.02);
  const nlohmann::json summary =
      nlohmann::json::parse(testing::ReadTextFile(dir.path() / "sfm" / "sfm.json"));
  EXPECT_EQ(summary.at("mode").get<std::string>(), "non-central");
  EXPECT_TRUE(summary.at("scale").at("metric").get<bool>()) << summary.at("scale");
  // Six cameras: 350 corners per image, continued among a pool of twice that (non-central).
  EXPECT_EQ(summary.at("front_end").at("corners_per_image").get<int>(), 350);
  EXPECT_EQ(summary.at("front_end").at("corner_quality").get<double>(), 0.003);
  EXPECT_EQ(summary.at("front_end").at("continuation_pool").get<double>(), 2.0);
  // Some corners (near structure, the first frames' large motions) are found only along their
  // epipolar segments; the summary counts them as the frames' rows do.
  EXPECT_EQ(summary.at("front_end").at("epipolar_min_depth").get<double>(), 1.5);
  EXPECT_EQ(summary.at("front_end").at("epipolar_search_radius").get<double>(), 6.0);
  EXPECT_EQ(summary.at("front_end").at("epipolar_max_search_radius").get<double>(), 15.0);
  const long epipolar = summary.at("front_end").at("epipolar_matches").get<long>();
  EXPECT_GT(epipolar, 0);
  const std::vector<std::string> rows =
      testing::SplitText(testing::ReadTextFile(dir.path() / "sfm" / "stats" / "sfm_frames.csv"));
  ASSERT_GE(rows.size(), 2u);
  const std::vector<std::string> header = testing::SplitText(rows[0], ',');
  const size_t column = std::find(header.begin(), header.end(), "epipolar") - header.begin();
  ASSERT_LT(column, header.size()) << rows[0];
  long summed = 0;
  for (size_t r = 1; r < rows.size(); ++r)
    summed += std::stol(testing::SplitText(rows[r], ',')[column]);
  EXPECT_EQ(summed, epipolar);
  // The resection's hypotheses from one camera's P3P, taken to the rig by that camera's offset:
  // the same.
  ExpectEveryFramePosedWithinOnePercent("sfm", drive, dir.path() / "sfm_camera_p3p", dir.path(),
                                        &scale, {"--resection-hypotheses", "camera-p3p"});
  EXPECT_NEAR(scale, 1.0, 0.02);
}

// A surround rig whose cameras are 1.5 m from their centre: central mode says in the log that
// the non-central mode is the right one; the synthetic rig (5 cm) does not.
TEST(SfmCommand, WarnsAboutLargeCameraOffsetsInCentralMode) {
  const fs::path dir =
      fs::temp_directory_path() / ("omni_sfm_offset_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  Rig rig = ReadRigJson(fs::path(OMNI_SOURCE_DIR) / "data" / "rigs" / "ladybug-like.json");
  for (Camera& camera : rig.cameras) {
    // Push each camera 1.5 m out along its optical axis (world = rig here).
    const Eigen::Vector3d axis =
        camera.cam_from_rig.rotation.conjugate() * Eigen::Vector3d::UnitZ();
    camera.cam_from_rig.translation -= camera.cam_from_rig.rotation * (1.5 * axis);
  }
  rig.central = true;
  WriteRigJson(rig, dir / "wide.json");
  const fs::path drive = dir / "drive";
  ASSERT_EQ(testing::RunOmnisculpt({"--quiet", "synth", "--preset", "tiny", "--frames", "2",
                                    "--rig", (dir / "wide.json").string(), "--out", drive.string()},
                                   dir)
                .exit_code,
            0);
  const testing::CommandResult wide = testing::RunOmnisculpt(
      {"sfm", drive.string(), "--out", (dir / "out").string(), "--central"}, dir);
  EXPECT_NE((wide.out + wide.err).find("non-central mode (--non-central) is the right one"),
            std::string::npos)
      << wide.out << wide.err;
  const testing::CommandResult non_central = testing::RunOmnisculpt(
      {"sfm", drive.string(), "--out", (dir / "out2").string(), "--non-central"}, dir);
  EXPECT_EQ((non_central.out + non_central.err).find("is the right one"), std::string::npos);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omni
