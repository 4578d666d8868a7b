#include "apps/sfm_summary.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "apps/commands.h"
#include "calib/drive.h"
#include "pipeline/sfm_outputs.h"
#include "pipeline/sfm_runner.h"

namespace omni {

nlohmann::json SfmSummaryJson(const Drive& drive, const SfmRunResult& run,
                              const SfmOutputs& outputs, bool central,
                              const std::vector<double>& replay_seconds,
                              const std::vector<size_t>& replay_keyframes) {
  const SfmStats& stats = outputs.stats;
  const bool usable = run.outcome == SfmOutcome::kUsable;
  nlohmann::json untracked = nlohmann::json::array();
  for (const SfmUntrackedRun& gap : run.untracked_runs) {
    const auto frame_name = [&](size_t row) {
      return row < run.frames.size() ? run.frames[row].name : std::to_string(row);
    };
    untracked.push_back({{"first_frame", frame_name(gap.first)},
                         {"last_frame", frame_name(gap.last)},
                         {"frames", gap.last - gap.first + 1},
                         {"to_the_end", gap.to_the_end}});
  }
  nlohmann::json loops = nlohmann::json::array();
  for (size_t i = 0; i < run.loop_closures.size(); ++i) {
    const LoopClosureEvent& e = run.loop_closures[i].event;
    nlohmann::json loop = {
        {"keyframe", e.keyframe},
        {"frame", e.frame},
        {"candidate_keyframe", e.candidate_keyframe},
        {"candidate_frame", e.candidate_frame},
        {"ring_shift", e.shift},
        {"appearance_score", e.score},
        {"matches", e.matches},
        {"inliers", e.inliers},
        {"relative_pose_matches", e.relative_matches},
        {"relative_pose_inliers", e.relative_inliers},
        {"rotation_disagreement_deg", e.rotation_disagreement * 180.0 / M_PI},
        {"correction_translation", e.correction_translation},
        {"correction_rotation_deg", run.loop_closures[i].correction_rotation_deg},
        {"correction_scale", e.correction_scale},
        {"ms", e.ms}};
    if (i < replay_seconds.size()) loop["surface_replay_seconds"] = replay_seconds[i];
    if (i < replay_keyframes.size()) loop["surface_replay_keyframes"] = replay_keyframes[i];
    loops.push_back(loop);
  }
  const bool final_ba =
      run.final_bundle_adjustment_seconds > 0.0 && run.final_rms_angle_after > 0.0;
  nlohmann::json frame_range = {{"drive_frames", drive.NumFrames()}};
  if (!run.frames.empty()) {
    frame_range["first"] = run.frames.front().frame;
    frame_range["last"] = run.frames.back().frame;
    frame_range["first_name"] = run.frames.front().name;
    frame_range["last_name"] = run.frames.back().name;
  }
  return {
      {"drive", drive.folder().string()},
      {"drive_absolute", std::filesystem::absolute(drive.folder()).lexically_normal().string()},
      {"frame_range", frame_range},
      {"status", usable ? "usable" : "not_usable"},
      {"sfm_outcome", SfmOutcomeName(run.outcome)},
      {"outcome", run.outcome_reason},
      {"mode", central ? "central" : "non-central"},
      {"front_end",
       {{"corners_per_image", run.corners_per_image},
        {"corner_quality", run.corner_quality},
        {"continuation_pool", run.continuation_pool},
        {"epipolar_min_depth", run.epipolar_min_depth},
        {"epipolar_search_radius", run.epipolar_search_radius},
        {"epipolar_max_search_radius", run.epipolar_max_search_radius},
        {"epipolar_matches", run.epipolar_matches},
        {"min_tracked_share", run.min_tracked_share},
        {"min_followed_track_share", run.min_followed_track_share}}},
      {"scale",
       {{"metric", run.metric_scale},
        {"source", run.scale_source},
        {"largest_camera_offset_m", run.largest_camera_offset},
        {"median_point_depth", run.median_point_depth},
        {"offset_depth_ratio", run.offset_depth_ratio}}},
      {"frames", run.frames_total},
      {"frames_skipped", run.skipped.size()},
      {"skipped", run.skipped},
      {"warnings", WarningsLogged()},
      {"frames_tracked", run.frames_tracked},
      {"frames_not_tracked", stats.frames_not_tracked},
      {"untracked_runs", untracked},
      {"keyframes", run.keyframes.size()},
      {"points", outputs.cloud.points.size()},
      {"colmap_images", stats.colmap.images},
      {"colmap_points", stats.colmap.points},
      {"colmap_mean_reprojection_error_px", stats.colmap.mean_reprojection_error},
      {"loop_closures", loops},
      {"final_bundle_adjustment",
       {{"ran", final_ba},
        {"seconds", run.final_bundle_adjustment_seconds},
        {"free_keyframes", run.final_free_keyframes},
        {"adjusted_frames", run.final_adjusted_frames},
        {"rms_angle_before_deg", run.final_rms_angle_before * 180.0 / M_PI},
        {"rms_angle_after_deg", run.final_rms_angle_after * 180.0 / M_PI}}},
      {"final_frame_refinement",
       {{"frames_tried", run.frames_refinement_tried},
        {"frames_refined", run.frames_refined},
        {"seconds", run.final_frame_refinement_seconds}}},
      {"sfm_seconds", run.seconds},
      {"frames_per_second", run.frames_total / std::max(run.seconds, 1e-9)},
      {"stage_seconds",
       {{"detect", run.front.detect},
        {"match", run.front.match},
        {"map_search", run.back.map_search},
        {"resect", run.back.resect},
        {"triangulate", run.back.triangulate},
        {"bundle_adjustment", run.back.bundle_adjustment},
        {"loop_closure", run.loop_closure_seconds},
        {"waiting_for_images", run.load_seconds},
        {"point_colors", outputs.colors.seconds}}},
  };
}

}  // namespace omni
