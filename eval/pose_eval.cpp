#include "eval/pose_eval.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <sstream>

#include "calib/error.h"

namespace omni {
namespace {

double AngleDeg(const Eigen::Quaterniond& rotation) {
  return Eigen::AngleAxisd(rotation.normalized()).angle() * 180.0 / M_PI;
}

}  // namespace

std::string PoseEvalOptions::Check() const {
  if (!(timestamp_tolerance >= 0.0)) return "timestamp_tolerance: must be >= 0";
  for (double length : rpe_segment_lengths) {
    if (!(length > 0.0)) return "rpe_segment_lengths: must be > 0";
  }
  if (!(scale_segment_length > 0.0)) return "scale_segment_length: must be > 0";
  return {};
}

double QuantileOfSorted(const std::vector<double>& sorted, double q) {
  if (sorted.empty()) return std::numeric_limits<double>::quiet_NaN();
  const double position = std::clamp(q, 0.0, 1.0) * static_cast<double>(sorted.size() - 1);
  const size_t below = static_cast<size_t>(std::floor(position));
  const size_t above = std::min(below + 1, sorted.size() - 1);
  const double fraction = position - static_cast<double>(below);
  return sorted[below] + fraction * (sorted[above] - sorted[below]);
}

ErrorStats ComputeErrorStats(std::vector<double> values) {
  ErrorStats stats;
  stats.count = static_cast<long>(values.size());
  if (values.empty()) return stats;
  std::sort(values.begin(), values.end());
  double sum = 0.0, sum_squares = 0.0;
  for (double v : values) {
    sum += v;
    sum_squares += v * v;
  }
  stats.mean = sum / values.size();
  stats.rmse = std::sqrt(sum_squares / values.size());
  stats.median = QuantileOfSorted(values, 0.5);
  stats.max = values.back();
  return stats;
}

PoseEvalResult EvaluatePoses(const std::vector<StampedPose>& estimated,
                             const std::vector<StampedPose>& ground_truth,
                             const PoseEvalOptions& options) {
  if (const std::string problem = options.Check(); !problem.empty()) {
    throw InputError("", "pose evaluation options", problem);
  }
  PoseEvalResult result;
  result.estimated_poses = static_cast<long>(estimated.size());
  result.gt_poses = static_cast<long>(ground_truth.size());

  std::vector<StampedPose> gt = ground_truth;
  std::stable_sort(gt.begin(), gt.end(), [](const StampedPose& a, const StampedPose& b) {
    return a.timestamp < b.timestamp;
  });
  std::vector<std::pair<size_t, size_t>> pairs;  // (gt index, estimated index)
  for (size_t e = 0; e < estimated.size(); ++e) {
    const double t = estimated[e].timestamp;
    if (options.matching == PoseMatching::kFrameIndex) {
      const long index = std::lround(t);
      if (std::abs(t - index) <= options.timestamp_tolerance && index >= 0 &&
          index < static_cast<long>(gt.size())) {
        pairs.emplace_back(index, e);
      }
      continue;
    }
    auto it = std::lower_bound(gt.begin(), gt.end(), t,
                               [](const StampedPose& p, double x) { return p.timestamp < x; });
    size_t best = gt.size();
    double best_gap = std::numeric_limits<double>::infinity();
    for (auto candidate : {it, it == gt.begin() ? it : it - 1}) {
      if (candidate == gt.end()) continue;
      const double gap = std::abs(candidate->timestamp - t);
      if (gap < best_gap) {
        best_gap = gap;
        best = static_cast<size_t>(candidate - gt.begin());
      }
    }
    if (best < gt.size() && best_gap <= options.timestamp_tolerance) pairs.emplace_back(best, e);
  }
  std::sort(pairs.begin(), pairs.end());
  if (pairs.size() < 3) {
    std::ostringstream problem;
    problem << "only " << pairs.size() << " of " << estimated.size()
            << " estimated poses match a ground-truth pose ("
            << (options.matching == PoseMatching::kTimestamp ? "timestamps within "
                                                             : "frame indices within ")
            << options.timestamp_tolerance << " of " << gt.size()
            << " ground-truth poses); at least 3 are needed";
    throw InputError("", "timestamps", problem.str());
  }

  std::vector<Eigen::Vector3d> estimated_centers, gt_centers;
  for (const auto& [g, e] : pairs) {
    estimated_centers.push_back(estimated[e].world_from_rig * options.center_in_rig);
    gt_centers.push_back(gt[g].world_from_rig * options.center_in_rig);
  }
  result.gt_from_estimated = EstimateSim3Umeyama(estimated_centers, gt_centers);
  const Sim3d& gt_from_estimated = result.gt_from_estimated;
  if (!std::isfinite(gt_from_estimated.scale) || !(gt_from_estimated.scale > 0.0)) {
    throw InputError("", "poses",
                     "the keyframe centres are degenerate (collinear or equal): "
                     "no similarity registers them");
  }
  result.registration_rms = AlignmentRms(gt_from_estimated, estimated_centers, gt_centers);

  const size_t n = pairs.size();
  std::vector<double> translation_errors, rotation_errors;
  double distance = 0.0;
  for (size_t i = 0; i < n; ++i) {
    const auto [g, e] = pairs[i];
    MatchedPose match;
    match.timestamp = gt[g].timestamp;
    match.estimated_world_from_rig = estimated[e].world_from_rig;
    match.registered_world_from_rig = TransformPose(gt_from_estimated, estimated[e].world_from_rig);
    match.gt_world_from_rig = gt[g].world_from_rig;
    if (i > 0) distance += (gt_centers[i] - gt_centers[i - 1]).norm();
    match.gt_distance = distance;
    translation_errors.push_back((gt_from_estimated * estimated_centers[i] - gt_centers[i]).norm());
    rotation_errors.push_back(AngleDeg(match.gt_world_from_rig.rotation.conjugate() *
                                       match.registered_world_from_rig.rotation));
    result.matches.push_back(match);
  }
  result.gt_length = distance;
  result.ate_translation = ComputeErrorStats(translation_errors);
  result.ate_rotation_deg = ComputeErrorStats(rotation_errors);

  // RPE over segments of ground-truth travel (KITTI style).
  const auto& matches = result.matches;
  for (double length : options.rpe_segment_lengths) {
    RpeResult rpe;
    rpe.segment_length = length;
    double translation_sum = 0.0, rotation_sum = 0.0;
    size_t j = 0;
    for (size_t i = 0; i < n; ++i) {
      j = std::max(j, i + 1);
      while (j < n && matches[j].gt_distance - matches[i].gt_distance < length) ++j;
      if (j >= n) break;
      const double travelled = matches[j].gt_distance - matches[i].gt_distance;
      const Rigid3d gt_j_from_i_inv =
          matches[i].gt_world_from_rig.Inverse() * matches[j].gt_world_from_rig;
      const Rigid3d est_j_from_i_inv =
          matches[i].registered_world_from_rig.Inverse() * matches[j].registered_world_from_rig;
      const Rigid3d error = gt_j_from_i_inv.Inverse() * est_j_from_i_inv;
      translation_sum += error.translation.norm() / travelled * 100.0;
      rotation_sum += AngleDeg(error.rotation) / travelled * 100.0;
      ++rpe.pairs;
    }
    if (rpe.pairs > 0) {
      rpe.translation_percent = translation_sum / rpe.pairs;
      rpe.rotation_deg_per_100m = rotation_sum / rpe.pairs;
    } else {
      rpe.translation_percent = rpe.rotation_deg_per_100m =
          std::numeric_limits<double>::quiet_NaN();
    }
    result.rpe.push_back(rpe);
  }

  // Scale drift: the local scale of consecutive segments relative to S's.
  for (size_t i = 0; i + 1 < n;) {
    size_t j = i + 1;
    double estimated_length = (estimated_centers[j] - estimated_centers[j - 1]).norm();
    while (j + 1 < n &&
           matches[j].gt_distance - matches[i].gt_distance < options.scale_segment_length) {
      ++j;
      estimated_length += (estimated_centers[j] - estimated_centers[j - 1]).norm();
    }
    const double gt_length = matches[j].gt_distance - matches[i].gt_distance;
    if (gt_length < 0.5 * options.scale_segment_length) break;  // a short tail says little
    if (estimated_length > 0.0) {
      ScaleSegment segment;
      segment.gt_distance_start = matches[i].gt_distance;
      segment.gt_length = gt_length;
      segment.relative_scale = gt_length / estimated_length / gt_from_estimated.scale;
      result.scale_drift.push_back(segment);
    }
    i = j;
  }
  if (!result.scale_drift.empty()) {
    result.scale_drift_min = result.scale_drift_max = result.scale_drift[0].relative_scale;
    for (const auto& segment : result.scale_drift) {
      result.scale_drift_min = std::min(result.scale_drift_min, segment.relative_scale);
      result.scale_drift_max = std::max(result.scale_drift_max, segment.relative_scale);
    }
  }
  return result;
}

}  // namespace omni
