#include "sfm/bundle_adjustment.h"

#include <ceres/ceres.h>

#include <cassert>
#include <cmath>
#include <memory>
#include <sstream>
#include <type_traits>

#include "calib/error.h"
#include "sfm/internal/angular_residual.h"

namespace omni {
namespace {

// The frame an observation's bearing is expressed in, and its pose in the rig frame:
// non-central mode, the observing camera (frame_from_rig = cam_from_rig); central mode, the
// rig's single central camera (rig axes, origin at the mean camera centre c0:
// frame_from_rig = (I, -c0)), the bearing being rotated from the camera to the rig axes.
struct ObservationFrame {
  Eigen::Matrix3d frame_from_rig_rotation;
  Eigen::Vector3d frame_from_rig_translation;
  Eigen::Vector3d bearing;  // unit, in that frame
};

Eigen::Vector3d CentralCenter(const Rig& rig) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Camera& camera : rig.cameras) sum += camera.cam_from_rig.Center();
  return sum / static_cast<double>(rig.cameras.size());
}

ObservationFrame MakeObservationFrame(const Rig& rig, BundleAdjustmentOptions::Mode mode,
                                      const Eigen::Vector3d& central_center, int camera,
                                      const Eigen::Vector3d& bearing, double offset_scale = 1.0) {
  const Rigid3d& cam_from_rig = rig.cameras[camera].cam_from_rig;
  ObservationFrame frame;
  if (mode == BundleAdjustmentOptions::Mode::kNonCentral) {
    frame.frame_from_rig_rotation = cam_from_rig.rotation.toRotationMatrix();
    frame.frame_from_rig_translation = offset_scale * cam_from_rig.translation;
    frame.bearing = bearing.normalized();
  } else {
    frame.frame_from_rig_rotation.setIdentity();
    frame.frame_from_rig_translation = -central_center;
    frame.bearing = (cam_from_rig.rotation.conjugate() * bearing).normalized();
  }
  return frame;
}

// The angular residual of one observation (internal::AngularResidualModel) as a Ceres cost:
// parameters world_from_rig rotation (Eigen quaternion x y z w), world_from_rig translation,
// point in the world, and with kScaledOffset the offsets' scale s (x_frame = A x_rig + s c;
// otherwise s = 1). Jacobians in closed form: the automatic ones cost several times more.
template <bool kScaledOffset>
class AngularResidualCost
    : public std::conditional_t<kScaledOffset, ceres::SizedCostFunction<2, 4, 3, 3, 1>,
                                ceres::SizedCostFunction<2, 4, 3, 3>> {
 public:
  // Default-constructed in one array per solve (no allocation per observation), then Set.
  AngularResidualCost() = default;
  void Set(const ObservationFrame& frame) {
    model_ = internal::AngularResidualModel(frame.frame_from_rig_rotation,
                                            frame.frame_from_rig_translation, frame.bearing);
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const auto jacobian = [jacobians](int block) {
      return jacobians != nullptr ? jacobians[block] : nullptr;
    };
    model_.Evaluate(parameters[0], parameters[1], parameters[2],
                    kScaledOffset ? parameters[3][0] : 1.0, residuals, jacobian(0), jacobian(1),
                    jacobian(2), kScaledOffset ? jacobian(3) : nullptr);
    return true;
  }

 private:
  internal::AngularResidualModel model_;
};
using AngularResidual = AngularResidualCost<false>;
using ScaledOffsetAngularResidual = AngularResidualCost<true>;

bool EstimatesOffsetScale(const BundleAdjustmentOptions& options) {
  return options.estimate_offset_scale &&
         options.mode == BundleAdjustmentOptions::Mode::kNonCentral;
}

ceres::LossFunction* MakeLoss(const BundleAdjustmentOptions& options) {
  switch (options.loss) {
    case BundleAdjustmentOptions::Loss::kTrivial:
      return nullptr;
    case BundleAdjustmentOptions::Loss::kHuber:
      return new ceres::HuberLoss(options.loss_scale);
    case BundleAdjustmentOptions::Loss::kCauchy:
      return new ceres::CauchyLoss(options.loss_scale);
  }
  return nullptr;
}

