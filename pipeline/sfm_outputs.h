#pragma once
// The outputs of an SfM run that `omnisculpt sfm` and `omnisculpt reconstruct` both write, by one
// writer: poses.tum (the keyframes' world_from_rig), points.ply (coloured from the keyframe
// images), sparse/ (a COLMAP text model), stats/sfm_frames.csv (one row per frame, the columns
// of SfmFramesCsvHeader), stats/sfm_stages.csv and stats/sfm_summary.csv (pipeline/sfm_stats.h).

#include <filesystem>

#include "calib/drive.h"
#include "calib/ply.h"
#include "pipeline/point_colors.h"
#include "pipeline/sfm_runner.h"
#include "pipeline/sfm_stats.h"

namespace omni {

struct SfmOutputOptions {
  // Timestamps of poses.tum when the drive has no frames.csv: frame index / frame_rate.
  double frame_rate = 15.0;
  // Seconds the SfM waited for room in the surface queue (reconstruct), a stage of its own.
  double queue_wait_seconds = 0.0;

  std::string Check() const;
};

struct SfmOutputs {
  PointCloud cloud;  // the points of points.ply, with their colours
  SfmStats stats;    // as written in stats/
  PointColorStats colors;
};

// Writes the files above into `folder` (made if missing); when the SfM did not initialise only
// the stats (there is no map).
SfmOutputs WriteSfmOutputs(const Drive& drive, const SfmRunResult& run,
                           const std::filesystem::path& folder,
                           const SfmOutputOptions& options = {});

}  // namespace omni
