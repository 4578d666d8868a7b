#pragma once
// `omnisculpt merge` (docs/design.md §12): reconstructions of segments of drives, made apart
// (`reconstruct --frames A:B`, one cluster task each), brought into one map. Each input is a
// reconstruction folder (reconstruct.json, sparse/, frame_poses.tum, poses.tum; or the folder
// of an `sfm` run, with sfm.json) whose drive is still reachable (the frames' names,
// timestamps and images come from it). Two segments of one drive
// that share frames are aligned by a similarity from those frames' poses, checked frame by frame
// (rotation and centre residuals); the similarities go into one pose graph over the segments
// (sfm/pose_graph.h), solved with the largest segment fixed. The merged model keeps, for every
// image, the pose of the segment in which its frame is farthest from the segment's ends (the
// best constrained), the 2-D points of every segment, and one 3-D point per set of segment
// points that share a corner (the same pixel of the same image): duplicates are fused. The
// segments' rays of the frames between keyframes (sparse/frame_rays.txt) follow: each frame's from
// the segment that poses it, each frame point from the segment that poses its last frame.

#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "calib/colmap_text.h"
#include "calib/pose.h"
#include "calib/rig.h"
#include "calib/tum.h"
#include "sfm/bundle_adjustment.h"
#include "sfm/loop_closure.h"
#include "sfm/pose_graph.h"

namespace omni {

// Revisits between segments that share no frame (a drive's loop cut into segments, two drives
// through one street): the loop closer's place recognition (sfm/loop_closure.h) over the
// segments' keyframes, then all-pairs ZNCC matching of the keyframes' corners that have a 3-D
// point and a similarity of those points in RANSAC.
struct MergeRevisitOptions {
  bool enabled = true;
  // Thumbnails, ring, minimum appearance score; ZNCC matching; images prepared at
  // prepared_downscale; RANSAC iterations; inlier_depth_share; min_inliers.
  LoopClosureOptions loop;
  // Of one drive, keyframes closer than this many frames are not a revisit (the segments'
  // shared frames align those), nor are frames inside the querying segment's own range.
  int min_frame_gap = 30;
  int candidates_per_keyframe = 2;  // verified per keyframe, best appearance first
  // Revisits kept per pair of segments, most inliers first, each of another place (their
  // frames in the querying segment min_frame_gap apart).
  int max_revisits_per_pair = 3;
  double min_inlier_ratio = 0.5;  // similarity inliers over the 3-D matches
  // When the shared frames already align the two segments: the revisit's similarity must move
  // the revisiting keyframe by at most this share of the merged drive's length and turn it by
  // at most max_rotation_deg (drift, not a look-alike place).
  double max_drift_share = 0.1;
  double max_rotation_deg = 5.0;
  unsigned seed = 1;

  std::string Check() const;
};

struct MergeOptions {
  // A verified overlap has at least this many shared frames that agree with the similarity.
  int min_shared_frames = 5;
  // A shared frame agrees when its rotation is within this angle (degrees) of the similarity's
  // and its centre within max_centre_residual_share of the overlap's path length (plus
  // min_centre_residual, in the units of the segment the other is mapped into).
  double max_rotation_residual_deg = 1.0;
  double max_centre_residual_share = 0.02;
  double min_centre_residual = 0.01;
  // Two 2-D points of one image closer than this (pixels) are one corner (the SfM detects the
  // same corners in the same image).
  double corner_tolerance_px = 0.25;
  MergeRevisitOptions revisits;
  PoseGraphOptions pose_graph;
  // Then a global bundle adjustment of the merged map (every keyframe and point, the first two
  // keyframes fixed), when the segments are of one drive and the map has at most this many
  // observations; the other frames follow their nearest keyframe. It needs complete tracks
  // in sparse/ (as the SfM writes them, docs/design.md §6).
  bool global_bundle_adjustment = true;
  size_t max_adjusted_observations = 3000000;
  BundleAdjustmentOptions bundle_adjustment = DefaultGlobalAdjustment();
  static BundleAdjustmentOptions DefaultGlobalAdjustment();

  std::string Check() const;
};

// One input reconstruction, loaded. Frames are the drive's indices.
struct MergeSegment {
  std::filesystem::path folder;
  std::string drive;                       // the drive's folder, absolute
  std::string drive_label;                 // its name in the merged model (unique among the drives)
  size_t first_frame = 0, last_frame = 0;  // the segment's range (inclusive)
  ColmapModel model;                       // sparse/
  std::map<size_t, StampedPose> frame_poses;     // frame_poses.tum by frame index
  std::map<size_t, StampedPose> keyframe_poses;  // poses.tum by frame index
  std::map<std::string, size_t> frame_of_name;   // the drive's frame names
  std::string mode;                              // "central" or "non-central"
  Rig rig;                                       // the drive's rig.json
};

// Loads a reconstruction folder. Returns nothing and sets *why (one line) when it is not a
// complete and usable reconstruction: missing, interrupted (OUT.incomplete), not usable, its
// drive not reachable, or a file in it malformed (the InputError's message).
std::optional<MergeSegment> LoadMergeSegment(const std::filesystem::path& folder, std::string* why);

// An overlap between two segments and how it was verified.
struct MergeOverlap {
  int a = 0, b = 0;  // segment indices
  std::string kind;  // "shared frames" or "revisit"
  int shared_frames = 0, inliers = 0;
  // A revisit: the keyframes' frames (a's and b's), the appearance score, the 3-D matches, and
  // the point pairs (a's point id, b's) of the inliers, which the merge fuses.
  size_t frame_a = 0, frame_b = 0;
  double score = 0.0;
  int matches = 0;
  std::vector<std::pair<uint32_t, uint32_t>> point_pairs;
  double rms_rotation_deg = 0.0, rms_centre = 0.0;  // over the inliers, in a's units
  Sim3d a_from_b;
  bool verified = false;
  std::string refusal;  // why it was not verified (empty when verified)
};

struct MergedDrive {
  std::string label, folder;
  std::vector<StampedPose> keyframes, frames;  // world_from_rig of the merged map, in time order
  std::vector<size_t> keyframe_frames, frame_frames;  // their frame indices
  std::vector<int> frame_segments;  // the segment each frame's pose comes from (most central)
};

struct MergeResult {
  std::vector<MergeOverlap> overlaps;
  // Per segment: merged into the map, its similarity city_from_segment, or why not.
  std::vector<bool> merged;
  std::vector<Sim3d> city_from_segment;
  std::vector<std::string> not_merged_why;
  int fixed_segment = -1;
  PoseGraphSummary pose_graph;
  ColmapModel model;  // the merged sparse model, with its frame rays
  std::vector<MergedDrive> drives;
  size_t input_points = 0;   // 3-D points of the merged segments
  size_t fused_points = 0;   // merged points made of more than one segment point
  size_t shared_images = 0;  // images present in more than one merged segment
  // The global adjustment: whether it ran (or why not), and its summary.
  bool adjusted = false;
  std::string adjustment_skipped;
  BundleAdjustmentSummary adjustment;
  double adjustment_seconds = 0.0;
};

// Aligns and merges the segments (at least one). Segments that no verified overlap connects to
// the largest group are left out (merged false, with why).
MergeResult MergeSegments(const std::vector<MergeSegment>& segments, const MergeOptions& options);

}  // namespace omni
