#include "sfm/keyframe_selection.h"

#include <limits>

#include "calib/error.h"

namespace omni {

std::string KeyframeSelectionOptions::Check() const {
  if (!(min_baseline_ratio >= 0.0)) return "min_baseline_ratio: expected a non-negative ratio";
  if (!(max_baseline_ratio > min_baseline_ratio))
    return "max_baseline_ratio: expected a ratio above min_baseline_ratio";
  if (!(max_rotation > 0.0)) return "max_rotation: expected a positive angle (radians)";
  if (!(min_tracked_share > 0.0 && min_tracked_share < 1.0))
    return "min_tracked_share: expected a value in (0, 1)";
  if (!(min_followed_track_share >= 0.0 && min_followed_track_share < 1.0))
    return "min_followed_track_share: expected a value in [0, 1)";
  if (min_tracked_points < 0) return "min_tracked_points: expected 0 or more";
  return {};
}

KeyframeDecisionReason DecideKeyframe(const KeyframeCandidate& candidate,
                                      const KeyframeSelectionOptions& options) {
  ThrowIfInvalid(options.Check(), "KeyframeSelectionOptions");
  KeyframeDecisionReason result;
  const double baseline =
      (candidate.world_from_rig.translation - candidate.last_keyframe_world_from_rig.translation)
          .norm();
  result.baseline_ratio = candidate.median_depth > 0.0 ? baseline / candidate.median_depth
                                                       : std::numeric_limits<double>::infinity();
  result.rotation = candidate.world_from_rig.rotation.angularDistance(
      candidate.last_keyframe_world_from_rig.rotation);
  result.tracked_share =
      candidate.last_keyframe_points > 0
          ? static_cast<double>(candidate.tracked_points) / candidate.last_keyframe_points
          : 0.0;
  result.followed_track_share =
      candidate.last_keyframe_tracks > 0
          ? static_cast<double>(candidate.followed_tracks) / candidate.last_keyframe_tracks
          : 1.0;
  if (result.baseline_ratio > options.max_baseline_ratio) {
    result.decision = KeyframeDecision::kKeyframe;
    result.reason = "large baseline";
  } else if (result.rotation > options.max_rotation) {
    result.decision = KeyframeDecision::kKeyframe;
    result.reason = "large rotation";
  } else if (result.baseline_ratio < options.min_baseline_ratio) {
    result.reason = "small baseline";
  } else if (result.tracked_share < options.min_tracked_share) {
    result.decision = KeyframeDecision::kKeyframe;
    result.reason = "few tracked points";
  } else if (result.followed_track_share < options.min_followed_track_share) {
    result.decision = KeyframeDecision::kKeyframe;
    result.reason = "few tracks followed";
  } else if (candidate.inliers < options.min_tracked_points) {
    result.decision = KeyframeDecision::kKeyframe;
    result.reason = "few points left";
  } else {
    result.reason = "enough tracked points";
  }
  return result;
}

}  // namespace omni