double AngleOf(const ObservationFrame& frame, const Rigid3d& world_from_rig,
               const Eigen::Vector3d& point_in_world) {
  const Eigen::Vector3d x_rig =
      world_from_rig.rotation.conjugate() * (point_in_world - world_from_rig.translation);
  const Eigen::Vector3d x_frame =
      frame.frame_from_rig_rotation * x_rig + frame.frame_from_rig_translation;
  if (x_frame.norm() == 0.0) return M_PI;
  return std::atan2(x_frame.cross(frame.bearing).norm(), x_frame.dot(frame.bearing));
}

double RmsAngle(const Rig& rig, const BundleAdjustmentOptions& options,
                const BundleAdjustmentProblem& problem, double offset_scale) {
  if (problem.observations.empty()) return 0.0;
  const Eigen::Vector3d center = CentralCenter(rig);
  double sum = 0.0;
  for (const BundleAdjustmentObservation& observation : problem.observations) {
    const ObservationFrame frame = MakeObservationFrame(
        rig, options.mode, center, observation.camera, observation.bearing, offset_scale);
    const double angle = AngleOf(frame, problem.keyframes[observation.keyframe].world_from_rig,
                                 problem.points_in_world[observation.point]);
    sum += angle * angle;
  }
  return std::sqrt(sum / problem.observations.size());
}

// A keyframe's parameters: its rotation (Eigen quaternion x y z w), then its translation.
constexpr size_t kRotationParameters = 4;
constexpr size_t kPoseParameters = kRotationParameters + 3;

