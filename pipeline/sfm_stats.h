#pragma once
// The SfM statistics files of `omnisculpt sfm` and `omnisculpt reconstruct`, one writer for
// both:
//   stats/sfm_stages.csv   stage,seconds,ms_per_frame: wall seconds per SfM stage, "other"
//                          the rest of the SfM's time, "total" the sum
//   stats/sfm_summary.csv  name,value: frames, tracking, keyframes, points, observations,
//                          reprojection error, frames/s of the SfM, and
//                          usable (1, or 0 when the SfM did not initialise or lost tracking)

#include <filesystem>
#include <string>

#include "sfm/colmap_model.h"
#include "sfm/track_builder.h"
#include "sfm/tracker.h"

namespace omni {

struct SfmStats {
  // Counted by AddFrame.
  size_t frames = 0;              // frames of the run, skipped ones included
  size_t frames_skipped = 0;      // an image could not be read
  size_t frames_not_tracked = 0;  // read but not tracked
  size_t matched_sum = 0;         // tracked observations (points matched to earlier frames)
  size_t inliers_sum = 0;         // resection inliers of the tracked frames
  size_t tracked_frames = 0;

  size_t keyframes = 0;
  size_t points = 0;
  ColmapModelStats colmap;  // observations and reprojection error of the written model
  TrackStats tracks;        // track lengths of the points handed over (sfm/tracker.h)

  // Wall seconds. Detection and matching run in parallel over the cameras.
  TrackBuilder::Timings front;
  Tracker::Timings back;
  double load_seconds = 0.0;                     // the SfM waiting for a frame's images
  double loop_closure_seconds = 0.0;             // detection, correction, global adjustment
  double final_bundle_adjustment_seconds = 0.0;  // when the drive ended
  double final_frame_refinement_seconds = 0.0;   // the frames posed again on the final map
  // RMS angle of the observations (degrees) before and after that adjustment; 0: it did not run.
  double final_ba_rms_angle_before_deg = 0.0, final_ba_rms_angle_after_deg = 0.0;
  double queue_wait_seconds = 0.0;  // the SfM blocked on a full surface queue (reconstruct)
  double total_seconds = 0.0;       // the whole SfM, from the first frame to the last keyframe
  bool usable = true;               // the run gave a usable map (pipeline/sfm_runner.h)

  void AddFrame(bool loaded, int matched, const FrameResult& result);
};

std::string SfmStagesCsv(const SfmStats& stats);
std::string SfmSummaryCsv(const SfmStats& stats);
// Writes both files into `stats_folder` (existing), atomically.
void WriteSfmStats(const SfmStats& stats, const std::filesystem::path& stats_folder);

}  // namespace omni
