// `omnisculpt reconstruct --frames A:B` and `omnisculpt merge`: segments of the short synthetic
// drive (fixture short_drive) reconstructed apart and merged into one map, measured against the
// ground truth and against one run over the same frames; inputs that are missing or do not
// overlap are reported, not merged.

#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/colmap_text.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "eval/pose_eval.h"
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

// `omnisculpt COMMAND DRIVE --frames RANGE --out OUT` (reconstruct or sfm), which must succeed.
void RunSegment(const fs::path& drive, const std::string& range, const fs::path& out,
                const fs::path& scratch, const std::string& command = "reconstruct") {
  const auto result = RunOmnisculpt(
      {"--quiet", command, drive.string(), "--frames", range, "--out", out.string()}, scratch);
  ASSERT_EQ(result.exit_code, 0) << command << " " << range << ": " << result.err;
}

// Another drive folder made of `drive`'s images and rig (the images linked, not copied): the
// same pictures under another name, so the merge takes it for another drive.
fs::path DriveSharingImages(const fs::path& drive, const fs::path& folder) {
  fs::create_directories(folder);
  fs::create_directory_symlink(drive / "images", folder / "images");
  fs::copy_file(drive / "rig.json", folder / "rig.json");
  return folder;
}

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
// segment that shares no frame with them and sees no place they saw is reported as not joined.
TEST(MergeCommandShortDrive, OverlappingSegmentsMergeIntoOneMapAsGoodAsOneRun) {
  const fs::path scratch = ScratchDir("segments");
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  for (const auto& [range, name] : {std::pair<std::string, std::string>{"0:50", "a"},
                                    {"40:90", "b"},
                                    {"0:90", "whole"},
                                    {"95:110", "apart"}})
    RunSegment(drive, range, scratch / name, scratch);
  // The segment's frames keep the drive's names and times.
  const nlohmann::json b = ReadJson(scratch / "b" / "reconstruct.json");
  EXPECT_EQ(b["frame_range"]["first"], 40);
  EXPECT_EQ(b["frame_range"]["last"], 89);
  EXPECT_EQ(b["frames"], 50);
  const auto b_frames = ReadTum(scratch / "b" / "frame_poses.tum");
  ASSERT_FALSE(b_frames.empty());
  EXPECT_NEAR(b_frames.front().timestamp, 40.0 / 15.0, 1e-6);
  // So do the rays of its frames between keyframes (sparse/frame_rays.txt).
  const ColmapModel b_model = ReadColmapModel(scratch / "b" / "sparse");
  ASSERT_FALSE(b_model.frame_rays.empty());
  for (const ColmapFrameRayPoint& line : b_model.frame_rays)
    for (const ColmapFrameRay& ray : line.rays) {
      const int frame = std::stoi(fs::path(ray.image_name).stem().string());
      ASSERT_TRUE(frame >= 40 && frame <= 89) << ray.image_name;
    }

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
  // a and b: 10 shared frames, verified; apart shares none, revisits nothing, and is not
  // merged: each of its pairs is reported with why.
  int shared = 0, refused = 0;
  for (const nlohmann::json& overlap : summary["overlaps"]) {
    const bool with_apart = overlap["b"] == (scratch / "apart").string();
    if (with_apart) {
      EXPECT_FALSE(overlap["verified"].get<bool>()) << overlap.dump();
      EXPECT_FALSE(overlap["refusal"].get<std::string>().empty());
      ++refused;
      continue;
    }
    ASSERT_EQ(overlap["kind"], "shared frames") << overlap.dump();
    ++shared;
    EXPECT_TRUE(overlap["verified"].get<bool>());
    EXPECT_EQ(overlap["shared_frames"], 10);
    EXPECT_GE(overlap["inliers"].get<int>(), 8);
    EXPECT_LT(overlap["rms_rotation_deg"].get<double>(), 0.3);
  }
  EXPECT_EQ(shared, 1) << summary.dump(2);
  EXPECT_EQ(refused, 2) << summary.dump(2);
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
  EXPECT_EQ(ReadPlyPoints(city / "points.ply").points.size(),
            summary["points"].get<size_t>() + summary["frame_points"].get<size_t>());
  // The frame points of the frames between keyframes: each frame's from one segment, so more
  // than either segment's and fewer than both's (they share 10 frames).
  const size_t frame_points_a = summary["inputs"][0]["frame_points"].get<size_t>();
  const size_t frame_points_b = summary["inputs"][1]["frame_points"].get<size_t>();
  const size_t frame_points = summary["frame_points"].get<size_t>();
  EXPECT_GT(frame_points, std::max(frame_points_a, frame_points_b));
  EXPECT_LT(frame_points, frame_points_a + frame_points_b);
  EXPECT_TRUE(fs::exists(city / "sparse" / "frame_rays.txt"));

  // A second merge into the same folder is refused without --force.
  const auto again = RunOmnisculpt(
      {"--quiet", "merge", (scratch / "a").string(), "--out", city.string()}, scratch);
  EXPECT_EQ(again.exit_code, 2) << again.err;
}