// One Ceres solve over the current observations. Returns false when Ceres reports no usable
// solution.
bool Solve(const Rig& rig, const BundleAdjustmentOptions& options, BundleAdjustmentProblem* problem,
           BundleAdjustmentSummary* summary) {
  // Ceres parameter blocks: quaternion (x y z w) and translation per keyframe; points in place.
  // Ceres orders the blocks of one elimination group by their addresses, and that order sets
  // the order of the sums of its linear algebra: the keyframes' blocks and the offset scale
  // live in one array, in keyframe order, and the points in theirs, so that the solution does
  // not depend, to the last bit, on where the allocator put them.
  const size_t num_keyframes = problem->keyframes.size();
  std::vector<double> camera_parameters(kPoseParameters * num_keyframes + 1);
  const auto rotation_of = [&](size_t i) { return &camera_parameters[kPoseParameters * i]; };
  const auto translation_of = [&](size_t i) {
    return &camera_parameters[kPoseParameters * i + kRotationParameters];
  };
  for (size_t i = 0; i < num_keyframes; ++i) {
    Eigen::Map<Eigen::Vector4d>(rotation_of(i)) =
        problem->keyframes[i].world_from_rig.rotation.normalized().coeffs();
    Eigen::Map<Eigen::Vector3d>(translation_of(i)) =
        problem->keyframes[i].world_from_rig.translation;
  }

  // One robust loss for every residual (declared before the problem, which uses it to the end).
  const std::unique_ptr<ceres::LossFunction> loss(MakeLoss(options));
  // The residuals' costs, in one array each, also outlive the problem.
  const bool scaled = EstimatesOffsetScale(options);
  std::vector<AngularResidual> costs(scaled ? 0 : problem->observations.size());
  std::vector<ScaledOffsetAngularResidual> scaled_costs(scaled ? problem->observations.size() : 0);
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem ceres_problem(problem_options);
  const Eigen::Vector3d center = CentralCenter(rig);
  std::vector<char> keyframe_used(problem->keyframes.size(), 0);
  std::vector<char> point_used(problem->points_in_world.size(), 0);
  double* offset_scale = &camera_parameters[kPoseParameters * num_keyframes];
  *offset_scale = summary->offset_scale;
  for (size_t i = 0; i < problem->observations.size(); ++i) {
    const BundleAdjustmentObservation& observation = problem->observations[i];
    const ObservationFrame frame =
        MakeObservationFrame(rig, options.mode, center, observation.camera, observation.bearing);
    if (scaled) {
      scaled_costs[i].Set(frame);
      ceres_problem.AddResidualBlock(
          &scaled_costs[i], loss.get(), rotation_of(observation.keyframe),
          translation_of(observation.keyframe), problem->points_in_world[observation.point].data(),
          offset_scale);
    } else {
      costs[i].Set(frame);
      ceres_problem.AddResidualBlock(&costs[i], loss.get(), rotation_of(observation.keyframe),
                                     translation_of(observation.keyframe),
                                     problem->points_in_world[observation.point].data());
    }
    keyframe_used[observation.keyframe] = 1;
    point_used[observation.point] = 1;
  }
  if (ceres_problem.NumResidualBlocks() == 0) return false;

  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  if (scaled) {
    ceres_problem.SetParameterLowerBound(offset_scale, 0, options.offset_scale / 100.0);
    ceres_problem.SetParameterUpperBound(offset_scale, 0, options.offset_scale * 100.0);
    ordering->AddElementToGroup(offset_scale, 1);
  }
  for (size_t i = 0; i < num_keyframes; ++i) {
    if (!keyframe_used[i]) continue;
    ceres_problem.SetManifold(rotation_of(i), new ceres::EigenQuaternionManifold);
    if (problem->keyframes[i].fixed) {
      ceres_problem.SetParameterBlockConstant(rotation_of(i));
      ceres_problem.SetParameterBlockConstant(translation_of(i));
    }
    ordering->AddElementToGroup(rotation_of(i), 1);
    ordering->AddElementToGroup(translation_of(i), 1);
  }
  for (size_t i = 0; i < problem->points_in_world.size(); ++i) {
    if (!point_used[i]) continue;
    ordering->AddElementToGroup(problem->points_in_world[i].data(), 0);
    if (!problem->point_fixed.empty() && problem->point_fixed[i])
      ceres_problem.SetParameterBlockConstant(problem->points_in_world[i].data());
  }

  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type =
      options.linear_solver == BundleAdjustmentOptions::LinearSolver::kDenseSchur
          ? ceres::DENSE_SCHUR
          : ceres::SPARSE_SCHUR;
  solver_options.linear_solver_ordering = ordering;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.num_threads = options.num_threads;
  solver_options.logging_type = ceres::SILENT;
  solver_options.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary ceres_summary;
  ceres::Solve(solver_options, &ceres_problem, &ceres_summary);

  summary->num_iterations += static_cast<int>(ceres_summary.iterations.size());
  if (summary->initial_cost == 0.0) summary->initial_cost = ceres_summary.initial_cost;
  summary->final_cost = ceres_summary.final_cost;
  if (!ceres_summary.IsSolutionUsable()) return false;
  if (scaled) summary->offset_scale = *offset_scale;
  for (size_t i = 0; i < num_keyframes; ++i) {
    if (problem->keyframes[i].fixed || !keyframe_used[i]) continue;
    problem->keyframes[i].world_from_rig =
        Rigid3d(Eigen::Quaterniond(rotation_of(i)).normalized(),
                Eigen::Map<const Eigen::Vector3d>(translation_of(i)));
  }
  return true;
}

}  // namespace

std::string BundleAdjustmentOptions::Check() const {
  if (!(loss_scale > 0.0)) return "loss_scale: expected a positive angle (radians)";
  if (max_iterations < 1) return "max_iterations: expected at least 1";
  if (!(function_tolerance > 0.0)) return "function_tolerance: expected a positive value";
  if (num_threads < 1) return "num_threads: expected at least 1";
  if (!(max_outlier_angle > 0.0)) return "max_outlier_angle: expected a positive angle (radians)";
  if (!(offset_scale > 0.0) || !std::isfinite(offset_scale))
    return "offset_scale: expected a positive finite scale";
  return {};
}

std::string BundleAdjustmentSummary::BriefReport() const {
  std::ostringstream out;
  out << "bundle adjustment: " << (success ? "ok" : "failed") << ", " << num_iterations
      << " iterations, cost " << initial_cost << " -> " << final_cost << ", rms angle "
      << rms_angle_before << " -> " << rms_angle_after << " rad, " << removed_observations.size()
      << " outliers removed";
  if (offset_scale != 1.0) out << ", offset scale " << offset_scale;
  return out.str();
}

