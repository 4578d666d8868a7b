#include "eval/surface_eval.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>
#include <stdexcept>
#include <string>
#include <unordered_set>
#include <utility>

#include "calib/error.h"

namespace omni {
namespace {

std::vector<double> SortedFinite(const std::vector<double>& values) {
  std::vector<double> sorted;
  sorted.reserve(values.size());
  for (double v : values) {
    if (std::isfinite(v)) sorted.push_back(v);
  }
  std::sort(sorted.begin(), sorted.end());
  return sorted;
}

double ShareBelow(const std::vector<double>& sorted, double threshold) {
  if (sorted.empty()) return 0.0;
  return static_cast<double>(std::upper_bound(sorted.begin(), sorted.end(), threshold) -
                             sorted.begin()) /
         static_cast<double>(sorted.size());
}

uint64_t VoxelKey(const Eigen::Vector3i& voxel) {
  // 21 bits per axis, offset to be positive: 2^21 voxels of 0.25 m = 524 km per axis.
  const uint64_t mask = (1u << 21) - 1;
  const auto x = static_cast<uint64_t>(voxel.x() + (1 << 20)) & mask;
  const auto y = static_cast<uint64_t>(voxel.y() + (1 << 20)) & mask;
  const auto z = static_cast<uint64_t>(voxel.z() + (1 << 20)) & mask;
  return (x << 42) | (y << 21) | z;
}

Eigen::Vector3i VoxelOf(const Eigen::Vector3d& point, double voxel) {
  return (point / voxel).array().floor().cast<int>();
}

double Ratio(long count, long of) {
  return of > 0 ? static_cast<double>(count) / static_cast<double>(of) : 0.0;
}

// One ray's contribution to the pixel figures: its hits and, with both, the error and whether
// the estimated hit is nearer its camera (both rays start at their camera centre, so the hit
// distances are the distances to the centres).
void AddPixel(bool estimated_hit, bool gt_hit, double error, bool estimate_in_front,
              const RayErrorOptions& options, PixelScores* scores) {
  ++scores->rays;
  scores->estimated_hits += estimated_hit;
  scores->gt_hits += gt_hit;
  if (!(estimated_hit && gt_hit)) return;
  ++scores->both_hits;
  for (size_t t = 0; t < options.pixel_thresholds.size(); ++t) {
    scores->precision_recall[t].within += error < options.pixel_thresholds[t];
  }
  if (error > options.pixel_tail_error) {
    ++scores->tail_count;
    ++(estimate_in_front ? scores->tail_front_count : scores->tail_behind_count);
  }
}

void FinishPixelScores(PixelScores* scores) {
  for (PixelPrecisionRecall& pr : scores->precision_recall) {
    pr.precision = Ratio(pr.within, scores->estimated_hits);
    pr.recall = Ratio(pr.within, scores->gt_hits);
    pr.f_score = pr.precision + pr.recall > 0.0
                     ? 2.0 * pr.precision * pr.recall / (pr.precision + pr.recall)
                     : 0.0;
  }
  scores->tail = Ratio(scores->tail_count, scores->both_hits);
  scores->tail_front = Ratio(scores->tail_front_count, scores->both_hits);
  scores->tail_behind = Ratio(scores->tail_behind_count, scores->both_hits);
}

PixelScores EmptyPixelScores(std::string camera, const std::vector<double>& thresholds) {
  PixelScores scores;
  scores.camera = std::move(camera);
  for (double threshold : thresholds) {
    PixelPrecisionRecall pr;
    pr.threshold = threshold;
    scores.precision_recall.push_back(pr);
  }
  return scores;
}

}  // namespace

std::string RayErrorOptions::Check() const {
  if (pixels <= 0) return "pixels: must be > 0";
  if (!(max_ray_length > 0.0)) return "max_ray_length: must be > 0";
  if (!(large_error > 0.0)) return "large_error: must be > 0";
  for (double q : quantile_levels) {
    if (!(q >= 0.0 && q <= 1.0)) return "quantile_levels: must be in [0, 1]";
  }
  for (double t : pixel_thresholds) {
    if (!(t > 0.0)) return "pixel_thresholds: must be > 0";
  }
  if (!(pixel_tail_error > 0.0)) return "pixel_tail_error: must be > 0";
  return {};
}

std::string SurfaceCompareOptions::Check() const {
  if (samples <= 0) return "samples: must be > 0";
  if (visibility_rays < 0) return "visibility_rays: must be >= 0";
  if (!(max_ray_length > 0.0)) return "max_ray_length: must be > 0";
  if (!(visibility_voxel > 0.0)) return "visibility_voxel: must be > 0";
  for (double t : thresholds) {
    if (!(t > 0.0)) return "thresholds: must be > 0";
  }
  return {};
}

bool PixelRay(const Camera& camera, const Rigid3d& world_from_rig, const Eigen::Vector2d& pixel,
              Ray* ray) {
  Eigen::Vector3d bearing;
  if (!camera.Unproject(pixel, &bearing)) return false;
  ray->origin = world_from_rig * camera.cam_from_rig.Center();
  ray->direction =
      (world_from_rig.rotation * (camera.cam_from_rig.rotation.conjugate() * bearing)).normalized();
  return true;
}

std::vector<PixelSample> SamplePixels(const Rig& rig, int keyframes, long count, uint64_t seed) {
  std::vector<PixelSample> samples;
  if (keyframes <= 0 || rig.cameras.empty() || count <= 0) return samples;
  std::vector<double> weights;
  for (const Camera& camera : rig.cameras) {
    weights.push_back(static_cast<double>(camera.width) * camera.height);
  }
  std::mt19937_64 rng(seed);
  std::discrete_distribution<int> pick_camera(weights.begin(), weights.end());
  std::uniform_int_distribution<int> pick_keyframe(0, keyframes - 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  samples.reserve(count);
  for (long i = 0; i < count; ++i) {
    PixelSample sample;
    sample.keyframe = pick_keyframe(rng);
    sample.camera = pick_camera(rng);
    const Camera& camera = rig.cameras[sample.camera];
    sample.pixel = Eigen::Vector2d(unit(rng) * camera.width - 0.5, unit(rng) * camera.height - 0.5);
    samples.push_back(sample);
  }
  return samples;
}

std::vector<Eigen::Vector3d> SampleSurface(const TriangleMesh& mesh, long count, uint64_t seed) {
  std::vector<double> cumulative_area;
  cumulative_area.reserve(mesh.triangles.size());
  double total = 0.0;
  for (const auto& tri : mesh.triangles) {
    total += 0.5 * (mesh.vertices[tri[1]] - mesh.vertices[tri[0]])
                       .cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]])
                       .norm();
    cumulative_area.push_back(total);
  }
  std::vector<Eigen::Vector3d> points;
  if (!(total > 0.0)) return points;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  points.reserve(count);
  for (long i = 0; i < count; ++i) {
    const double at = unit(rng) * total;
    const size_t t =
        std::min<size_t>(std::upper_bound(cumulative_area.begin(), cumulative_area.end(), at) -
                             cumulative_area.begin(),
                         cumulative_area.size() - 1);
    double u = unit(rng), v = unit(rng);
    if (u + v > 1.0) {
      u = 1.0 - u;
      v = 1.0 - v;
    }
    const auto& tri = mesh.triangles[t];
    const Eigen::Vector3d& a = mesh.vertices[tri[0]];
    points.push_back(a + u * (mesh.vertices[tri[1]] - a) + v * (mesh.vertices[tri[2]] - a));
  }
  return points;
}

