#pragma once
// A simulated perfect SfM for the surface module (issue 6): keyframes along a ground-truth
// trajectory and points sampled on the visible ground-truth surface, each with its rays to the
// earlier keyframes that see it unoccluded (paper §3.3: a point of P_t is observed by keyframes
// t' ≤ t only). Central rig: every ray starts at the keyframe centre.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "calib/ply.h"
#include "calib/tum.h"
#include "surface/sculptor.h"

namespace omni {

struct GtKeyframeOptions {
  double keyframe_spacing = 1.9;  // metres between keyframe centres (paper §5.1: 2.5 km, 1306 kf)
  int points_per_keyframe = 370;  // new points per keyframe (paper §5.1: 483k points / 1306 kf)
  // Largest point–centre distance, in units of keyframe_spacing (paper §5.1: 15 s).
  double max_distance_factor = 15.0;
  int max_observing_keyframes = 12;  // earlier keyframes tried for the rays of a point
  int min_rays = 2;                  // points seen by fewer keyframes are not reconstructed
  double point_noise = 0.0;          // std. dev. of a Gaussian added to points, metres
  // Pose noise of the simulated SfM (own seeded stream, so the points sampled do not change):
  // each keyframe centre, and the origins of the rays from it, moved by a Gaussian of this std.
  // dev. per axis (metres); with LoadGtKeyframes, the keyframe poses also rotated by a Gaussian
  // angle of pose_noise_deg std. dev. per axis.
  double pose_noise = 0.0;
  double pose_noise_deg = 0.0;
  int max_keyframes = 0;  // 0: the whole trajectory
  uint64_t seed = 1;

  std::string Check() const;
};

// Indices of the keyframes: the first frame, then each frame whose centre is at least
// `spacing` metres from the previous keyframe's.
std::vector<size_t> SelectKeyframeFrames(const std::vector<Eigen::Vector3d>& centres,
                                         double spacing);

// The keyframe stream of DESIGN.md §4 over `mesh` seen from `keyframe_centres` (Embree).
std::vector<SurfaceKeyframe> MakeGtKeyframes(const TriangleMesh& mesh,
                                             const std::vector<Eigen::Vector3d>& keyframe_centres,
                                             const GtKeyframeOptions& options);

// Reads DRIVE/rig.json, DRIVE/gt/poses.tum and DRIVE/gt/mesh.ply (InputError when missing or
// malformed) and returns the stream; the centre of a frame is world_from_rig applied to the
// rig's central centre. keyframe_poses, when given, receives the ground-truth pose of each
// keyframe of the stream (what a perfect SfM would write as poses.tum).
std::vector<SurfaceKeyframe> LoadGtKeyframes(const std::filesystem::path& drive,
                                             const GtKeyframeOptions& options,
                                             TriangleMesh* gt_mesh = nullptr,
                                             std::vector<StampedPose>* keyframe_poses = nullptr);

}  // namespace omni
