#pragma once
// Pose evaluation against ground truth (paper §5.2): match estimated keyframe
// poses to ground-truth poses, register them with the similarity S minimising
// Σ‖S(c_i) − c_i^g‖² over the keyframe centres (Umeyama), then ATE, RPE and scale drift.

#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/tum.h"

namespace omni {

enum class PoseMatching {
  kTimestamp,   // equal timestamps within timestamp_tolerance
  kFrameIndex,  // the estimated timestamp rounded is an index into the ground-truth list
};

struct PoseEvalOptions {
  PoseMatching matching = PoseMatching::kTimestamp;
  // Largest timestamp difference of a match, seconds (frames of a 15 Hz drive are 66 ms apart).
  double timestamp_tolerance = 1e-4;
  // The keyframe centre in the rig frame (paper §5.2: the mean of the camera centres); the
  // rig origin by default.
  Eigen::Vector3d center_in_rig = Eigen::Vector3d::Zero();
  // RPE segment lengths, in ground-truth distance travelled (metres).
  std::vector<double> rpe_segment_lengths = {10.0, 100.0};
  // Length of the consecutive segments over which the local scale is measured (metres).
  double scale_segment_length = 20.0;

  std::string Check() const;
};

struct MatchedPose {
  double timestamp = 0.0;
  Rigid3d estimated_world_from_rig;   // as read
  Rigid3d registered_world_from_rig;  // TransformPose(S, estimated)
  Rigid3d gt_world_from_rig;
  double gt_distance = 0.0;  // ground-truth distance travelled from the first match
};

struct ErrorStats {
  long count = 0;
  double rmse = 0.0, mean = 0.0, median = 0.0, max = 0.0;
};

struct RpeResult {
  double segment_length = 0.0;       // metres of ground-truth travel
  long pairs = 0;                    // 0 when the drive is shorter
  double translation_percent = 0.0;  // mean ‖t error‖ / segment length × 100
  double rotation_deg_per_100m = 0.0;
};

struct ScaleSegment {
  double gt_distance_start = 0.0;  // along the drive
  double gt_length = 0.0;
  double relative_scale = 1.0;  // local scale gt length / estimated length, divided by S.scale
};

struct PoseEvalResult {
  long estimated_poses = 0;
  long gt_poses = 0;
  std::vector<MatchedPose> matches;
  Sim3d gt_from_estimated;        // S
  double registration_rms = 0.0;  // sqrt(E(S) / n), paper §5.2
  ErrorStats ate_translation;     // metres, after S
  ErrorStats ate_rotation_deg;
  double gt_length = 0.0;  // metres travelled by the matched ground truth
  std::vector<RpeResult> rpe;
  std::vector<ScaleSegment> scale_drift;
  double scale_drift_min = 1.0, scale_drift_max = 1.0;
};

// Throws InputError when fewer than three poses match (e.g. no common timestamps).
PoseEvalResult EvaluatePoses(const std::vector<StampedPose>& estimated,
                             const std::vector<StampedPose>& ground_truth,
                             const PoseEvalOptions& options = {});

// Quantile of a sorted sample (linear interpolation between order statistics), q in [0, 1];
// NaN when empty.
double QuantileOfSorted(const std::vector<double>& sorted, double q);
ErrorStats ComputeErrorStats(std::vector<double> values);

}  // namespace omni
