#pragma once
// Surface evaluation against ground truth (paper §5.2):
// * the ray-traced error: for pixels sampled uniformly over the keyframe images of every
//   camera, the first hit of the pixel's ray from the registered estimated pose in the
//   registered estimated surface and from the ground-truth pose in the ground-truth surface;
//   error = distance between the hits where both exist;
// * pixel precision / recall / F-score from the same rays: a pixel is right at τ when both hits
//   exist and are less than τ apart; precision counts it among the pixels with an estimated
//   hit, recall among those with a ground-truth hit; the tail (errors above a length) is split
//   by whether the estimated hit is nearer its camera than the ground-truth hit or not;
// * surface against surface: accuracy (estimated → GT) and completeness (GT → estimated, over
//   the part of the GT surface the drive saw) on uniform area samples, precision / recall /
//   F-score at given distances;
// * distances of points (the SfM cloud) to the GT surface.
// Every length is in ground-truth units (metres).

#include <cstdint>
#include <string>
#include <vector>

#include "calib/rig.h"
#include "eval/pose_eval.h"
#include "raycast/raycast.h"

namespace omni {

struct KeyframePoses {
  Rigid3d estimated_world_from_rig;  // registered: S applied (TransformPose), rig in metres
  Rigid3d gt_world_from_rig;
};

struct RayErrorOptions {
  long pixels = 769000;  // paper §5.2 samples 769k pixels
  uint64_t seed = 1;
  // A hit farther than this from the camera counts as no hit (infinite: any distance).
  double max_ray_length = std::numeric_limits<double>::infinity();
  std::vector<double> quantile_levels = {0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9};
  double large_error = 6.0;  // paper §5.2: share of errors above 600 cm
  // Pixel precision / recall / F-score at these distances (metres).
  std::vector<double> pixel_thresholds = {0.2, 0.5};
  double pixel_tail_error = 1.0;  // the tail: both-hit pixels whose error is above this

  std::string Check() const;
};

// Pixel precision / recall at one distance.
struct PixelPrecisionRecall {
  double threshold = 0.0;
  long within = 0;         // pixels with both hits less than threshold apart
  double precision = 0.0;  // within / estimated_hits (0 without an estimated hit)
  double recall = 0.0;     // within / gt_hits (0 without a ground-truth hit)
  double f_score = 0.0;    // harmonic mean (0 when both are 0)
};

// The pixel figures of one camera, or of all (camera empty), or of the pixels whose
// ground-truth hit is on the triangles of one label (label set; then every ray has a
// ground-truth hit).
struct PixelScores {
  std::string camera;  // the camera's name; empty for the total
  std::string label;   // the label's name; empty unless the figures are a label's
  long rays = 0, estimated_hits = 0, gt_hits = 0, both_hits = 0;
  std::vector<PixelPrecisionRecall> precision_recall;  // one per RayErrorOptions threshold
  // Both-hit pixels with an error above pixel_tail_error: all of them, those whose estimated hit
  // is nearer the camera than the ground-truth hit (‖hit_e − c_e‖ < ‖hit_g − c_g‖, each from the
  // camera centre of its own pose: "in front"), and the others ("behind").
  long tail_count = 0, tail_front_count = 0, tail_behind_count = 0;
  double tail = 0.0, tail_front = 0.0, tail_behind = 0.0;  // of both_hits (0 without)
};

struct RayErrorResult {
  long sampled_pixels = 0;  // pixels drawn
  long rays = 0;            // of which the camera model unprojects
  long estimated_hits = 0, gt_hits = 0, both_hits = 0;
  double share_estimated_hit = 0.0, share_gt_hit = 0.0, share_both_hit = 0.0;  // of rays
  std::vector<double> quantile_levels;
  std::vector<double> quantiles;   // of the errors, one per level
  double share_above_large = 0.0;  // of the errors
  ErrorStats errors;
  std::vector<double> sorted_errors;       // for the CDF
  double pixel_tail_error = 0.0;           // metres, as in the options
  PixelScores pixel;                       // all cameras
  std::vector<PixelScores> pixel_cameras;  // one per rig camera, in rig order
  // With GtLabels: one per label, in label order (every named label, and every other label a
  // ground-truth hit met).
  std::vector<PixelScores> pixel_labels;
};

// What the ground truth's triangles are (TriangleMesh::labels: synth's kinds of surface, a
// pole, a wall, the road...), for the pixel figures per label.
struct GtLabels {
  std::vector<uint8_t> per_triangle;  // of the ground-truth mesh; empty: no figures per label
  std::vector<std::string> names;     // names[label]; a label beyond them is "label N"
};

// Throws InputError when there is no keyframe; std::invalid_argument when a ground-truth hit's
// triangle has no label in a non-empty labels.per_triangle.
RayErrorResult EvaluateRayErrors(const Rig& rig, const std::vector<KeyframePoses>& keyframes,
                                 const RayCaster& estimated_surface, const RayCaster& gt_surface,
                                 const RayErrorOptions& options = {}, const GtLabels& labels = {});

struct SurfaceCompareOptions {
  long samples = 200000;  // uniform area samples on each surface
  uint64_t seed = 2;
  std::vector<double> thresholds = {0.2, 0.5};  // metres, precision/recall/F-score
  // Seen part of the GT surface: GT samples near the hits of visibility rays (pixels sampled as
  // in the ray error, from the GT keyframe poses) within max_ray_length. The paper's point
  // filter keeps points within 15 s of the keyframe (§5.1; s ≈ 1.8 m on its synthetic drive).
  long visibility_rays = 1000000;
  double max_ray_length = 30.0;
  // A GT sample is seen when a visibility hit falls in its voxel or a neighbouring one.
  double visibility_voxel = 0.25;

