#include "pipeline/reconstruction.h"

#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>

#include "calib/drive.h"
#include "tests/apps/short_drive.h"

namespace omni {
namespace {

int ThisThreadNiceness() {
  return getpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)));
}

// The niceness of the surface thread, read in the snapshot callback (which runs on it) of a
// pipeline run on the first frames of the short drive; -100 when no snapshot came.
int SurfaceThreadNiceness(const Drive& drive, int surface_thread_nice) {
  PipelineOptions options;
  options.sfm.max_frames = 40;
  options.snapshot_every = 1;
  options.surface_thread_nice = surface_thread_nice;
  std::atomic<int> niceness{-100};
  PipelineCallbacks callbacks;
  callbacks.snapshot = [&niceness](const PipelineSnapshot&) { niceness = ThisThreadNiceness(); };
  RunPipeline(drive, options, callbacks);
  return niceness;
}

// The surface thread runs surface_thread_nice nicer than the thread that started the pipeline
// (capped at 19), the SfM's; 0 leaves it at the same priority.
TEST(PipelineShortDrive, TheSurfaceThreadRunsNicerThanTheSfm) {
  std::string error;
  const std::filesystem::path folder = testing::ShortDrive(&error);
  ASSERT_FALSE(folder.empty()) << error;
  const Drive drive = Drive::Open(folder);
  const int base = ThisThreadNiceness();
  EXPECT_EQ(SurfaceThreadNiceness(drive, 0), base);
  EXPECT_EQ(SurfaceThreadNiceness(drive, 5), std::min(19, base + 5));
  EXPECT_EQ(ThisThreadNiceness(), base);  // the caller's own priority is untouched
}

// sfm_finished comes once, from the SfM thread, with the SfM's result as RunPipeline returns it;
// what it throws fails the run.
TEST(PipelineShortDrive, SfmFinishedGivesTheFinalSfmResultOnce) {
  std::string error;
  const std::filesystem::path folder = testing::ShortDrive(&error);
  ASSERT_FALSE(folder.empty()) << error;
  const Drive drive = Drive::Open(folder);
  PipelineOptions options;
  options.sfm.max_frames = 40;
  int calls = 0;
  size_t keyframes = 0, frames = 0;
  Eigen::Vector3d last_centre = Eigen::Vector3d::Zero();
  bool on_caller_thread = true;
  const auto caller = std::this_thread::get_id();
  PipelineCallbacks callbacks;
  callbacks.sfm_finished = [&](const SfmRunResult& sfm, double queue_blocked_seconds) {
    ++calls;
    on_caller_thread = std::this_thread::get_id() == caller;
    keyframes = sfm.keyframes.size();
    frames = sfm.frames.size();
    if (!sfm.keyframes.empty()) last_centre = sfm.keyframes.back().world_from_rig.translation;
    EXPECT_GE(queue_blocked_seconds, 0.0);
  };
  const PipelineResult result = RunPipeline(drive, options, callbacks);
  EXPECT_EQ(calls, 1);
  EXPECT_FALSE(on_caller_thread);
  ASSERT_GE(result.sfm.keyframes.size(), 2u);
  EXPECT_EQ(keyframes, result.sfm.keyframes.size());
  EXPECT_EQ(frames, result.sfm.frames.size());
  EXPECT_EQ(last_centre, result.sfm.keyframes.back().world_from_rig.translation);

  callbacks.sfm_finished = [](const SfmRunResult&, double) {
    throw std::runtime_error("the SfM's files could not be written");
  };
  EXPECT_THROW(RunPipeline(drive, options, callbacks), std::runtime_error);
}

