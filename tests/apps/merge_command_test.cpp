// `omnisculpt reconstruct --frames A:B` and `omnisculpt merge`: segments of the short synthetic
// drive (fixture short_drive) reconstructed apart and merged into one map, measured against the
// ground truth and against one run over the same frames; inputs that are missing or do not
// overlap are reported, not merged.

#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "tests/apps/reconstruction_checks.h"
#include "tests/apps/run_omnisculpt.h"
#include "tests/apps/short_drive.h"

namespace omni {
namespace {

namespace fs = std::filesystem;
using testing::PoseRms;
using testing::ReadTextFile;
using testing::RunOmnisculpt;

fs::path ScratchDir(const std::string& name) { return testing::ScratchDir("merge", name); }

nlohmann::json ReadJson(const fs::path& path) { return nlohmann::json::parse(ReadTextFile(path)); }

TEST(MergeCommandShortDrive, RefusesABadFrameRangeAndNothingToMerge) {
  const fs::path scratch = ScratchDir("bad_input");
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  for (const std::string range : {"10", "20:10", "a:5", "500:", "-3:4"}) {
    const auto result = RunOmnisculpt(
        {"reconstruct", drive.string(), "--frames", range, "--out", (scratch / "out").string()},
        scratch);
    EXPECT_EQ(result.exit_code, 2) << range << ": " << result.err;
    EXPECT_NE(result.err.find("--frames"), std::string::npos) << range << ": " << result.err;
    EXPECT_FALSE(fs::exists(scratch / "out")) << range;
  }
  const auto nothing =
      RunOmnisculpt({"merge", (scratch / "none1").string(), (scratch / "none2").string(), "--out",
                     (scratch / "city").string()},
                    scratch);
  EXPECT_EQ(nothing.exit_code, 2) << nothing.err;
  EXPECT_NE(nothing.err.find("no reconstruction to merge"), std::string::npos) << nothing.err;
  EXPECT_NE(nothing.err.find("none2: missing"), std::string::npos) << nothing.err;
  EXPECT_FALSE(fs::exists(scratch / "city"));
}

// Two overlapping segments of the drive's first 90 frames (no loop), merged, against one run
// over frames 0-89; a third input that does not exist is reported and the others merged; a
// segment that shares no frame with them is reported as not joined.
TEST(MergeCommandShortDrive, OverlappingSegmentsMergeIntoOneMapAsGoodAsOneRun) {
  const fs::path scratch = ScratchDir("segments");
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  const auto reconstruct = [&](const std::string& range, const std::string& name) {
    const auto result = RunOmnisculpt({"--quiet", "reconstruct", drive.string(), "--frames", range,
                                       "--out", (scratch / name).string()},
                                      scratch);
    EXPECT_EQ(result.exit_code, 0) << range << ": " << result.err;
  };
  reconstruct("0:50", "a");
  reconstruct("40:90", "b");
  reconstruct("0:90", "whole");
  reconstruct("110:", "apart");
  // The segment's frames keep the drive's names and times.
  const nlohmann::json b = ReadJson(scratch / "b" / "reconstruct.json");
  EXPECT_EQ(b["frame_range"]["first"], 40);
  EXPECT_EQ(b["frame_range"]["last"], 89);
  EXPECT_EQ(b["frames"], 50);
  const auto b_frames = ReadTum(scratch / "b" / "frame_poses.tum");
  ASSERT_FALSE(b_frames.empty());
  EXPECT_NEAR(b_frames.front().timestamp, 40.0 / 15.0, 1e-6);

  const fs::path city = scratch / "city";
  const auto merged = RunOmnisculpt(
      {"--quiet", "merge", (scratch / "a").string(), (scratch / "b").string(),
       (scratch / "missing").string(), (scratch / "apart").string(), "--out", city.string()},
      scratch);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  EXPECT_NE(merged.err.find("missing: no such folder"), std::string::npos) << merged.err;
  const nlohmann::json summary = ReadJson(city / "merge.json");
  EXPECT_EQ(summary["status"], "partial") << summary.dump(2);
  ASSERT_EQ(summary["missing"].size(), 1u);
  EXPECT_EQ(summary["missing"][0]["folder"], (scratch / "missing").string());
  // a and b: 10 shared frames, verified; apart shares none and is not merged.
  ASSERT_EQ(summary["overlaps"].size(), 1u) << summary.dump(2);
  const nlohmann::json& overlap = summary["overlaps"][0];
  EXPECT_TRUE(overlap["verified"].get<bool>());
  EXPECT_EQ(overlap["shared_frames"], 10);
  EXPECT_GE(overlap["inliers"].get<int>(), 8);
  EXPECT_LT(overlap["rms_rotation_deg"].get<double>(), 0.3);
  ASSERT_EQ(summary["inputs"].size(), 3u);
  EXPECT_TRUE(summary["inputs"][0]["merged"].get<bool>());
  EXPECT_TRUE(summary["inputs"][1]["merged"].get<bool>());
  EXPECT_FALSE(summary["inputs"][2]["merged"].get<bool>());
  EXPECT_NE(summary["inputs"][2]["why"].get<std::string>().find("no verified overlap"),
            std::string::npos);
  EXPECT_GT(summary["points_fused"].get<int>(), 0);
  EXPECT_LT(summary["points"].get<int>(), summary["points_in"].get<int>());
  EXPECT_TRUE(summary["manifold"].get<bool>());
  EXPECT_TRUE(summary["closed_manifold"].get<bool>());

  // One trajectory over frames 0-89, every keyframe of both segments once.
  const auto poses = ReadTum(city / "poses.tum");
  const auto a_keyframes = ReadTum(scratch / "a" / "poses.tum");
  const auto b_keyframes = ReadTum(scratch / "b" / "poses.tum");
  EXPECT_GT(poses.size(), std::max(a_keyframes.size(), b_keyframes.size()));
  EXPECT_LE(poses.size(), a_keyframes.size() + b_keyframes.size());
  for (size_t i = 1; i < poses.size(); ++i) EXPECT_LT(poses[i - 1].timestamp, poses[i].timestamp);
  EXPECT_NEAR(poses.back().timestamp, b_keyframes.back().timestamp, 1e-9);
  const double merged_rms = PoseRms(city, drive);
  const double whole_rms = PoseRms(scratch / "whole", drive);
  std::printf("keyframe RMS: merged %.2f cm, one run over the same frames %.2f cm\n",
              100 * merged_rms, 100 * whole_rms);
  EXPECT_LE(merged_rms, 1.5 * whole_rms + 0.005);
  EXPECT_LT(merged_rms, 0.01 * 60.0);  // under 1 % of the ~60 m driven

  // The surface: an oriented 2-manifold with boundary, of the points of both segments.
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  EXPECT_TRUE(CheckMesh(ReadPlyMesh(city / "surface.ply"), bounded).ok);
  EXPECT_TRUE(CheckMesh(ReadPlyMesh(city / "surface_closed.ply")).ok);
  EXPECT_EQ(ReadPlyPoints(city / "points.ply").points.size(), summary["points"].get<size_t>());

  // A second merge into the same folder is refused without --force.
  const auto again = RunOmnisculpt(
      {"--quiet", "merge", (scratch / "a").string(), "--out", city.string()}, scratch);
  EXPECT_EQ(again.exit_code, 2) << again.err;
}

}  // namespace
}  // namespace omni
