// The one SfM loop (pipeline/sfm_runner.h) on hand-made inputs: its options checked in the
// Release build, one row per frame in the one schema, unreadable frames skipped and counted,
// the outcome of a run that never initialises, and the stop of an early end.

#include "pipeline/sfm_runner.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "calib/error.h"
#include "calib/rig_io.h"
#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

Rig DefaultRig() {
  return ReadRigJson(std::filesystem::path(OMNI_SOURCE_DIR) / "data" / "rigs" /
                     "ladybug-like.json");
}

// `frames` frames of black images, frame `unreadable` (if any) failing to load.
SfmFrameSource BlackFrames(const Rig& rig, size_t frames, long unreadable = -1) {
  SfmFrameSource source;
  source.folder = "black-drive";
  source.num_frames = frames;
  source.load = [&rig, unreadable](size_t frame) {
    if (static_cast<long>(frame) == unreadable)
      throw InputError("black-drive/images/cam0/bad.png", "", "cannot be read");
    std::vector<cv::Mat> images;
    for (const Camera& camera : rig.cameras)
      images.push_back(cv::Mat::zeros(camera.height, camera.width, CV_8UC1));
    return images;
  };
  source.name = [](size_t frame) { return "f" + std::to_string(frame); };
  return source;
}

TEST(SfmRunnerOptions, BadOptionsAreReportedWithTheFieldInRelease) {
  const Rig rig = DefaultRig();
  SfmRunnerOptions options;
  options.usable_tracked_frames_share = 1.5;
  try {
    SfmRunner runner(rig, options);
    ADD_FAILURE() << "no exception for usable_tracked_frames_share 1.5";
  } catch (const std::invalid_argument& error) {
    EXPECT_NE(std::string(error.what()).find("SfmRunnerOptions.usable_tracked_frames_share"),
              std::string::npos)
        << error.what();
  }
  options = SfmRunnerOptions();
  options.prefetch.frames_ahead = 0;
  EXPECT_NE(options.Check().find("prefetch.frames_ahead"), std::string::npos) << options.Check();
  EXPECT_THROW(RunSfm(rig, BlackFrames(rig, 2), options), std::invalid_argument);
  options = SfmRunnerOptions();
  options.max_frames = -1;
  EXPECT_THROW(RunSfm(rig, BlackFrames(rig, 2), options), std::invalid_argument);
  options = SfmRunnerOptions();
  options.final_frame_refinement_checks.min_inlier_share = 1.5;
  EXPECT_NE(options.Check().find("final_frame_refinement_checks.min_inlier_share"),
            std::string::npos)
      << options.Check();
  EXPECT_THROW((SfmRunner{rig, options}), std::invalid_argument);
}

// The final adjustment frees the keyframes since the last global adjustment and the local
// window before them, when they are few enough; the whole map otherwise.
TEST(SfmRunnerOptions, FinalAdjustmentFreesTheTailSinceTheLastGlobalAdjustment) {
  SfmRunnerOptions options;
  const int window = options.tracker.num_free_keyframes + options.tracker.num_fixed_keyframes;
  ASSERT_EQ(window, 10);
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 130), 120);
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 140), 130);
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 0), 0);    // no global adjustment
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 10), 0);   // the window reaches 0
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 80), 70);  // half the map: a tail
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 79), 0);   // more than half
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 150), 0);  // not this map's
  options.final_bundle_adjustment_tail_share = 0.1;
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 130), 0);
  options.final_bundle_adjustment_tail_share = 0.5;
  options.final_bundle_adjustment_tail = false;
  EXPECT_EQ(FinalAdjustmentFirstFreeKeyframe(options, 140, 130), 0);
  options = SfmRunnerOptions();
  options.final_bundle_adjustment_tail_share = 1.5;
  EXPECT_NE(options.Check().find("final_bundle_adjustment_tail_share"), std::string::npos)
      << options.Check();
  options = SfmRunnerOptions();
  EXPECT_TRUE(options.final_bundle_adjustment_frames);
  options.final_bundle_adjustment_frames_max_keyframes = -1;
  EXPECT_NE(options.Check().find("final_bundle_adjustment_frames_max_keyframes"), std::string::npos)
      << options.Check();
}