// `sfm` runs (sfm.json, no surface of their own) merge as reconstructions do, and two merges of
// the same runs write the same poses byte for byte.
TEST(MergeCommandShortDrive, SfmRunsOfSegmentsMergeToo) {
  const fs::path scratch = ScratchDir("sfm_runs");
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  RunSegment(drive, "0:40", scratch / "a", scratch, "sfm");
  RunSegment(drive, "30:70", scratch / "b", scratch, "sfm");
  const fs::path city = scratch / "city";
  const auto merged =
      RunOmnisculpt({"--quiet", "merge", (scratch / "a").string(), (scratch / "b").string(),
                     "--out", city.string(), "--final-batch"},
                    scratch);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  const nlohmann::json summary = ReadJson(city / "merge.json");
  EXPECT_EQ(summary["status"], "usable") << summary.dump(2);
  ASSERT_EQ(summary["overlaps"].size(), 1u) << summary.dump(2);
  EXPECT_TRUE(summary["overlaps"][0]["verified"].get<bool>());
  EXPECT_EQ(summary["overlaps"][0]["shared_frames"], 10);
  EXPECT_LT(PoseRms(city, drive), 0.01 * 40.0);  // under 1 % of the ~40 m driven
  const fs::path city_again = scratch / "city_again";
  const auto again = RunOmnisculpt({"--quiet", "merge", (scratch / "a").string(),
                                    (scratch / "b").string(), "--out", city_again.string()},
                                   scratch);
  ASSERT_EQ(again.exit_code, 0) << again.err;
  for (const char* file : {"poses.tum", "frame_poses.tum"}) {
    if (!fs::exists(city / file)) continue;
    EXPECT_EQ(ReadTextFile(city / file), ReadTextFile(city_again / file)) << file;
  }
  EXPECT_TRUE(fs::exists(city / "poses.tum"));
  // --final-batch (the default) writes every keyframe sculpted in one batch at the s of the
  // first 10 (without sculpting them one by one first: no per-keyframe times), another closed
  // surface of the same map than the one sculpted keyframe by keyframe (--no-final-batch).
  // Without --init-keyframes the map's keyframes are all in the first batch, and no final batch
  // runs even when asked.
  EXPECT_FALSE(summary["final_batch"]["ran"].get<bool>()) << summary.dump(2);
  EXPECT_TRUE(summary["manifold"].get<bool>());
  EXPECT_TRUE(summary["closed_manifold"].get<bool>());
  ASSERT_GT(summary["keyframes"].get<int>(), 10);
  const fs::path city_batch = scratch / "city_batch";
  const auto batch =
      RunOmnisculpt({"--quiet", "merge", (scratch / "a").string(), (scratch / "b").string(),
                     "--out", city_batch.string(), "--init-keyframes", "10"},
                    scratch);
  ASSERT_EQ(batch.exit_code, 0) << batch.err;
  const nlohmann::json batch_summary = ReadJson(city_batch / "merge.json");
  EXPECT_TRUE(batch_summary["final_batch"]["ran"].get<bool>()) << batch_summary.dump(2);
  EXPECT_TRUE(batch_summary["surface_ms_median"].is_null()) << batch_summary.dump(2);
  // The rays of the points the aperture bound drops carve short of them, as in reconstruct.
  EXPECT_GT(batch_summary["uncertain_rays"].get<size_t>(), 0u) << batch_summary.dump(2);
  EXPECT_TRUE(batch_summary["closed_manifold"].get<bool>());
  const fs::path city_stream = scratch / "city_stream";
  const auto stream =
      RunOmnisculpt({"--quiet", "merge", (scratch / "a").string(), (scratch / "b").string(),
                     "--out", city_stream.string(), "--init-keyframes", "10", "--no-final-batch",
                     "--uncertain-ray-margin", "0"},
                    scratch);
  ASSERT_EQ(stream.exit_code, 0) << stream.err;
  const nlohmann::json stream_summary = ReadJson(city_stream / "merge.json");
  EXPECT_FALSE(stream_summary["final_batch"]["ran"].get<bool>());
  EXPECT_EQ(stream_summary["uncertain_rays"].get<size_t>(), 0u);
  EXPECT_TRUE(stream_summary["closed_manifold"].get<bool>());
  EXPECT_EQ(stream_summary["keyframes"], summary["keyframes"]);
  EXPECT_NE(ReadPlyMesh(city_stream / "surface_closed.ply").triangles,
            ReadPlyMesh(city_batch / "surface_closed.ply").triangles);
}

