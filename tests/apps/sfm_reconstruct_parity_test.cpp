// `omnisculpt sfm` and `omnisculpt reconstruct` run one SfM loop (pipeline/sfm_runner.h): on
// drives cut from the short synthetic drive (fixture short_drive), one with a black frame mid-way
// and one with a jump (frames left out), both commands track the same frames, after the
// failure too (the re-localisation against the last keyframe), with the same poses, and write
// the same stats/sfm_frames.csv columns. A drive the SfM cannot initialise on makes both
// commands exit with the not-usable code and one line on stderr.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "calib/tum.h"
#include "eval/pose_eval.h"
#include "tests/apps/reconstruction_checks.h"
#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

namespace fs = std::filesystem;
using testing::PoseRms;
using testing::ReadTextFile;
using testing::RunOmnisculpt;
using testing::SplitText;

constexpr int kExitNotUsable = 3;  // apps/commands.h

fs::path ScratchDir(const std::string& name) { return testing::ScratchDir("sfm_parity", name); }

// How a drive is cut from the short drive.
struct Cut {
  std::vector<int> black;       // frames whose images are black
  std::vector<int> unreadable;  // frames whose image of one camera is not an image
  double clock_start = -1.0;    // >= 0: a frames.csv with frame i at clock_start + i * 0.2 s
};

// A drive of the short drive's frames `keep` (in order), renumbered 0.., its ground truth
// restamped to match (frame / 15 s, or the frames.csv clock).
fs::path CutShortDrive(const fs::path& scratch, const std::vector<int>& keep, const Cut& cut = {}) {
  const std::vector<int>& black = cut.black;
  const fs::path source(OMNI_SHORT_DRIVE_DIR);
  const fs::path drive = scratch / "drive";
  fs::create_directories(drive / "gt");
  fs::copy_file(source / "rig.json", drive / "rig.json");
  const std::vector<StampedPose> truth = ReadTum(source / "gt" / "poses.tum");
  std::vector<StampedPose> kept;
  for (size_t i = 0; i < keep.size(); ++i)
    kept.push_back({cut.clock_start >= 0.0 ? cut.clock_start + 0.2 * i : i / 15.0,
                    truth.at(keep[i]).world_from_rig});
  WriteTum(kept, drive / "gt" / "poses.tum");
  std::string frames_csv = "frame,camera,timestamp_s\n";
  for (const auto& camera : fs::directory_iterator(source / "images")) {
    std::vector<fs::path> images;
    for (const auto& image : fs::directory_iterator(camera.path())) images.push_back(image.path());
    std::sort(images.begin(), images.end());
    const fs::path target = drive / "images" / camera.path().filename();
    fs::create_directories(target);
    for (size_t i = 0; i < keep.size(); ++i) {
      char name[32];
      std::snprintf(name, sizeof(name), "%06zu", i);
      const fs::path image = images.at(keep[i]);
      const fs::path copy = target / (name + image.extension().string());
      char stamp[64];
      std::snprintf(stamp, sizeof(stamp), "%.6f", cut.clock_start + 0.2 * i);
      frames_csv +=
          std::string(name) + "," + camera.path().filename().string() + "," + stamp + "\n";
      const bool unreadable = camera.path().filename() == "cam2" &&
                              std::count(cut.unreadable.begin(), cut.unreadable.end(), keep[i]);
      if (std::find(black.begin(), black.end(), keep[i]) != black.end()) {
        const cv::Mat original = cv::imread(image.string(), cv::IMREAD_UNCHANGED);
        cv::imwrite(copy.string(), cv::Mat::zeros(original.size(), original.type()));
      } else if (unreadable) {
        std::ofstream(copy, std::ios::binary) << "not an image";
      } else {
        fs::create_symlink(image, copy);
      }
    }
  }
  if (cut.clock_start >= 0.0) std::ofstream(drive / "frames.csv") << frames_csv;
  return drive;
}

