#pragma once
// A simulated perfect SfM for the surface module: keyframes along a ground-truth
// trajectory and points sampled on the visible ground-truth surface, each with its rays to the
// earlier keyframes that see it unoccluded (paper §3.3: a point of P_t is observed by keyframes
// t' ≤ t only). Central rig: every ray starts at the keyframe centre.
//
// Two ways of choosing the points of a keyframe:
//  - corner mode (the default when the drive has images): the rays through the Harris corners
//    of the keyframe's images (sfm/harris.h, the SfM's detector) are cast from their camera's
//    centre onto the mesh, so that the points favour textured corners as a Harris-based SfM's
//    do;
//  - uniform mode (GT-only drives, or corner_points off): random directions from the keyframe
//    centre.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <unordered_map>
#include <vector>

#include "calib/ply.h"
#include "calib/pose.h"
#include "calib/rig.h"
#include "calib/tum.h"
#include "sfm/harris.h"
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
  // Corner mode: LoadGtKeyframes samples the points at Harris corners of the keyframe images
  // when the drive has images (uniform directions otherwise, or when this is off).
  bool corner_points = true;
  HarrisOptions harris;  // the corner detector (the SfM's defaults)
  // Corner mode: a corner whose hit is closer than this to an earlier point (of this keyframe
  // or an earlier one) is that point seen again, as an SfM track would be, not a new point
  // (metres).
  double corner_merge_distance = 0.05;
  // LoadGtKeyframes: besides the keyframes' rays, a ray from every drive frame between a point's
  // first observing keyframe and its own that sees it unoccluded within the distance bound, as
  // an SfM that tracks the point through every frame would have them (origin the frame's
  // centre, the keyframe the latest one at or before the frame). Not the SfM's contract today
  // (docs/design.md §7: keyframes' rays only): an experiment on the perfect SfM.
  bool frame_rays = false;
  // LoadGtKeyframes: free rays (SurfaceKeyframe::free_rays) from each keyframe, in each camera
  // along the pixels of a regular grid of about this many whose ray hits nothing (the sky), from
  // the keyframe centre. 0: none (an SfM hands over none today).
  int sky_rays_per_camera = 0;

  std::string Check() const;
};

// Indices of the keyframes: the first frame, then each frame whose centre is at least
// `spacing` metres from the previous keyframe's.
std::vector<size_t> SelectKeyframeFrames(const std::vector<Eigen::Vector3d>& centres,
                                         double spacing);

// The keyframe stream of docs/design.md §7 over `mesh` seen from `keyframe_centres` (Embree).
std::vector<SurfaceKeyframe> MakeGtKeyframes(const TriangleMesh& mesh,
                                             const std::vector<Eigen::Vector3d>& keyframe_centres,
                                             const GtKeyframeOptions& options);

// The images of keyframe t, one 8-bit grey (or colour) image per camera of the rig.
using GtKeyframeImages = std::function<std::vector<cv::Mat>(size_t keyframe)>;

// The corner mode: keyframe t has the rig pose world_from_rig[t] (its centre: the rig's
// central centre) and the images images(t); its points are the first hits on `mesh` of the
// rays from the camera centres through the Harris corners of its images, taken in a seeded
// random order until points_per_keyframe are kept, with the rules of MakeGtKeyframes (within
// max_distance, rays from the keyframes that see the point unoccluded, min_rays, point and pose
// noise).
std::vector<SurfaceKeyframe> MakeGtKeyframesAtCorners(const TriangleMesh& mesh, const Rig& rig,
                                                      const std::vector<Rigid3d>& world_from_rig,
                                                      const GtKeyframeImages& images,
                                                      const GtKeyframeOptions& options);

// Reads DRIVE/rig.json, DRIVE/gt/poses.tum and DRIVE/gt/mesh.ply (InputError when missing or
// malformed) and returns the stream; the centre of a frame is world_from_rig applied to the
// rig's central centre. With options.corner_points, a drive whose images match gt/poses.tum
// frame by frame gets the corner mode (images read with calib/drive.h), any other the uniform
// mode. keyframe_poses, when given, receives the ground-truth pose of each
// keyframe of the stream (what a perfect SfM would write as poses.tum).
// keyframe_frames, when given, receives the drive frame of each keyframe.
std::vector<SurfaceKeyframe> LoadGtKeyframes(const std::filesystem::path& drive,
                                             const GtKeyframeOptions& options,
                                             TriangleMesh* gt_mesh = nullptr,
                                             std::vector<StampedPose>* keyframe_poses = nullptr,
                                             std::vector<size_t>* keyframe_frames = nullptr);

// The colour of each point of `stream` (LoadGtKeyframes of `drive`, at the drive frames
// keyframe_frames) as a real SfM's points.ply has it (pipeline/point_colors.h): the mean of the
// drive's RGB images at the pixels where the point projects, in every camera of the
// ground-truth pose of each keyframe of its rays whose image it falls in. Empty when the drive
// has no images matching gt/poses.tum.
std::unordered_map<PointId, Rgb8> GtPointColors(const std::filesystem::path& drive,
                                                const std::vector<SurfaceKeyframe>& stream,
                                                const std::vector<size_t>& keyframe_frames);

}  // namespace omni
