#pragma once
// Keyframe selection after Mouragnon et al. (BMVC 2007), as the paper's SfM does (§2): a frame
// becomes a keyframe when it has moved enough from the last keyframe for the new points to be
// well triangulated, and at the latest when the share of the last keyframe's points still
// tracked falls low (so consecutive keyframes keep enough common points), or when the motion
// grows too large for the matching to keep up. Motion is measured relative to the scene depth,
// so the same options work at the SfM's arbitrary scale.

#include <string>

#include "calib/pose.h"

namespace omni {

struct KeyframeSelectionOptions {
  // Baseline ratio = distance between rig centres / median depth of the tracked points.
  double min_baseline_ratio = 0.03;  // below: too little parallax, never a keyframe
  double max_baseline_ratio = 0.25;  // above: a keyframe whatever the tracking
  double max_rotation = 0.35;        // radians (≈ 20°) since the last keyframe: a keyframe
  // A keyframe once fewer than this share of the last keyframe's points are still tracked.
  // On the synthetic demo drive (0.44 m between frames) 0.3 gives a keyframe every ~1.5 m,
  // close to the paper's 1.9 m (§5), with the same trajectory error as 0.7 (every frame).
  double min_tracked_share = 0.3;
  // A keyframe also once fewer than this share of the last keyframe's tracks (all its
  // observations, with or without a point) are still followed (0: off). A track becomes a point
  // only when two keyframes see it: where tracks die within a few frames (side cameras close to
  // the street, a low frame rate) while the far points stay, the point rule above waits too
  // long and most tracks end between two keyframes, never in the map. On the car rig's drive
  // (six pinhole cameras 1-1.5 m off the centre, 0.8 m between frames) the point rule alone
  // took a keyframe once 10-15 % of the tracks were left, every 4.4 m, with 120-215 points
  // each; with 0.25 the keyframes' error over 15 starts was 0.57 times as large, at 0.93 times
  // the frames/s; the Ladybug-like rig, whose tracks live longer, barely changes
  // (docs/figures.md F83).
  double min_followed_track_share = 0.25;
  // A keyframe also once fewer than this many points are tracked, whatever the share: the map
  // must grow before the tracking runs out of points (wide baselines, low frame rates).
  int min_tracked_points = 60;

  std::string Check() const;
};

enum class KeyframeDecision {
  kSkip,      // an ordinary frame
  kKeyframe,  // make it a keyframe
};

struct KeyframeCandidate {
  Rigid3d last_keyframe_world_from_rig;
  Rigid3d world_from_rig;        // the current frame's estimated pose
  int last_keyframe_points = 0;  // points of the last keyframe
  int tracked_points = 0;        // of those, still tracked in the current frame
  int last_keyframe_tracks = 0;  // observations (tracks) of the last keyframe
  int followed_tracks = 0;       // of those, still followed in the current frame
  int inliers = 0;               // points of the map the frame's pose agrees with
  double median_depth = 0.0;     // of the tracked points from the current frame (map units)
};

// Why a frame was (or not) chosen, for the statistics.
struct KeyframeDecisionReason {
  KeyframeDecision decision = KeyframeDecision::kSkip;
  double baseline_ratio = 0.0;
  double rotation = 0.0;
  double tracked_share = 0.0;
  double followed_track_share = 0.0;
  const char* reason = "";
};

KeyframeDecisionReason DecideKeyframe(const KeyframeCandidate& candidate,
                                      const KeyframeSelectionOptions& options);

}  // namespace omni