// A drive with its own clock (frames.csv in epoch seconds with nanoseconds, as the real sets
// of ../shared/data/real have): the segments' poses carry those times, which a double holds
// to about 0.2 µs only, and the merge still finds each frame (shared frames, poses by frame).
TEST(MergeCommandShortDrive, SegmentsOfADriveWithItsOwnClockMerge) {
  const fs::path scratch = ScratchDir("own_clock");
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  const fs::path clocked = DriveSharingImages(drive, scratch / "clocked_drive");
  {
    std::ofstream csv(clocked / "frames.csv");
    csv << "frame,camera,timestamp_s\n";
    for (int f = 0; f < 130; ++f) {
      char name[16], time[64];
      std::snprintf(name, sizeof(name), "%06d", f);
      // 1646304541.927203655 + f / 15 s, written to the nanosecond.
      const long long ns = 927203655LL + f * 1000000000LL / 15;
      std::snprintf(time, sizeof(time), "%lld.%09lld", 1646304541LL + ns / 1000000000LL,
                    ns % 1000000000LL);
      for (int c = 0; c < 6; ++c) csv << name << ",cam" << c << "," << time << "\n";
    }
  }
  RunSegment(clocked, "0:40", scratch / "a", scratch);
  RunSegment(clocked, "30:70", scratch / "b", scratch);
  const fs::path city = scratch / "city";
  const auto merged = RunOmnisculpt({"--quiet", "merge", (scratch / "a").string(),
                                     (scratch / "b").string(), "--out", city.string()},
                                    scratch);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  const nlohmann::json summary = ReadJson(city / "merge.json");
  EXPECT_EQ(summary["status"], "usable") << summary.dump(2);
  ASSERT_GE(summary["overlaps"].size(), 1u) << summary.dump(2);
  EXPECT_EQ(summary["overlaps"][0]["kind"], "shared frames");
  EXPECT_TRUE(summary["overlaps"][0]["verified"].get<bool>());
  EXPECT_EQ(summary["overlaps"][0]["shared_frames"], 10);
  // The merged frames carry the drive's clock, once each, in order.
  const auto frames = ReadTum(city / "frame_poses.tum");
  ASSERT_EQ(frames.size(), 70u);
  EXPECT_NEAR(frames.front().timestamp, 1646304541.927203655, 1e-6);
  for (size_t i = 1; i < frames.size(); ++i)
    EXPECT_NEAR(frames[i].timestamp - frames[i - 1].timestamp, 1.0 / 15.0, 1e-6) << i;
}

// The drive's loop cut into two segments whose only link at the loop is a revisit (frames
// 113-129 see the place of frames 0-13): the merge finds it, fuses the matched points, and the
// merged map is as good as one run that closed the loop itself.
TEST(MergeCommandShortDrive, ALoopCutIntoSegmentsClosesInTheMerge) {
  const fs::path scratch = ScratchDir("loop");
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  for (const auto& [range, name] :
       {std::pair<std::string, std::string>{"0:70", "first"}, {"55:", "second"}, {"0:", "whole"}})
    RunSegment(drive, range, scratch / name, scratch);
  const nlohmann::json whole = ReadJson(scratch / "whole" / "reconstruct.json");
  ASSERT_FALSE(whole["loop_closures"].empty()) << "the single run closes the loop itself";
  const fs::path city = scratch / "city";
  const auto merged = RunOmnisculpt({"--quiet", "merge", (scratch / "first").string(),
                                     (scratch / "second").string(), "--out", city.string()},
                                    scratch);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  const nlohmann::json summary = ReadJson(city / "merge.json");
  EXPECT_EQ(summary["status"], "usable");
  int revisits = 0;
  for (const nlohmann::json& overlap : summary["overlaps"]) {
    if (overlap["kind"] != "revisit") continue;
    ++revisits;
    EXPECT_TRUE(overlap["verified"].get<bool>());
    // The second segment's end sees the first's start.
    EXPECT_GE(overlap["frame_b"].get<int>(), 105) << overlap.dump();
    EXPECT_LE(overlap["frame_a"].get<int>(), 25) << overlap.dump();
  }
  EXPECT_GE(revisits, 1) << summary.dump(2);
  EXPECT_TRUE(summary["global_bundle_adjustment"]["ran"].get<bool>());
  const double merged_rms = PoseRms(city, drive);
  const double whole_rms = PoseRms(scratch / "whole", drive);
  std::printf("keyframe RMS: merged %.2f cm, one run closing the loop %.2f cm\n", 100 * merged_rms,
              100 * whole_rms);
  EXPECT_LE(merged_rms, 1.5 * whole_rms + 0.003);
  EXPECT_TRUE(summary["manifold"].get<bool>());
  EXPECT_TRUE(summary["closed_manifold"].get<bool>());
}

