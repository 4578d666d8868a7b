#pragma once
// Local bundle adjustment of keyframe poses and points on bearings (docs/design.md §9): the
// newest keyframes free, older ones fixed (they fix the gauge), an angular residual on the
// tangent plane of each observed bearing, a robust loss in radians, a Schur-based solver, and
// the outlier observations removed afterwards. Central mode treats the rig as one camera at
// the mean of its camera centres (the paper's approximation); non-central mode uses the true
// cam_from_rig of the observing camera. Ceres stays inside the .cpp.

#include <Eigen/Core>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"

namespace omni {

struct BundleAdjustmentOptions {
  enum class Mode { kCentral, kNonCentral };
  enum class Loss { kTrivial, kHuber, kCauchy };
  enum class LinearSolver { kSparseSchur, kDenseSchur };

  Mode mode = Mode::kCentral;
  Loss loss = Loss::kCauchy;
  // Scale of the robust loss: angular residuals beyond it are down-weighted (radians; 0.004 rad
  // ≈ 2 pixels at f = 500 px).
  double loss_scale = 0.004;
  LinearSolver linear_solver = LinearSolver::kSparseSchur;
  int max_iterations = 50;
  double function_tolerance = 1e-8;
  int num_threads = 1;
  // After the solve, observations whose angular error exceeds this are removed (radians), and
  // the problem is solved again once if any was.
  double max_outlier_angle = 0.01;
  bool resolve_after_outlier_removal = true;
  // Non-central mode only: the camera offsets (cam_from_rig translations, metres) times one
  // scale estimated with the poses and points (from offset_scale; bounded to
  // [offset_scale / 100, offset_scale * 100]), for a map whose unit is not the metre: the true
  // offsets in a central-mode map.
  bool estimate_offset_scale = false;
  double offset_scale = 1.0;

  std::string Check() const;
};

struct BundleAdjustmentKeyframe {
  Rigid3d world_from_rig;
  bool fixed = false;  // fixed keyframes are not moved; they fix the gauge
};

struct BundleAdjustmentObservation {
  int keyframe = 0;  // index into BundleAdjustmentProblem::keyframes
  int camera = 0;    // index into Rig::cameras
  int point = 0;     // index into BundleAdjustmentProblem::points
  Eigen::Vector3d bearing = Eigen::Vector3d::UnitZ();  // unit, in the camera frame
};

struct BundleAdjustmentProblem {
  std::vector<BundleAdjustmentKeyframe> keyframes;
  std::vector<Eigen::Vector3d> points_in_world;
  // Optional, one per point: fixed points (e.g. of finalised keyframes, which must not move
  // again) are not moved. Empty: all points free.
  std::vector<char> point_fixed;
  std::vector<BundleAdjustmentObservation> observations;
};

struct BundleAdjustmentSummary {
  bool success = false;  // the solver ran and returned a usable solution
  int num_iterations = 0;
  double initial_cost = 0.0;
  double final_cost = 0.0;
  double rms_angle_before = 0.0;  // radians, over all observations given
  double rms_angle_after = 0.0;   // radians, over the observations kept
  double offset_scale = 1.0;      // the offsets' scale estimated (estimate_offset_scale)
  // Indices (into the observations given) of the observations removed as outliers.
  std::vector<int> removed_observations;
  std::string BriefReport() const;
};

// Angle between an observation's bearing and the direction to its point under the given
// keyframe pose, in the options' mode (radians; pi when the point is at the centre); offsets at
// scale 1.
double ObservationAngle(const Rig& rig, const BundleAdjustmentOptions::Mode mode,
                        const Rigid3d& world_from_rig, const Eigen::Vector3d& point_in_world,
                        int camera, const Eigen::Vector3d& bearing);

// Refines the free keyframes and the points in place and erases the outlier observations from
// problem->observations. Asserts valid options and indices.
BundleAdjustmentSummary LocalBundleAdjust(const Rig& rig, const BundleAdjustmentOptions& options,
                                          BundleAdjustmentProblem* problem);

}  // namespace omni
