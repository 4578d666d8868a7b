#include "pipeline/sfm_stats.h"

#include <algorithm>
#include <sstream>
#include <utility>
#include <vector>

#include "calib/atomic_file.h"

namespace omni {

void SfmStats::AddFrame(bool loaded, int matched, const FrameResult& result) {
  ++frames;
  if (!loaded) {
    ++frames_skipped;
    return;
  }
  matched_sum += static_cast<size_t>(std::max(matched, 0));
  if (!result.tracked) {
    ++frames_not_tracked;
    return;
  }
  ++tracked_frames;
  inliers_sum += static_cast<size_t>(std::max(result.inliers, 0));
}

std::string SfmStagesCsv(const SfmStats& s) {
  std::vector<std::pair<const char*, double>> stages = {
      {"load_wait", s.load_seconds},
      {"detect", s.front.detect},
      {"match", s.front.match},
      {"resect", s.back.resect},
      {"triangulate", s.back.triangulate},
      {"map_search", s.back.map_search},
      {"bundle_adjustment", s.back.bundle_adjustment},
      {"loop_closure", s.loop_closure_seconds},
      {"final_bundle_adjustment", s.final_bundle_adjustment_seconds},
      {"final_frame_refinement", s.final_frame_refinement_seconds},
      {"queue_wait", s.queue_wait_seconds}};
  double timed = 0.0;
  for (const auto& stage : stages) timed += stage.second;
  // The rest of the SfM's time (keyframe selection, map upkeep, handing keyframes over).
  stages.push_back({"other", std::max(0.0, s.total_seconds - timed)});
  stages.push_back({"total", s.total_seconds});
  // Detection on the prefetch thread, ahead of the frames' tracking: not part of the total.
  stages.push_back({"detect_ahead", s.front.detect_ahead});
  std::ostringstream csv;
  csv << "stage,seconds,ms_per_frame\n";
  const double frames = static_cast<double>(std::max<size_t>(s.frames, 1));
  for (const auto& [stage, seconds] : stages)
    csv << stage << ',' << seconds << ',' << 1000.0 * seconds / frames << '\n';
  return csv.str();
}

std::string SfmSummaryCsv(const SfmStats& s) {
  const size_t loaded = s.frames - s.frames_skipped;
  std::ostringstream csv;
  csv << "name,value\n"
      << "frames," << s.frames << '\n'
      << "frames_skipped," << s.frames_skipped << '\n'
      << "frames_not_tracked," << s.frames_not_tracked << '\n'
      << "keyframes," << s.keyframes << '\n'
      << "points," << s.points << '\n'
      << "mean_matched_per_frame,"
      << (loaded > 0 ? static_cast<double>(s.matched_sum) / loaded : 0.0) << '\n'
      << "mean_inliers_per_tracked_frame,"
      << (s.tracked_frames > 0 ? static_cast<double>(s.inliers_sum) / s.tracked_frames : 0.0)
      << '\n'
      << "observations," << s.colmap.observations << '\n'
      << "mean_reprojection_error_px," << s.colmap.mean_reprojection_error << '\n'
      << "mean_track_keyframes," << s.tracks.mean_keyframes << '\n'
      << "median_track_keyframes," << s.tracks.median_keyframes << '\n'
      << "mean_rays_per_point," << s.tracks.mean_rays << '\n'
      << "mean_frame_rays_per_point," << s.tracks.mean_frame_rays << '\n'
      << "frame_points," << s.tracks.frame_points << '\n'
      << "multi_camera_points_share," << s.tracks.multi_camera_share << '\n'
      << "aperture_ok_share," << s.tracks.aperture_ok_share << '\n'
      << "frames_per_second," << s.frames / std::max(s.total_seconds, 1e-9) << '\n'
      << "final_ba_rms_angle_before_deg," << s.final_ba_rms_angle_before_deg << '\n'
      << "final_ba_rms_angle_after_deg," << s.final_ba_rms_angle_after_deg << '\n'
      << "usable," << s.usable << '\n';
  return csv.str();
}

void WriteSfmStats(const SfmStats& stats, const std::filesystem::path& stats_folder) {
  WriteTextFileAtomically(stats_folder / "sfm_stages.csv", SfmStagesCsv(stats));
  WriteTextFileAtomically(stats_folder / "sfm_summary.csv", SfmSummaryCsv(stats));
}

}  // namespace omni