std::vector<int> Range(int begin, int end) {
  std::vector<int> frames;
  for (int f = begin; f < end; ++f) frames.push_back(f);
  return frames;
}

struct FramesCsv {
  std::vector<std::string> header;
  std::vector<std::vector<std::string>> rows;

  std::vector<int> Column(const std::string& name) const {
    const size_t column = std::find(header.begin(), header.end(), name) - header.begin();
    std::vector<int> values;
    if (column == header.size()) {
      ADD_FAILURE() << "no column " << name;
      return values;
    }
    for (const std::vector<std::string>& row : rows) values.push_back(std::stoi(row.at(column)));
    return values;
  }
};

FramesCsv ReadFramesCsv(const fs::path& out) {
  const std::vector<std::string> lines = SplitText(ReadTextFile(out / "stats" / "sfm_frames.csv"));
  FramesCsv csv;
  if (lines.empty()) return csv;
  csv.header = SplitText(lines[0], ',');
  for (size_t i = 1; i < lines.size(); ++i) csv.rows.push_back(SplitText(lines[i], ','));
  return csv;
}

// Runs both commands on `drive`; checks that they agree frame by frame and exit alike (0, or
// the not-usable code with one error line).
void ExpectSameTracking(const fs::path& scratch, const fs::path& drive, size_t frames,
                        FramesCsv* sfm_csv, std::string* sfm_error = nullptr) {
  const fs::path sfm_out = scratch / "sfm", rec_out = scratch / "rec";
  const testing::CommandResult sfm =
      RunOmnisculpt({"--quiet", "sfm", drive.string(), "--out", sfm_out.string()}, scratch);
  ASSERT_TRUE(sfm.exit_code == 0 || sfm.exit_code == kExitNotUsable) << sfm.err;
  const testing::CommandResult rec =
      RunOmnisculpt({"--quiet", "reconstruct", drive.string(), "--out", rec_out.string()}, scratch);
  EXPECT_EQ(rec.exit_code, sfm.exit_code) << rec.err;
  if (sfm.exit_code != 0) {
    // One error line each (the warnings about frames not tracked are on stderr too).
    auto errors = [](const std::string& err) {
      size_t count = 0;
      for (const std::string& line : SplitText(err)) count += line.rfind("omnisculpt: ", 0) == 0;
      return count;
    };
    EXPECT_EQ(errors(sfm.err), 1u) << sfm.err;
    EXPECT_EQ(errors(rec.err), 1u) << rec.err;
  }
  if (sfm_error) *sfm_error = sfm.err;
  const FramesCsv from_sfm = ReadFramesCsv(sfm_out), from_rec = ReadFramesCsv(rec_out);
  EXPECT_EQ(from_sfm.header, from_rec.header);
  ASSERT_EQ(from_sfm.rows.size(), frames);
  ASSERT_EQ(from_rec.rows.size(), frames);
  for (const char* column : {"loaded", "tracked", "keyframe", "relocalising"})
    EXPECT_EQ(from_sfm.Column(column), from_rec.Column(column)) << column;
  // The same SfM: the same keyframes, and poses as close to the truth.
  const std::vector<StampedPose> sfm_poses = ReadTum(sfm_out / "poses.tum");
  const std::vector<StampedPose> rec_poses = ReadTum(rec_out / "poses.tum");
  ASSERT_EQ(sfm_poses.size(), rec_poses.size());
  if (sfm_poses.size() < 3) return;  // too few to register
  for (size_t k = 0; k < sfm_poses.size(); ++k)
    EXPECT_DOUBLE_EQ(sfm_poses[k].timestamp, rec_poses[k].timestamp);
  const double sfm_rms = PoseRms(sfm_out, drive), rec_rms = PoseRms(rec_out, drive);
  std::printf("pose RMS: sfm %.4f m, reconstruct %.4f m\n", sfm_rms, rec_rms);
  EXPECT_LT(sfm_rms, 0.25);
  EXPECT_LT(rec_rms, 0.25);
  EXPECT_LT(std::abs(sfm_rms - rec_rms), 0.02);
  *sfm_csv = from_sfm;
}