RayErrorResult EvaluateRayErrors(const Rig& rig, const std::vector<KeyframePoses>& keyframes,
                                 const RayCaster& estimated_surface, const RayCaster& gt_surface,
                                 const RayErrorOptions& options, const GtLabels& labels) {
  if (const std::string problem = options.Check(); !problem.empty()) {
    throw InputError("", "ray error options", problem);
  }
  if (keyframes.empty()) throw InputError("", "keyframes", "no keyframe to sample pixels from");
  const std::vector<PixelSample> samples =
      SamplePixels(rig, static_cast<int>(keyframes.size()), options.pixels, options.seed);
  RayErrorResult result;
  result.sampled_pixels = static_cast<long>(samples.size());
  std::vector<Ray> estimated_rays, gt_rays;
  std::vector<int> ray_cameras;
  estimated_rays.reserve(samples.size());
  gt_rays.reserve(samples.size());
  ray_cameras.reserve(samples.size());
  for (const PixelSample& sample : samples) {
    const Camera& camera = rig.cameras[sample.camera];
    Ray estimated_ray, gt_ray;
    if (!PixelRay(camera, keyframes[sample.keyframe].estimated_world_from_rig, sample.pixel,
                  &estimated_ray) ||
        !PixelRay(camera, keyframes[sample.keyframe].gt_world_from_rig, sample.pixel, &gt_ray)) {
      continue;
    }
    estimated_ray.max_distance = gt_ray.max_distance = options.max_ray_length;
    estimated_rays.push_back(estimated_ray);
    gt_rays.push_back(gt_ray);
    ray_cameras.push_back(sample.camera);
  }
  result.rays = static_cast<long>(gt_rays.size());
  const std::vector<RayHit> estimated_hits = estimated_surface.CastMany(estimated_rays);
  const std::vector<RayHit> gt_hits = gt_surface.CastMany(gt_rays);
  result.pixel_tail_error = options.pixel_tail_error;
  result.pixel = EmptyPixelScores("", options.pixel_thresholds);
  for (const Camera& camera : rig.cameras) {
    result.pixel_cameras.push_back(EmptyPixelScores(camera.name, options.pixel_thresholds));
  }
  // Per label, indexed by the label (at most 256), made when named or first met.
  std::vector<PixelScores> label_scores(labels.per_triangle.empty() ? 0 : 256,
                                        EmptyPixelScores("", options.pixel_thresholds));
  std::vector<bool> label_used(256, false);
  for (size_t l = 0; l < std::min<size_t>(labels.names.size(), 256); ++l) label_used[l] = true;
  std::vector<double> errors;
  for (size_t i = 0; i < gt_rays.size(); ++i) {
    const bool estimated_hit = estimated_hits[i].Hit();
    const bool gt_hit = gt_hits[i].Hit();
    result.estimated_hits += estimated_hit;
    result.gt_hits += gt_hit;
    double error = 0.0;
    if (estimated_hit && gt_hit) {
      ++result.both_hits;
      const Eigen::Vector3d p_e =
          estimated_rays[i].origin + estimated_hits[i].distance * estimated_rays[i].direction;
      const Eigen::Vector3d p_g = gt_rays[i].origin + gt_hits[i].distance * gt_rays[i].direction;
      error = (p_e - p_g).norm();
      errors.push_back(error);
    }
    const bool in_front = estimated_hits[i].distance < gt_hits[i].distance;
    AddPixel(estimated_hit, gt_hit, error, in_front, options, &result.pixel);
    AddPixel(estimated_hit, gt_hit, error, in_front, options,
             &result.pixel_cameras[ray_cameras[i]]);
    if (gt_hit && !labels.per_triangle.empty()) {
      const size_t triangle = static_cast<size_t>(gt_hits[i].triangle);
      if (triangle >= labels.per_triangle.size()) {
        throw std::invalid_argument("EvaluateRayErrors: ground-truth triangle " +
                                    std::to_string(triangle) + " has no label (" +
                                    std::to_string(labels.per_triangle.size()) + " labels)");
      }
      const uint8_t label = labels.per_triangle[triangle];
      label_used[label] = true;
      AddPixel(estimated_hit, gt_hit, error, in_front, options, &label_scores[label]);
    }
  }
  FinishPixelScores(&result.pixel);
  for (PixelScores& scores : result.pixel_cameras) FinishPixelScores(&scores);
  if (!labels.per_triangle.empty()) {
    for (size_t l = 0; l < label_scores.size(); ++l) {
      if (!label_used[l]) continue;
      PixelScores& scores = label_scores[l];
      scores.label = l < labels.names.size() ? labels.names[l] : "label " + std::to_string(l);
      FinishPixelScores(&scores);
      result.pixel_labels.push_back(std::move(scores));
    }
  }
  if (result.rays > 0) {
    result.share_estimated_hit = static_cast<double>(result.estimated_hits) / result.rays;
    result.share_gt_hit = static_cast<double>(result.gt_hits) / result.rays;
    result.share_both_hit = static_cast<double>(result.both_hits) / result.rays;
  }
  result.errors = ComputeErrorStats(errors);
  std::sort(errors.begin(), errors.end());
  result.quantile_levels = options.quantile_levels;
  for (double q : options.quantile_levels) result.quantiles.push_back(QuantileOfSorted(errors, q));
  result.share_above_large = errors.empty() ? 0.0 : 1.0 - ShareBelow(errors, options.large_error);
  result.sorted_errors = std::move(errors);
  return result;
}