// Two drives through the same streets (a second drive made of the first one's images, so it
// is another drive to the merge: no frame is shared): only place recognition can join them; each
// drive keeps its own poses file, and together they make one trajectory.
TEST(MergeCommandShortDrive, TwoDrivesAreJoinedWhereTheyPassTheSamePlaces) {
  const fs::path scratch = ScratchDir("two_drives");
  std::string error;
  const fs::path drive = testing::ShortDrive(&error);
  ASSERT_FALSE(drive.empty()) << error;
  const fs::path other = DriveSharingImages(drive, scratch / "other_drive");
  RunSegment(drive, "0:70", scratch / "first", scratch);
  RunSegment(other, "50:", scratch / "second", scratch);
  const fs::path city = scratch / "city";
  const auto merged = RunOmnisculpt({"--quiet", "merge", (scratch / "first").string(),
                                     (scratch / "second").string(), "--out", city.string()},
                                    scratch);
  ASSERT_EQ(merged.exit_code, 0) << merged.err;
  const nlohmann::json summary = ReadJson(city / "merge.json");
  EXPECT_EQ(summary["status"], "usable") << summary.dump(2);
  ASSERT_EQ(summary["drives"].size(), 2u);
  int revisits = 0;
  for (const nlohmann::json& overlap : summary["overlaps"]) {
    EXPECT_EQ(overlap["kind"], "revisit") << overlap.dump();
    if (overlap["verified"].get<bool>()) ++revisits;
  }
  EXPECT_GE(revisits, 1) << summary.dump(2);
  // One rig for both: adjusted together.
  EXPECT_TRUE(summary["global_bundle_adjustment"]["ran"].get<bool>()) << summary.dump(2);
  EXPECT_FALSE(fs::exists(city / "poses.tum"));
  // One trajectory: the first drive's frames 0-69 then the second's 70-129, against the truth.
  const std::string first_label = summary["drives"][0]["label"];
  const std::string second_label = summary["drives"][1]["label"];
  std::vector<StampedPose> joined;
  for (const StampedPose& pose : ReadTum(city / "drives" / first_label / "poses.tum"))
    if (pose.timestamp < 70.0 / 15.0 - 1e-6) joined.push_back(pose);
  const size_t from_first = joined.size();
  for (const StampedPose& pose : ReadTum(city / "drives" / second_label / "poses.tum"))
    if (pose.timestamp >= 70.0 / 15.0 - 1e-6) joined.push_back(pose);
  const PoseEvalResult evaluation = EvaluatePoses(joined, ReadTum(drive / "gt" / "poses.tum"));
  std::printf("two drives joined: keyframe RMS %.2f cm over %zu keyframes (%zu of the first)\n",
              100 * evaluation.registration_rms, joined.size(), from_first);
  // Each drive its part of the trajectory: at least a keyframe every 4 frames (2.9 m) over the
  // first's 70 frames and the second's 60 (the keyframe rule makes one every 2 to 3 there).
  EXPECT_GE(from_first, 70u / 4);
  EXPECT_GE(joined.size() - from_first, 60u / 4);
  EXPECT_LT(evaluation.registration_rms, 0.05);  // 5 cm: 0.05 % of the 103 m driven
  // The two drives share no frame: each keeps all its frame points, every ray named in its
  // drive's folder of the merged model.
  EXPECT_EQ(summary["frame_points"].get<size_t>(),
            summary["inputs"][0]["frame_points"].get<size_t>() +
                summary["inputs"][1]["frame_points"].get<size_t>());
  const ColmapModel model = ReadColmapModel(city / "sparse");
  ASSERT_FALSE(model.frame_rays.empty());
  for (const ColmapFrameRayPoint& line : model.frame_rays)
    for (const ColmapFrameRay& ray : line.rays)
      ASSERT_TRUE(ray.image_name.rfind(first_label + "/", 0) == 0 ||
                  ray.image_name.rfind(second_label + "/", 0) == 0)
          << ray.image_name;
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  EXPECT_TRUE(CheckMesh(ReadPlyMesh(city / "surface.ply"), bounded).ok);
}

}  // namespace
}  // namespace omni