TEST(SfmReconstructParityShortDrive, ABlackFrameIsLostThenTrackingResumesInBoth) {
  const fs::path scratch = ScratchDir("black");
  Cut cut;
  cut.black = {20};
  const fs::path drive = CutShortDrive(scratch, Range(0, 45), cut);
  FramesCsv csv;
  ExpectSameTracking(scratch, drive, 45, &csv);
  if (HasFatalFailure()) return;
  const std::vector<int> tracked = csv.Column("tracked");
  EXPECT_EQ(tracked.at(20), 0);  // no corners in a black image
  // Re-localisation against the last keyframe: every frame from two after it is tracked.
  for (size_t f = 22; f < tracked.size(); ++f) EXPECT_EQ(tracked[f], 1) << "frame " << f;
  EXPECT_EQ(csv.Column("relocalising").at(21), 1);
}

// A run of three black frames (2.4 m of driving, 11 degrees of turn with no image): tracking is
// lost over the run and resumes after it (re-localisation against the last keyframes, the map
// points searched around the constant-velocity prediction); both commands say where the gap
// was, on stderr and in the run's JSON. (Four such frames are at the edge: 24 to 30 inliers
// after the gap; six are too many: the keyframes' patches no longer match, and the run reports
// the loss.)
TEST(SfmReconstructParityShortDrive, ARunOfBlackFramesIsAReportedGapThenTrackingResumes) {
  const fs::path scratch = ScratchDir("black_run");
  Cut cut;
  constexpr int kFirstBlack = 20, kEndBlack = 23;  // frames 20, 21 and 22
  cut.black = Range(kFirstBlack, kEndBlack);
  const fs::path drive = CutShortDrive(scratch, Range(0, 50), cut);
  FramesCsv csv;
  std::string error;
  ExpectSameTracking(scratch, drive, 50, &csv, &error);
  if (HasFatalFailure()) return;
  const std::vector<int> tracked = csv.Column("tracked");
  for (int f = kFirstBlack; f < kEndBlack; ++f) EXPECT_EQ(tracked.at(f), 0) << "frame " << f;
  const int resumed_after =
      static_cast<int>(std::find(tracked.begin() + kEndBlack, tracked.end(), 1) - tracked.begin());
  EXPECT_LE(resumed_after, kEndBlack + 2) << "tracking did not resume within two frames of the run";
  for (size_t f = resumed_after; f < tracked.size(); ++f) EXPECT_EQ(tracked[f], 1) << "frame " << f;
  EXPECT_NE(error.find("frames 000020 to"), std::string::npos) << error;
  for (const char* summary : {"sfm/sfm.json", "rec/reconstruct.json"}) {
    const nlohmann::json json = nlohmann::json::parse(ReadTextFile(scratch / summary));
    ASSERT_EQ(json["untracked_runs"].size(), 1u) << json;
    EXPECT_EQ(json["untracked_runs"][0]["first_frame"], "000020") << json;
    EXPECT_EQ(json["untracked_runs"][0]["frames"], resumed_after - kFirstBlack) << json;
    EXPECT_EQ(json["untracked_runs"][0]["to_the_end"], false) << json;
    EXPECT_EQ(json["status"], "usable") << json;
  }
}

// Four frames left out (3.2 m): the re-localisation against the last keyframe does not reach
// that far, so tracking is lost from the jump on; both commands lose the same frames and say
// so, naming the frame where it was lost.
TEST(SfmReconstructParityShortDrive, AJumpIsFollowedTheSameWayByBoth) {
  const fs::path scratch = ScratchDir("jump");
  std::vector<int> keep = Range(0, 20);
  for (int f = 24; f < 45; ++f) keep.push_back(f);
  const fs::path drive = CutShortDrive(scratch, keep);
  FramesCsv csv;
  std::string error;
  ExpectSameTracking(scratch, drive, keep.size(), &csv, &error);
  if (HasFatalFailure()) return;
  const std::vector<int> tracked = csv.Column("tracked");
  for (size_t f = 0; f < 20; ++f) EXPECT_EQ(tracked[f], 1) << "frame " << f;
  if (std::count(tracked.begin() + 20, tracked.end(), 1) == 0) {
    EXPECT_NE(error.find("none from frame 000020 on"), std::string::npos) << error;
  }
}