  std::string Check() const;
};

struct PrecisionRecall {
  double threshold = 0.0;
  double precision = 0.0;  // share of estimated samples within threshold of GT
  double recall = 0.0;     // share of seen GT samples within threshold of the estimate
  double f_score = 0.0;
};

struct SurfaceCompareResult {
  long estimated_samples = 0;
  long gt_samples = 0;
  long gt_samples_seen = 0;
  ErrorStats accuracy;      // estimated → GT
  ErrorStats completeness;  // seen GT → estimated
  std::vector<PrecisionRecall> precision_recall;
};

// The meshes are the ones the casters were built from. Without GT keyframe poses (empty), every
// GT sample counts as seen.
SurfaceCompareResult CompareSurfaces(const TriangleMesh& estimated_surface,
                                     const RayCaster& estimated_caster,
                                     const TriangleMesh& gt_surface, const RayCaster& gt_caster,
                                     const Rig& rig, const std::vector<Rigid3d>& gt_world_from_rigs,
                                     const SurfaceCompareOptions& options = {});

struct PointDistanceResult {
  long points = 0;
  std::vector<double> quantile_levels = {0.1, 0.25, 0.5, 0.75, 0.9};
  std::vector<double> quantiles;
  ErrorStats distances;
};
PointDistanceResult PointDistances(const std::vector<Eigen::Vector3d>& points,
                                   const RayCaster& gt_caster);

// `count` points uniformly distributed over the area of the mesh (deterministic for a seed).
std::vector<Eigen::Vector3d> SampleSurface(const TriangleMesh& mesh, long count, uint64_t seed);

struct PixelSample {
  int keyframe = 0;
  int camera = 0;
  Eigen::Vector2d pixel;
};
// `count` pixels uniformly over all the pixels of all the keyframe images.
std::vector<PixelSample> SamplePixels(const Rig& rig, int keyframes, long count, uint64_t seed);

// The world ray of a pixel seen from a rig pose; false when the camera cannot unproject it.
bool PixelRay(const Camera& camera, const Rigid3d& world_from_rig, const Eigen::Vector2d& pixel,
              Ray* ray);

}  // namespace omni
