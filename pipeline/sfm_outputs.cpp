#include "pipeline/sfm_outputs.h"

#include <cmath>
#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/tum.h"
#include "sfm/colmap_model.h"

namespace omni {

std::string SfmOutputOptions::Check() const {
  if (!(frame_rate > 0.0) || !std::isfinite(frame_rate))
    return "frame_rate: expected a positive rate";
  if (!(queue_wait_seconds >= 0.0)) return "queue_wait_seconds: expected 0 or more";
  return {};
}

SfmOutputs WriteSfmOutputs(const Drive& drive, const SfmRunResult& run,
                           const std::filesystem::path& folder, const SfmOutputOptions& options) {
  ThrowIfInvalid(options.Check(), "SfmOutputOptions");
  const Rig& rig = drive.rig();
  SfmOutputs outputs;
  std::filesystem::create_directories(folder / "stats");
  // The drive's own clock (frames.csv) when it has one.
  auto timestamp = [&](size_t frame) {
    return drive.HasTimestamps() ? drive.FrameTimestamp(frame) : frame / options.frame_rate;
  };
  std::vector<StampedPose> poses, frame_poses;
  for (const SfmFramePose& pose : TrackedFramePoses(run))
    frame_poses.push_back({timestamp(pose.frame), pose.world_from_rig});
  for (const FinalizedKeyframe& keyframe : run.keyframes) {
    poses.push_back({timestamp(static_cast<size_t>(keyframe.frame)), keyframe.world_from_rig});
    for (const FinalizedPoint& point : keyframe.points)
      outputs.cloud.points.push_back(point.position);
  }
  // sparse/ holds each point's complete track when the run has them (the same points in the
  // same order); the colours are the mean over those observations.
  bool complete = run.model_keyframes.size() == run.keyframes.size();
  for (size_t k = 0; complete && k < run.keyframes.size(); ++k)
    complete = run.model_keyframes[k].points.size() == run.keyframes[k].points.size();
  const std::vector<FinalizedKeyframe>& model = complete ? run.model_keyframes : run.keyframes;
  // Point colours from the keyframe images (the SfM reads grey images only).
  outputs.cloud.colors = ColorPoints(
      rig, model, [&drive](int frame, int camera) { return drive.LoadRgb(frame, camera); }, {},
      &outputs.colors);
  ColmapModelStats colmap;
  if (run.outcome != SfmOutcome::kNotInitialised) {
    // No map files without a map: the stats say what happened.
    WriteTum(poses, folder / "poses.tum");
    WriteTum(frame_poses, folder / "frame_poses.tum");
    WritePlyPoints(outputs.cloud, folder / "points.ply");
    // Each image's name made once: std::filesystem::relative reads the links of every folder
    // of the path, and the frame rays name the same images hundreds of thousands of times.
    std::map<std::pair<int, int>, std::string> image_names;
    colmap = WriteColmapTextModel(
        rig, model,
        [&drive, &image_names](int frame, int camera) -> const std::string& {
          auto [it, added] = image_names.try_emplace({frame, camera});
          if (added)
            it->second = std::filesystem::relative(drive.ImagePath(frame, camera), drive.folder())
                             .generic_string();
          return it->second;
        },
        folder / "sparse", outputs.cloud.colors);
  }

  std::ostringstream frames_csv;
  frames_csv << SfmFramesCsvHeader() << '\n';
  for (const SfmFrameRow& row : run.frames) frames_csv << SfmFramesCsvRow(row) << '\n';
  WriteTextFileAtomically(folder / "stats" / "sfm_frames.csv", frames_csv.str());

  SfmStats& stats = outputs.stats;
  for (const SfmFrameRow& row : run.frames) stats.AddFrame(row.loaded, row.matched, row.result);
  stats.keyframes = run.keyframes.size();
  stats.points = outputs.cloud.points.size();
  stats.colmap = colmap;
  stats.tracks = ComputeTrackStats(run.keyframes);
  stats.front = run.front;
  stats.back = run.back;
  stats.load_seconds = run.load_seconds;
  stats.loop_closure_seconds = run.loop_closure_seconds;
  stats.final_bundle_adjustment_seconds = run.final_bundle_adjustment_seconds;
  stats.final_frame_refinement_seconds = run.final_frame_refinement_seconds;
  stats.final_ba_rms_angle_before_deg = run.final_rms_angle_before * 180.0 / M_PI;
  stats.final_ba_rms_angle_after_deg = run.final_rms_angle_after * 180.0 / M_PI;
  stats.queue_wait_seconds = options.queue_wait_seconds;
  stats.total_seconds = run.seconds;
  stats.usable = run.outcome == SfmOutcome::kUsable;
  WriteSfmStats(stats, folder / "stats");
  return outputs;
}

}  // namespace omni