// An image that cannot be read: its frame is skipped by both commands (a row with loaded 0),
// and the keyframes after it keep their own frames: poses.tum carries the drive's clock
// (frames.csv), which the ground truth is stamped with too, so a pose given the wrong frame
// would not register.
TEST(SfmReconstructParityShortDrive, AnUnreadableFrameIsSkippedAndThePosesKeepTheDrivesClock) {
  const fs::path scratch = ScratchDir("unreadable");
  Cut cut;
  cut.unreadable = {20};
  cut.clock_start = 5000.0;
  const fs::path drive = CutShortDrive(scratch, Range(0, 45), cut);
  FramesCsv csv;
  ExpectSameTracking(scratch, drive, 45, &csv);
  if (HasFatalFailure()) return;
  EXPECT_EQ(csv.Column("loaded").at(20), 0);
  const std::vector<StampedPose> poses = ReadTum(scratch / "rec" / "poses.tum");
  ASSERT_GT(poses.size(), 3u);
  EXPECT_GT(poses.back().timestamp, 5000.0 + 0.2 * 21 - 1e-6);
  for (const StampedPose& pose : poses) {
    const double step = (pose.timestamp - 5000.0) / 0.2;
    EXPECT_NEAR(step, std::round(step), 1e-4) << pose.timestamp;
    EXPECT_NE(std::lround(step), 20) << "the skipped frame has no pose";
  }
}

// The global bundle adjustment when the drive ends: it runs, lowers the angular error of the
// observations, and leaves the keyframes within 2 cm of the truth (measured 0.7-1.3 cm on the
// short drive; its gain against --no-final-ba is within the SfM's run-to-run spread there,
// docs/figures.md F12, so the test does not compare two runs).
TEST(SfmReconstructParityShortDrive, TheFinalBundleAdjustmentRunsAndKeepsThePosesAccurate) {
  const fs::path scratch = ScratchDir("final_ba");
  const fs::path drive(OMNI_SHORT_DRIVE_DIR);
  const testing::CommandResult run = RunOmnisculpt(
      {"--quiet", "sfm", drive.string(), "--out", (scratch / "sfm").string(), "--non-central"},
      scratch);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  std::map<std::string, double> summary;
  for (const std::string& line :
       SplitText(ReadTextFile(scratch / "sfm" / "stats" / "sfm_summary.csv"))) {
    const std::vector<std::string> fields = SplitText(line, ',');
    if (fields.size() == 2 && fields[0] != "name") summary[fields[0]] = std::stod(fields[1]);
  }
  ASSERT_EQ(summary.count("final_ba_rms_angle_after_deg"), 1u);
  const double before = summary["final_ba_rms_angle_before_deg"];
  const double after = summary["final_ba_rms_angle_after_deg"];
  std::printf("final bundle adjustment: RMS angle %.5f -> %.5f degrees\n", before, after);
  EXPECT_GT(after, 0.0);
  EXPECT_LT(after, before);
  EXPECT_LT(PoseRms(scratch / "sfm", drive), 0.02);
  const std::string stages = ReadTextFile(scratch / "sfm" / "stats" / "sfm_stages.csv");
  EXPECT_NE(stages.find("final_bundle_adjustment,"), std::string::npos) << stages;
}

