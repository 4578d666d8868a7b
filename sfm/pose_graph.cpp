#include "sfm/pose_graph.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <cassert>
#include <cmath>
#include <sstream>

#include "calib/error.h"

namespace omni {

std::string PoseGraphOptions::Check() const {
  if (max_iterations < 1) return "max_iterations: expected at least 1";
  if (!(function_tolerance > 0.0)) return "function_tolerance: expected a positive number";
  if (!(translation_weight > 0.0) || !(rotation_weight > 0.0) || !(scale_weight > 0.0))
    return "translation_weight, rotation_weight, scale_weight: expected positive numbers";
  return {};
}

std::string PoseGraphSummary::BriefReport() const {
  std::ostringstream o;
  o << (success ? "converged" : "failed") << ", " << num_iterations << " iterations, cost "
    << initial_cost << " -> " << final_cost;
  return o.str();
}

Sim3d RelativeSim3(const Sim3d& world_from_from, const Sim3d& world_from_to) {
  return world_from_from.Inverse() * world_from_to;
}

namespace {

// Residual of one edge i -> j with measurement M = (s_m, R_m, t_m) ≈ S_i^-1 S_j, nodes stored
// as (unit quaternion x y z w, translation, log scale):
//   S_i^-1 S_j = (s_j / s_i, R_i^T R_j, R_i^T (t_j − t_i) / s_i) =: (s, R, t)
//   E = M^-1 (S_i^-1 S_j) = (s / s_m, R_m^T R, R_m^T (t − t_m) / s_m)
//   r = [w_t · t_E, w_r · 2 vec(q_E), w_s · log s_E] · weight        (7 residuals)
struct Sim3EdgeCost {
  Sim3EdgeCost(const Sim3d& measured, double wt, double wr, double ws)
      : q_m(measured.rotation.normalized()),
        t_m(measured.translation),
        log_s_m(std::log(measured.scale)),
        wt(wt),
        wr(wr),
        ws(ws) {}

  template <typename T>
  bool operator()(const T* qi_, const T* ti_, const T* li_, const T* qj_, const T* tj_,
                  const T* lj_, T* r) const {
    const Eigen::Map<const Eigen::Quaternion<T>> qi(qi_), qj(qj_);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> ti(ti_), tj(tj_);
    const T inv_si = ceres::exp(-li_[0]);
    const Eigen::Quaternion<T> q = qi.conjugate() * qj;
    const Eigen::Matrix<T, 3, 1> t = (qi.conjugate() * (tj - ti)) * inv_si;
    const Eigen::Quaternion<T> q_mt = q_m.cast<T>();
    const Eigen::Quaternion<T> q_e = q_mt.conjugate() * q;
    const Eigen::Matrix<T, 3, 1> t_e =
        (q_mt.conjugate() * (t - t_m.cast<T>())) * T(std::exp(-log_s_m));
    const T sign = q_e.w() < T(0) ? T(-1) : T(1);
    for (int k = 0; k < 3; ++k) {
      r[k] = T(wt) * t_e[k];
      r[3 + k] = T(wr) * T(2) * sign * q_e.vec()[k];
    }
    r[6] = T(ws) * (lj_[0] - li_[0] - T(log_s_m));
    return true;
  }

  static ceres::CostFunction* Create(const Sim3d& measured, double wt, double wr, double ws) {
    return new ceres::AutoDiffCostFunction<Sim3EdgeCost, 7, 4, 3, 1, 4, 3, 1>(
        new Sim3EdgeCost(measured, wt, wr, ws));
  }

  Eigen::Quaterniond q_m;
  Eigen::Vector3d t_m;
  double log_s_m, wt, wr, ws;
};

}  // namespace

PoseGraphSummary OptimizePoseGraph(const std::vector<PoseGraphEdge>& edges,
                                   const std::vector<int>& fixed, const PoseGraphOptions& options,
                                   std::vector<Sim3d>* world_from_node) {
  ThrowIfInvalid(options.Check(), "PoseGraphOptions");
  assert(!fixed.empty());
  const size_t n = world_from_node->size();
  std::vector<Eigen::Quaterniond> q(n);
  std::vector<Eigen::Vector3d> t(n);
  std::vector<double> log_s(n);
  for (size_t i = 0; i < n; ++i) {
    q[i] = (*world_from_node)[i].rotation.normalized();
    t[i] = (*world_from_node)[i].translation;
    log_s[i] = std::log((*world_from_node)[i].scale);
  }
  ceres::Problem problem;
  for (const PoseGraphEdge& edge : edges) {
    assert(edge.from >= 0 && edge.to >= 0 && static_cast<size_t>(edge.from) < n &&
           static_cast<size_t>(edge.to) < n && edge.from != edge.to);
    problem.AddResidualBlock(
        Sim3EdgeCost::Create(edge.from_from_to, edge.weight * options.translation_weight,
                             edge.weight * options.rotation_weight,
                             edge.weight * options.scale_weight),
        nullptr, q[edge.from].coeffs().data(), t[edge.from].data(), &log_s[edge.from],
        q[edge.to].coeffs().data(), t[edge.to].data(), &log_s[edge.to]);
  }
  for (size_t i = 0; i < n; ++i)
    if (problem.HasParameterBlock(q[i].coeffs().data()))
      problem.SetManifold(q[i].coeffs().data(), new ceres::EigenQuaternionManifold);
  for (int i : fixed) {
    assert(i >= 0 && static_cast<size_t>(i) < n);
    if (!problem.HasParameterBlock(q[i].coeffs().data())) continue;
    problem.SetParameterBlockConstant(q[i].coeffs().data());
    problem.SetParameterBlockConstant(t[i].data());
    problem.SetParameterBlockConstant(&log_s[i]);
  }
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  solver.max_num_iterations = options.max_iterations;
  solver.function_tolerance = options.function_tolerance;
  solver.gradient_tolerance = 1e-14;
  solver.parameter_tolerance = 1e-12;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  PoseGraphSummary result;
  result.success = summary.IsSolutionUsable();
  result.num_iterations = static_cast<int>(summary.iterations.size());
  result.initial_cost = summary.initial_cost;
  result.final_cost = summary.final_cost;
  if (!result.success) return result;
  for (size_t i = 0; i < n; ++i)
    (*world_from_node)[i] = Sim3d(std::exp(log_s[i]), q[i].normalized(), t[i]);
  return result;
}

}  // namespace omni