// A surface thread that falls behind skips the keyframes that a replay queued after them
// re-sculpts, and gives the same surfaces as one that kept up.
TEST(PipelineShortDrive, ASurfaceThatFallsBehindSkipsWhatAReplayRedoesWithTheSameSurface) {
  std::string error;
  const std::filesystem::path folder = testing::ShortDrive(&error);
  ASSERT_FALSE(folder.empty()) << error;
  const Drive drive = Drive::Open(folder);
  PipelineOptions options;
  options.sculptor.init_keyframes = 3;  // s known early: the skipping needs it
  options.snapshot_every = 1;
  PipelineCallbacks callbacks;
  callbacks.snapshot = [](const PipelineSnapshot&) {};
  options.skip_superseded_keyframes = false;  // every keyframe sculpted, however slow
  const PipelineResult kept_up = RunPipeline(drive, options, callbacks);
  EXPECT_EQ(kept_up.surface_keyframes_skipped, 0u);
  options.skip_superseded_keyframes = true;
  // The whole drive: a loop closure's replay, then the final adjustment's.
  ASSERT_FALSE(kept_up.sfm.loop_closures.empty());
  ASSERT_EQ(kept_up.loop_replay_keyframes.size(), kept_up.sfm.loop_closures.size() + 1);
  EXPECT_EQ(kept_up.loop_replay_keyframes.back(), kept_up.sfm.keyframes.size());

  // The first snapshot (on the surface thread, after the first batch) waits until the SfM has
  // finished and queued everything (a queue large enough for the whole drive): the loop
  // closure's replay and the keyframes are then skipped for the final adjustment's replay.
  std::mutex mutex;
  std::condition_variable finished;
  bool sfm_finished = false;
  callbacks.sfm_finished = [&](const SfmRunResult&, double) {
    std::lock_guard<std::mutex> lock(mutex);
    sfm_finished = true;
    finished.notify_all();
  };
  callbacks.snapshot = [&](const PipelineSnapshot&) {
    std::unique_lock<std::mutex> lock(mutex);
    finished.wait_for(lock, std::chrono::minutes(2), [&] { return sfm_finished; });
  };
  options.queue_capacity = 1024;
  const PipelineResult behind = RunPipeline(drive, options, callbacks);
  ASSERT_TRUE(sfm_finished);
  ASSERT_EQ(behind.sfm.keyframes.size(), kept_up.sfm.keyframes.size());
  // The loop closure's replay and at least one keyframe handed over after the first three.
  EXPECT_GT(behind.surface_keyframes_skipped, kept_up.loop_replay_keyframes[0]);
  // One entry per replay, skipped (0 s, 0 keyframes) or not; the final one sculpted every
  // keyframe.
  ASSERT_EQ(behind.sfm.loop_closures.size(), kept_up.sfm.loop_closures.size());
  ASSERT_EQ(behind.loop_replay_keyframes.size(), behind.sfm.loop_closures.size() + 1);
  ASSERT_EQ(behind.loop_replay_seconds.size(), behind.loop_replay_keyframes.size());
  EXPECT_EQ(behind.loop_replay_keyframes[0], 0u);
  EXPECT_EQ(behind.loop_replay_seconds[0], 0.0);
  EXPECT_EQ(behind.loop_replay_keyframes.back(), behind.sfm.keyframes.size());
  ASSERT_FALSE(behind.surface_rows.empty());
  EXPECT_EQ(behind.surface_rows.back().replay,
            static_cast<int>(behind.loop_replay_keyframes.size()));
  EXPECT_LT(behind.surface_rows.size(), kept_up.surface_rows.size());
  EXPECT_EQ(behind.mesh.vertices, kept_up.mesh.vertices);
  EXPECT_EQ(behind.mesh.triangles, kept_up.mesh.triangles);
  EXPECT_EQ(behind.closed_mesh.vertices, kept_up.closed_mesh.vertices);
  EXPECT_EQ(behind.closed_mesh.triangles, kept_up.closed_mesh.triangles);
  EXPECT_FALSE(behind.mesh.triangles.empty());
}

// reconstruct's sculptor differs from the surface command's where the SfM's own points asked
// for it (docs/figures.md F53, F58, F59, F66); surface.ply is taken the same way (F63).
TEST(PipelineOptions, TheSculptorDefaultsOfReconstruct) {
  const SculptorOptions surface;
  const SculptorOptions reconstruct = PipelineOptions().sculptor;
  EXPECT_EQ(surface.keyframes_per_step, 1);
  EXPECT_EQ(reconstruct.keyframes_per_step, 3);
  EXPECT_EQ(surface.enclosed_free_rounds, 1);
  EXPECT_EQ(reconstruct.enclosed_free_rounds, 2);
  EXPECT_EQ(surface.min_aperture_deg, 5.0);
  EXPECT_EQ(reconstruct.min_aperture_deg, 4.0);
  EXPECT_EQ(surface.uncertain_ray_margin_deg, 0.0);
  EXPECT_EQ(reconstruct.uncertain_ray_margin_deg, 0.1);
  EXPECT_EQ(surface.observed.max_edge_factor, 1.4);
  EXPECT_EQ(reconstruct.observed.max_edge_factor, 1.4);
  EXPECT_EQ(reconstruct.observed.grow_max_edge_factor, 4.0);
  EXPECT_EQ(reconstruct.Check(), "");
}

TEST(PipelineOptions, ChecksTheSurfaceThreadNiceness) {
  PipelineOptions options;
  EXPECT_EQ(options.Check(), "");
  options.surface_thread_nice = 20;
  EXPECT_NE(options.Check().find("surface_thread_nice"), std::string::npos);
  options.surface_thread_nice = -1;
  EXPECT_NE(options.Check().find("surface_thread_nice"), std::string::npos);
}

}  // namespace
}  // namespace omni