// Two frames of nothing but black: no corners, no map. Both commands say so on stderr in one
// line and exit with the not-usable code; reconstruct publishes what happened.
TEST(SfmReconstructParityShortDrive, NoMapIsNotUsableInBoth) {
  const fs::path scratch = ScratchDir("no_map");
  Cut cut;
  cut.black = Range(0, 6);
  const fs::path drive = CutShortDrive(scratch, Range(0, 6), cut);
  const testing::CommandResult sfm = RunOmnisculpt(
      {"--quiet", "sfm", drive.string(), "--out", (scratch / "sfm").string()}, scratch);
  EXPECT_EQ(sfm.exit_code, kExitNotUsable) << sfm.err;
  const testing::CommandResult rec = RunOmnisculpt(
      {"--quiet", "reconstruct", drive.string(), "--out", (scratch / "rec").string()}, scratch);
  EXPECT_EQ(rec.exit_code, kExitNotUsable) << rec.err;
  for (const testing::CommandResult* run : {&sfm, &rec}) {
    std::vector<std::string> errors;
    for (const std::string& line : SplitText(run->err))
      if (line.find("error") != std::string::npos) errors.push_back(line);
    ASSERT_EQ(errors.size(), 1u) << run->err;
    EXPECT_NE(errors[0].find("could not initialise"), std::string::npos) << errors[0];
    EXPECT_NE(errors[0].find(drive.string()), std::string::npos) << errors[0];
  }
  // No map files without a map; the frames' rows say what happened.
  EXPECT_FALSE(fs::exists(scratch / "sfm" / "poses.tum"));
  EXPECT_EQ(ReadFramesCsv(scratch / "sfm").rows.size(), 6u);
  const nlohmann::json summary =
      nlohmann::json::parse(ReadTextFile(scratch / "rec" / "reconstruct.json"));
  EXPECT_EQ(summary["status"], "not_usable");
  EXPECT_EQ(summary["sfm_outcome"], "not_initialised");
  EXPECT_LE(summary["frames_tracked"].get<int>(), 1);  // the first frame, the first keyframe
  EXPECT_FALSE(fs::exists(scratch / "rec.incomplete"));
}

// The default tiny drive, as a new user would try it: it either reconstructs (a surface, exit
// 0) or says in one line on stderr that the result is not usable (exit 3), never an empty
// surface reported as a success.
TEST(ReconstructCommand, TheDefaultTinyDriveReconstructsOrSaysItCouldNot) {
  const fs::path scratch = ScratchDir("tiny");
  const fs::path drive = scratch / "tiny";
  ASSERT_EQ(
      RunOmnisculpt({"--quiet", "synth", "--preset", "tiny", "--out", drive.string()}, scratch)
          .exit_code,
      0);
  const testing::CommandResult rec = RunOmnisculpt(
      {"--quiet", "reconstruct", drive.string(), "--out", (scratch / "rec").string()}, scratch);
  const nlohmann::json summary =
      nlohmann::json::parse(ReadTextFile(scratch / "rec" / "reconstruct.json"));
  std::printf("tiny drive: exit %d, %d of %d frames tracked, %d triangles, %s\n", rec.exit_code,
              summary["frames_tracked"].get<int>(), summary["frames"].get<int>(),
              summary["triangles"].get<int>(), summary["outcome"].get<std::string>().c_str());
  if (rec.exit_code == 0) {
    EXPECT_EQ(summary["status"], "usable");
    EXPECT_GT(summary["triangles"].get<int>(), 0);
    EXPECT_TRUE(fs::exists(scratch / "rec" / "surface.ply"));
  } else {
    EXPECT_EQ(rec.exit_code, kExitNotUsable) << rec.err;
    EXPECT_EQ(summary["status"], "not_usable");
    // One error line; the warnings (frames not tracked) are on stderr too.
    std::vector<std::string> errors;
    for (const std::string& line : SplitText(rec.err)) {
      if (line.rfind("omnisculpt: error: ", 0) == 0) errors.push_back(line);
    }
    ASSERT_EQ(errors.size(), 1u) << rec.err;
    EXPECT_NE(errors[0].find("omnisculpt: error: " + drive.string()), std::string::npos) << rec.err;
  }
}

}  // namespace
}  // namespace omni