// The front end's pool of corners: on in both modes by default, off in central mode when
// asked; the other front-end options pass through.
TEST(SfmRunnerOptions, TheFrontEndContinuesTracksAmongAPoolInBothModesByDefault) {
  SfmRunnerOptions options;
  options.tracks.harris.max_corners = 123;
  options.tracks.continuation_pool = 2.5;
  options.tracker.central = false;
  EXPECT_EQ(SfmFrontEndOptions(options).continuation_pool, 2.5);
  EXPECT_EQ(FrontEndHarrisOptions(SfmFrontEndOptions(options)).pool_corners, 308);
  options.tracker.central = true;
  EXPECT_EQ(SfmFrontEndOptions(options).continuation_pool, 2.5);
  EXPECT_EQ(FrontEndHarrisOptions(SfmFrontEndOptions(options)).pool_corners, 308);
  EXPECT_EQ(SfmFrontEndOptions(options).harris.max_corners, 123);
  options.continuation_pool_in_central_mode = false;
  EXPECT_EQ(SfmFrontEndOptions(options).continuation_pool, 1.0);
  EXPECT_EQ(FrontEndHarrisOptions(SfmFrontEndOptions(options)).pool_corners, 0);
  options.tracker.central = false;
  EXPECT_EQ(SfmFrontEndOptions(options).continuation_pool, 2.5);
}

TEST(SfmRunner, BlackFramesNeverInitialiseAndEveryFrameHasItsRow) {
  const Rig rig = DefaultRig();
  std::vector<size_t> done;
  SfmRunnerCallbacks callbacks;
  callbacks.frame_done = [&done](const SfmFrameRow& row, int, int) { done.push_back(row.frame); };
  const SfmRunResult run = RunSfm(rig, BlackFrames(rig, 5, 2), SfmRunnerOptions(), callbacks);
  EXPECT_EQ(run.outcome, SfmOutcome::kNotInitialised);
  EXPECT_NE(run.outcome_reason.find("could not initialise"), std::string::npos);
  EXPECT_EQ(run.frames_total, 5u);
  // The first frame read is the map's first keyframe by definition; nothing follows it.
  EXPECT_LE(run.frames_tracked, 1u);
  EXPECT_LE(run.keyframes.size(), 1u);
  ASSERT_EQ(run.skipped.size(), 1u);
  EXPECT_NE(run.skipped[0].find("bad.png"), std::string::npos) << run.skipped[0];
  EXPECT_EQ(done, (std::vector<size_t>{0, 1, 2, 3, 4}));
  const size_t columns = testing::SplitText(SfmFramesCsvHeader(), ',').size();
  ASSERT_EQ(run.frames.size(), 5u);
  for (const SfmFrameRow& row : run.frames) {
    EXPECT_EQ(testing::SplitText(SfmFramesCsvRow(row), ',').size(), columns)
        << SfmFramesCsvRow(row);
    EXPECT_EQ(row.loaded, row.frame != 2);
    EXPECT_EQ(row.corners, 0);
    if (row.frame > 0) {
      EXPECT_FALSE(row.result.tracked) << row.frame;
    }
  }
  EXPECT_EQ(run.frames[3].name, "f3");
}

TEST(SfmRunner, MaxFramesAndStop) {
  const Rig rig = DefaultRig();
  SfmRunnerOptions options;
  options.max_frames = 3;
  EXPECT_EQ(RunSfm(rig, BlackFrames(rig, 10), options).frames.size(), 3u);
  SfmRunnerCallbacks callbacks;
  size_t polled = 0;
  callbacks.stop = [&polled] { return ++polled > 4; };
  EXPECT_EQ(RunSfm(rig, BlackFrames(rig, 10), SfmRunnerOptions(), callbacks).frames.size(), 4u);
}

TEST(SfmRunner, NoReadableFrameIsBadInputNamingTheFolder) {
  const Rig rig = DefaultRig();
  SfmFrameSource source = BlackFrames(rig, 3);
  source.load = [](size_t) -> std::vector<cv::Mat> {
    throw InputError("x.png", "", "cannot be read");
  };
  try {
    RunSfm(rig, source, SfmRunnerOptions());
    ADD_FAILURE() << "no error";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("black-drive"), std::string::npos) << error.what();
  }
}

}  // namespace
}  // namespace omni