double ObservationAngle(const Rig& rig, const BundleAdjustmentOptions::Mode mode,
                        const Rigid3d& world_from_rig, const Eigen::Vector3d& point_in_world,
                        int camera, const Eigen::Vector3d& bearing) {
  const ObservationFrame frame =
      MakeObservationFrame(rig, mode, CentralCenter(rig), camera, bearing);
  return AngleOf(frame, world_from_rig, point_in_world);
}

BundleAdjustmentSummary LocalBundleAdjust(const Rig& rig, const BundleAdjustmentOptions& options,
                                          BundleAdjustmentProblem* problem) {
  ThrowIfInvalid(options.Check(), "BundleAdjustmentOptions");
  assert(!rig.cameras.empty());
  assert(problem->point_fixed.empty() ||
         problem->point_fixed.size() == problem->points_in_world.size());
  for ([[maybe_unused]] const BundleAdjustmentObservation& observation : problem->observations) {
    assert(observation.keyframe >= 0 &&
           observation.keyframe < static_cast<int>(problem->keyframes.size()));
    assert(observation.camera >= 0 && observation.camera < static_cast<int>(rig.NumCameras()));
    assert(observation.point >= 0 &&
           observation.point < static_cast<int>(problem->points_in_world.size()));
  }
  BundleAdjustmentSummary summary;
  summary.offset_scale = EstimatesOffsetScale(options) ? options.offset_scale : 1.0;
  if (EstimatesOffsetScale(options)) {
    // The solve starts from the scale that fits the current poses and points best among 33
    // spaced by factors of 1.33 over the bounds (the cost is not convex in it far away).
    double best = RmsAngle(rig, options, *problem, summary.offset_scale);
    for (int i = -16; i <= 16; ++i) {
      const double scale = options.offset_scale * std::pow(100.0, i / 16.0);
      const double rms = RmsAngle(rig, options, *problem, scale);
      if (rms < best) {
        best = rms;
        summary.offset_scale = scale;
      }
    }
  }
  summary.rms_angle_before = RmsAngle(rig, options, *problem, summary.offset_scale);
  if (!Solve(rig, options, problem, &summary)) return summary;

  // Remove the outliers, keeping the original indices of the removed ones.
  const Eigen::Vector3d center = CentralCenter(rig);
  std::vector<BundleAdjustmentObservation> kept;
  kept.reserve(problem->observations.size());
  for (size_t i = 0; i < problem->observations.size(); ++i) {
    const BundleAdjustmentObservation& observation = problem->observations[i];
    const ObservationFrame frame = MakeObservationFrame(
        rig, options.mode, center, observation.camera, observation.bearing, summary.offset_scale);
    const double angle = AngleOf(frame, problem->keyframes[observation.keyframe].world_from_rig,
                                 problem->points_in_world[observation.point]);
    if (angle > options.max_outlier_angle)
      summary.removed_observations.push_back(static_cast<int>(i));
    else
      kept.push_back(observation);
  }
  problem->observations = std::move(kept);
  if (!summary.removed_observations.empty() && options.resolve_after_outlier_removal &&
      !problem->observations.empty()) {
    if (!Solve(rig, options, problem, &summary)) return summary;
  }
  summary.rms_angle_after = RmsAngle(rig, options, *problem, summary.offset_scale);
  summary.success = true;
  return summary;
}