SurfaceCompareResult CompareSurfaces(const TriangleMesh& estimated_surface,
                                     const RayCaster& estimated_caster,
                                     const TriangleMesh& gt_surface, const RayCaster& gt_caster,
                                     const Rig& rig, const std::vector<Rigid3d>& gt_world_from_rigs,
                                     const SurfaceCompareOptions& options) {
  if (const std::string problem = options.Check(); !problem.empty()) {
    throw InputError("", "surface comparison options", problem);
  }
  SurfaceCompareResult result;
  const std::vector<Eigen::Vector3d> estimated_samples =
      SampleSurface(estimated_surface, options.samples, options.seed);
  std::vector<Eigen::Vector3d> gt_samples =
      SampleSurface(gt_surface, options.samples, options.seed + 1);
  result.estimated_samples = static_cast<long>(estimated_samples.size());
  result.gt_samples = static_cast<long>(gt_samples.size());

  // The part of the GT surface the drive saw.
  if (!gt_world_from_rigs.empty() && options.visibility_rays > 0) {
    const std::vector<PixelSample> pixels =
        SamplePixels(rig, static_cast<int>(gt_world_from_rigs.size()), options.visibility_rays,
                     options.seed + 2);
    std::vector<Ray> rays;
    rays.reserve(pixels.size());
    for (const PixelSample& pixel : pixels) {
      Ray ray;
      if (PixelRay(rig.cameras[pixel.camera], gt_world_from_rigs[pixel.keyframe], pixel.pixel,
                   &ray)) {
        ray.max_distance = options.max_ray_length;
        rays.push_back(ray);
      }
    }
    const std::vector<RayHit> hits = gt_caster.CastMany(rays);
    std::unordered_set<uint64_t> seen_voxels;
    for (size_t i = 0; i < rays.size(); ++i) {
      if (!hits[i].Hit()) continue;
      seen_voxels.insert(VoxelKey(VoxelOf(rays[i].origin + hits[i].distance * rays[i].direction,
                                          options.visibility_voxel)));
    }
    auto seen = [&](const Eigen::Vector3d& point) {
      const Eigen::Vector3i voxel = VoxelOf(point, options.visibility_voxel);
      for (int dx = -1; dx <= 1; ++dx) {
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dz = -1; dz <= 1; ++dz) {
            if (seen_voxels.count(VoxelKey(voxel + Eigen::Vector3i(dx, dy, dz)))) return true;
          }
        }
      }
      return false;
    };
    gt_samples.erase(std::remove_if(gt_samples.begin(), gt_samples.end(),
                                    [&](const Eigen::Vector3d& p) { return !seen(p); }),
                     gt_samples.end());
  }
  result.gt_samples_seen = static_cast<long>(gt_samples.size());

  const std::vector<double> accuracy = SortedFinite(gt_caster.DistancesTo(estimated_samples));
  const std::vector<double> completeness = SortedFinite(estimated_caster.DistancesTo(gt_samples));
  result.accuracy = ComputeErrorStats(accuracy);
  result.completeness = ComputeErrorStats(completeness);
  for (double threshold : options.thresholds) {
    PrecisionRecall pr;
    pr.threshold = threshold;
    pr.precision = ShareBelow(accuracy, threshold);
    pr.recall = ShareBelow(completeness, threshold);
    pr.f_score = pr.precision + pr.recall > 0.0
                     ? 2.0 * pr.precision * pr.recall / (pr.precision + pr.recall)
                     : 0.0;
    result.precision_recall.push_back(pr);
  }
  return result;
}

PointDistanceResult PointDistances(const std::vector<Eigen::Vector3d>& points,
                                   const RayCaster& gt_caster) {
  PointDistanceResult result;
  result.points = static_cast<long>(points.size());
  const std::vector<double> distances = SortedFinite(gt_caster.DistancesTo(points));
  result.distances = ComputeErrorStats(distances);
  for (double q : result.quantile_levels)
    result.quantiles.push_back(QuantileOfSorted(distances, q));
  return result;
}

}  // namespace omni