namespace internal {

AngularResidualModel::AngularResidualModel(const Eigen::Matrix3d& frame_from_rig_rotation,
                                           const Eigen::Vector3d& frame_from_rig_translation,
                                           const Eigen::Vector3d& bearing)
    : frame_from_rig_rotation_(frame_from_rig_rotation),
      frame_from_rig_translation_(frame_from_rig_translation),
      bearing_(bearing) {
  tangent_u_ = bearing_.unitOrthogonal();
  tangent_v_ = bearing_.cross(tangent_u_);
}

void AngularResidualModel::Evaluate(const double* world_from_rig_q, const double* world_from_rig_t,
                                    const double* point, double offset_scale, double* residual,
                                    double* jacobian_q, double* jacobian_t, double* jacobian_point,
                                    double* jacobian_scale) const {
  using RowMajor23 = Eigen::Matrix<double, 2, 3, Eigen::RowMajor>;
  const Eigen::Map<const Eigen::Vector3d> v(world_from_rig_q);  // q's vector part
  const double w = world_from_rig_q[3];
  const Eigen::Vector3d y = Eigen::Map<const Eigen::Vector3d>(point) -
                            Eigen::Map<const Eigen::Vector3d>(world_from_rig_t);
  // conj(q) y as Eigen computes it (vector part −v): y − 2w (v × y) + 2 v × (v × y).
  const Eigen::Vector3d v_cross_y = v.cross(y);
  const Eigen::Vector3d x_rig = y - 2.0 * w * v_cross_y + 2.0 * v.cross(v_cross_y);
  const Eigen::Vector3d x_frame =
      frame_from_rig_rotation_ * x_rig + offset_scale * frame_from_rig_translation_;
  const double norm = x_frame.norm();
  const Eigen::Vector3d p = x_frame / norm;
  const double denominator = 1.0 + bearing_.dot(p);
  const double up = tangent_u_.dot(p), vp = tangent_v_.dot(p);
  residual[0] = 2.0 * up / denominator;
  residual[1] = 2.0 * vp / denominator;
  if (jacobian_q == nullptr && jacobian_t == nullptr && jacobian_point == nullptr &&
      jacobian_scale == nullptr)
    return;
  // d r / d x_frame = d r / d p · (I − p pᵀ) / ‖x_frame‖.
  RowMajor23 dr_dp;
  const double inverse_squared = 1.0 / (denominator * denominator);
  dr_dp.row(0) = (2.0 / denominator) * tangent_u_.transpose() -
                 (2.0 * up * inverse_squared) * bearing_.transpose();
  dr_dp.row(1) = (2.0 / denominator) * tangent_v_.transpose() -
                 (2.0 * vp * inverse_squared) * bearing_.transpose();
  const RowMajor23 dr_dframe = (dr_dp - (dr_dp * p) * p.transpose()) / norm;
  if (jacobian_scale != nullptr) {
    Eigen::Map<Eigen::Vector2d> js(jacobian_scale);
    js = dr_dframe * frame_from_rig_translation_;
  }
  const RowMajor23 dr_drig = dr_dframe * frame_from_rig_rotation_;
  if (jacobian_point != nullptr || jacobian_t != nullptr) {
    // d x_rig / d y = I − 2w [v]× + 2 [v]×², the matrix of the formula (conj(q)'s rotation for
    // a unit q).
    Eigen::Matrix3d v_hat;
    v_hat << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
    const Eigen::Matrix3d dx_dy =
        Eigen::Matrix3d::Identity() - 2.0 * w * v_hat + 2.0 * v_hat * v_hat;
    const RowMajor23 dr_dy = dr_drig * dx_dy;
    if (jacobian_point != nullptr) {
      Eigen::Map<RowMajor23> jx(jacobian_point);
      jx = dr_dy;
    }
    if (jacobian_t != nullptr) {
      Eigen::Map<RowMajor23> jt(jacobian_t);
      jt = -dr_dy;
    }
  }
  if (jacobian_q != nullptr) {
    // d x_rig / d v = 2w [y]× + 2 ((v·y) I + v yᵀ − 2 y vᵀ), d x_rig / d w = −2 (v × y).
    Eigen::Matrix3d y_hat;
    y_hat << 0.0, -y.z(), y.y(), y.z(), 0.0, -y.x(), -y.y(), y.x(), 0.0;
    const Eigen::Matrix3d dx_dv =
        2.0 * w * y_hat + 2.0 * (v.dot(y) * Eigen::Matrix3d::Identity() + v * y.transpose() -
                                 2.0 * y * v.transpose());
    Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>> jq(jacobian_q);
    jq.leftCols<3>() = dr_drig * dx_dv;
    jq.col(3) = dr_drig * (-2.0 * v_cross_y);
  }
}

}  // namespace internal

}  // namespace omni
