#pragma once
// Internal to sfm/ (not a public header): the RANSAC of the resection (absolute pose, central
// P3P or non-central GP3P through OpenGV's AbsolutePoseSacProblem), the estimate of OpenGV's
// opengv::sac::Ransac run by RunOpengvRansac (sfm/opengv_ransac.h), only cheaper:
//  - the hypotheses are drawn in order from the problem's seeded generator, solved and scored
//    in small batches in parallel (TBB), then accepted in drawing order as the sequential loop
//    would, with its adaptive stopping (the number of iterations follows the best inlier ratio)
//    and its limits: the best model, the iterations and the inliers are those of the
//    sequential loop;
//  - a hypothesis is scored with OpenGV's score (1 − cos of the angle between the bearing and
//    the point seen from the model, computed the same way) on arrays prepared once, and its
//    count stops as soon as it can no longer beat the best count known when its batch started
//    (such a hypothesis would not have been taken).
//  - with a prior pose (sfm/ransac.h PosePrior) that explains enough correspondences, no
//    sampling at all;
//  - the best model is refined on its inliers by Levenberg-Marquardt on the analytic Jacobian
//    of the cost that OpenGV's refinement minimises with numerical derivatives (the sum of the
//    squared scores), to the same minimum in a fraction of the time; the refined model is kept
//    when it has at least as many inliers, as before;
//  - optionally (a consensus threshold above the threshold) the hypotheses are scored, and the
//    adaptive stopping counts, within the consensus threshold, and the best one is refined on
//    the correspondences within it before the inliers are selected (and refined on) within the
//    threshold. With the consensus threshold equal to the threshold, OpenGV's estimate.

#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <climits>
#include <cmath>
#include <limits>
#include <memory>
#include <opengv/sac_problems/absolute_pose/AbsolutePoseSacProblem.hpp>
#include <opengv/types.hpp>
#include <vector>

#include "sfm/opengv_ransac.h"
#include "sfm/ransac.h"

namespace omni::internal {

// The refinement on the inliers (AbsolutePoseScorer::Refine): Levenberg-Marquardt steps until
// the cost falls by less than this share or the step is this small (radians and metres), at
// most this many.
constexpr int kMaxRefineIterations = 30;
constexpr double kRefineRelativeDecrease = 1e-10;
constexpr double kRefineMinStep = 1e-10;

// OpenGV's absolute-pose score of every correspondence against a model (world_from_rig as
// [R t]): the point taken into the rig frame, then into its camera's frame (non-central), made
// unit, and 1 − its dot product with the observed bearing.
class AbsolutePoseScorer {
 public:
  // Central: no cameras (identity rotation, zero offset). Non-central: cameras[i] indexes
  // cam_rotations (camera axes in the rig frame) and cam_offsets (camera centres in the rig).
  AbsolutePoseScorer(const std::vector<Eigen::Vector3d>& bearings,
                     const std::vector<Eigen::Vector3d>& points,
                     const std::vector<int>* cameras = nullptr,
                     const opengv::rotations_t* cam_rotations = nullptr,
                     const opengv::translations_t* cam_offsets = nullptr)
      : bearings_(bearings), points_(points), cameras_(cameras) {
    if (cameras_ != nullptr) {
      for (const opengv::rotation_t& rotation : *cam_rotations)
        cam_rotations_transposed_.push_back(rotation.transpose());
      cam_offsets_ = *cam_offsets;
    }
  }

  size_t size() const { return bearings_.size(); }

  // The number of correspondences scoring below threshold; once that count can no longer
  // exceed `bound`, returns early with a count of at most `bound`.
  int Count(const opengv::transformation_t& model, double threshold, int bound) const {
    const Inverse inverse(model);
    const int n = static_cast<int>(size());
    int count = 0;
    for (int i = 0; i < n; ++i) {
      if (Score(inverse, i) < threshold) ++count;
      if (count + (n - 1 - i) <= bound) return count;
    }
    return count;
  }

  void Select(const opengv::transformation_t& model, double threshold,
              std::vector<int>* inliers) const {
    const Inverse inverse(model);
    inliers->clear();
    for (int i = 0; i < static_cast<int>(size()); ++i)
      if (Score(inverse, i) < threshold) inliers->push_back(i);
  }

  // The refinement of the model on the inliers: the least squares of OpenGV's score over them
  // (the cost that opengv::absolute_pose::optimize_nonlinear minimises, there by
  // Levenberg-Marquardt on numerical derivatives), here by Levenberg-Marquardt on the analytic
  // Jacobian: the pose perturbed by a rotation and a translation in the rig frame.
  opengv::transformation_t Refine(const opengv::transformation_t& model,
                                  const std::vector<int>& inliers) const {
    using Matrix6 = Eigen::Matrix<double, 6, 6>;
    using Vector6 = Eigen::Matrix<double, 6, 1>;
    Eigen::Matrix3d rotation = model.block<3, 3>(0, 0);  // world_from_rig
    Eigen::Vector3d translation = model.col(3);
    // Cost, and (when wanted) the normal equations, at a pose.
    auto evaluate = [&](const Eigen::Matrix3d& r, const Eigen::Vector3d& t, Matrix6* jtj,
                        Vector6* jtf) {
      const Eigen::Matrix3d rig_from_world = r.transpose();
      double cost = 0.0;
      if (jtj != nullptr) {
        jtj->setZero();
        jtf->setZero();
      }
      for (int i : inliers) {
        const Eigen::Vector3d q = rig_from_world * (points_[i] - t);  // the point in the rig
        Eigen::Vector3d in_camera = q;
        const Eigen::Matrix3d* cam_from_rig = nullptr;
        if (cameras_ != nullptr) {
          const int c = (*cameras_)[i];
          cam_from_rig = &cam_rotations_transposed_[c];
          in_camera = *cam_from_rig * (q - cam_offsets_[c]);
        }
        const double norm = in_camera.norm();
        const Eigen::Vector3d unit = in_camera / norm;
        const double residual = 1.0 - unit.dot(bearings_[i]);
        cost += residual * residual;
        if (jtj == nullptr) continue;
        // d residual / d in_camera, then in the rig frame: q moves by q x w - d for a rotation
        // w (world_from_rig * exp(w)) and a translation R d.
        const Eigen::Vector3d g = -(bearings_[i] - unit * unit.dot(bearings_[i])) / norm;
        const Eigen::Vector3d h = cam_from_rig != nullptr ? cam_from_rig->transpose() * g : g;
        Vector6 row;
        row.head<3>() = h.cross(q);
        row.tail<3>() = -h;
        *jtj += row * row.transpose();
        *jtf += row * residual;
      }
      return cost;
    };
    Matrix6 jtj;
    Vector6 jtf;
    double cost = evaluate(rotation, translation, &jtj, &jtf);
    double lambda = 1e-3;
    for (int iteration = 0; iteration < kMaxRefineIterations && cost > 0.0; ++iteration) {
      // Each score is about half the squared angle, so the cost is quartic in the angles and its
      // Hessian about 1.5 times the Gauss-Newton one: the Gauss-Newton step would overshoot by
      // half (converging only linearly).
      Matrix6 damped = 1.5 * jtj;
      damped.diagonal() *= 1.0 + lambda;
      const Vector6 step = damped.ldlt().solve(-jtf);
      if (!step.allFinite()) break;
      const Eigen::Matrix3d new_rotation =
          rotation * Eigen::AngleAxisd(step.head<3>().norm(),
                                       step.head<3>().norm() > 0.0
                                           ? Eigen::Vector3d(step.head<3>().normalized())
                                           : Eigen::Vector3d::UnitX())
                         .toRotationMatrix();
      const Eigen::Vector3d new_translation = translation + rotation * step.tail<3>();
      const double new_cost = evaluate(new_rotation, new_translation, nullptr, nullptr);
      if (new_cost < cost) {
        const bool converged =
            cost - new_cost <= kRefineRelativeDecrease * cost || step.norm() <= kRefineMinStep;
        rotation = new_rotation;
        translation = new_translation;
        cost = evaluate(rotation, translation, &jtj, &jtf);
        lambda = std::max(lambda / 10.0, 1e-12);
        if (converged) break;
      } else {
        lambda *= 10.0;
        if (lambda > 1e8) break;
      }
    }
    opengv::transformation_t refined;
    refined.block<3, 3>(0, 0) = rotation;
    refined.col(3) = translation;
    return refined;
  }

 private:
  struct Inverse {  // rig_from_world as OpenGV forms it
    explicit Inverse(const opengv::transformation_t& model) {
      matrix.block<3, 3>(0, 0) = model.block<3, 3>(0, 0).transpose();
      matrix.col(3) = -matrix.block<3, 3>(0, 0) * model.col(3);
    }
    opengv::transformation_t matrix;
  };

  double Score(const Inverse& inverse, int i) const {
    Eigen::Matrix<double, 4, 1> p_hom;
    p_hom.block<3, 1>(0, 0) = points_[i];
    p_hom[3] = 1.0;
    const opengv::point_t body = inverse.matrix * p_hom;
    opengv::point_t reprojection = body;
    if (cameras_ != nullptr) {
      const int c = (*cameras_)[i];
      reprojection = cam_rotations_transposed_[c] * (body - cam_offsets_[c]);
    }
    reprojection = reprojection / reprojection.norm();
    return 1.0 - (reprojection.transpose() * bearings_[i]);
  }

  const std::vector<Eigen::Vector3d>& bearings_;
  const std::vector<Eigen::Vector3d>& points_;
  const std::vector<int>* cameras_;
  opengv::rotations_t cam_rotations_transposed_;
  opengv::translations_t cam_offsets_;
};

// The model refined on its inliers (when more than a minimal sample) and its inliers selected
// again; taken when the refinement is finite and keeps at least as many inliers. Whether it
// was taken.
inline bool RefineOnInliers(const AbsolutePoseScorer& scorer, double threshold, int sample_size,
                            opengv::transformation_t* model, std::vector<int>* inliers) {
  if (static_cast<int>(inliers->size()) <= sample_size) return false;
  const opengv::transformation_t refined = scorer.Refine(*model, *inliers);
  if (!refined.allFinite()) return false;
  std::vector<int> refined_inliers;
  scorer.Select(refined, threshold, &refined_inliers);
  if (refined_inliers.size() < inliers->size()) return false;
  *model = refined;
  *inliers = std::move(refined_inliers);
  return true;
}

// The inliers of `model` within threshold, then the model refined on them (RefineOnInliers) up
// to kRepeatedRefinements times, each kept while it keeps at least as many (none when `refine`
// is false): the prior's and the consensus's estimate.
constexpr int kRepeatedRefinements = 2;
inline void SelectAndRefine(const AbsolutePoseScorer& scorer, double threshold, int sample_size,
                            bool refine, opengv::transformation_t* model,
                            std::vector<int>* inliers) {
  scorer.Select(*model, threshold, inliers);
  for (int round = 0; round < kRepeatedRefinements && refine; ++round) {
    if (!RefineOnInliers(scorer, threshold, sample_size, model, inliers)) break;
  }
}

// Hypotheses solved at once: never more than the iterations the adaptive stopping still
// expects (so that a short run does not solve many extra samples), at least 2 (two cores).
constexpr int kMaxHypothesisBatch = 16;

using AbsolutePoseProblem = opengv::sac_problems::absolute_pose::AbsolutePoseSacProblem;

// `hypothesis_centre`: when given, the problem's hypotheses are poses of a frame with the rig's
// axes at this point of the rig (a central solver on bearings from one centre), taken to
// world_from_rig before they are scored; the scorer, the refinement and the model are the
// rig's. `consensus_threshold`: the score within which hypotheses are counted (see above); one
// at or below `threshold` (e.g. 0) counts within the threshold itself.
inline RansacResult RunAbsolutePoseRansac(const std::shared_ptr<AbsolutePoseProblem>& problem,
                                          const AbsolutePoseScorer& scorer, double threshold,
                                          const RansacOptions& options,
                                          opengv::transformation_t* model,
                                          const PosePrior* prior = nullptr,
                                          const Eigen::Vector3d* hypothesis_centre = nullptr,
                                          double consensus_threshold = 0.0) {
  const bool wider_consensus = consensus_threshold > threshold;
  const double count_threshold = wider_consensus ? consensus_threshold : threshold;
  RansacResult result;
  const size_t num_correspondences = scorer.size();
  result.inlier_mask.assign(num_correspondences, 0);
  const int sample_size = problem->getSampleSize();
  const int min_inliers = std::max(options.min_inliers, sample_size);
  if (static_cast<int>(num_correspondences) < min_inliers) return result;

  if (prior != nullptr) {
    opengv::transformation_t candidate = prior->pose.ToMatrix();
    std::vector<int> inliers;
    SelectAndRefine(scorer, threshold, sample_size, options.refine, &candidate, &inliers);
    if (static_cast<int>(inliers.size()) >= std::max(min_inliers, prior->accept_inliers)) {
      result.success = true;
      result.from_prior = true;
      result.num_inliers = static_cast<int>(inliers.size());
      for (int index : inliers) result.inlier_mask[index] = 1;
      *model = candidate;
      return result;
    }
  }

  SeedOpengvProblem(problem.get(), options.seed);

  // The loop of opengv::sac::Ransac::computeModel, batch by batch.
  int iterations = 0;
  int best_count = -INT_MAX;
  double k = 1.0;
  unsigned skipped = 0;
  const unsigned max_skip = static_cast<unsigned>(options.max_iterations) * 10;
  bool have_model = false;
  opengv::transformation_t best_model;
  std::vector<std::vector<int>> samples(kMaxHypothesisBatch);
  std::vector<opengv::transformation_t> models(kMaxHypothesisBatch);
  std::vector<char> solved(kMaxHypothesisBatch);
  std::vector<int> counts(kMaxHypothesisBatch);
  bool stop = false;
  while (!stop && iterations < k && skipped < max_skip) {
    const double expected = std::ceil(k) - iterations;
    const int batch = static_cast<int>(std::clamp(expected, 2.0, double(kMaxHypothesisBatch)));
    int drawn = 0;
    for (; drawn < batch; ++drawn) {
      int unused_iterations = iterations;
      problem->getSamples(unused_iterations, samples[drawn]);
      if (samples[drawn].empty()) break;  // the sequential loop stops at this sample
    }
    const int bound = best_count;
    tbb::parallel_for(
        tbb::blocked_range<int>(0, drawn, 1), [&](const tbb::blocked_range<int>& range) {
          for (int j = range.begin(); j != range.end(); ++j) {
            solved[j] = problem->computeModelCoefficients(samples[j], models[j]);
            if (solved[j] && hypothesis_centre != nullptr)
              models[j].col(3) -= models[j].block<3, 3>(0, 0) * *hypothesis_centre;
            counts[j] = solved[j] ? scorer.Count(models[j], count_threshold, bound) : 0;
          }
        });
    // Accepted in drawing order, exactly as one sample at a time.
    for (int j = 0; j < batch; ++j) {
      if (!(iterations < k && skipped < max_skip)) break;
      if (j == drawn) {  // no sample could be drawn
        stop = true;
        break;
      }
      if (!solved[j]) {
        ++skipped;
        continue;
      }
      if (counts[j] > best_count) {
        best_count = counts[j];
        best_model = models[j];
        have_model = true;
        const double w = static_cast<double>(best_count) / static_cast<double>(num_correspondences);
        double p_no_outliers = 1.0 - std::pow(w, static_cast<double>(sample_size));
        p_no_outliers = std::max(std::numeric_limits<double>::epsilon(), p_no_outliers);
        p_no_outliers = std::min(1.0 - std::numeric_limits<double>::epsilon(), p_no_outliers);
        k = std::log(1.0 - options.confidence) / std::log(p_no_outliers);
      }
      ++iterations;
      if (iterations > options.max_iterations) {
        stop = true;
        break;
      }
    }
  }
  if (!have_model) return result;

  std::vector<int> inliers;
  if (wider_consensus && options.refine)
    SelectAndRefine(scorer, consensus_threshold, sample_size, true, &best_model, &inliers);
  scorer.Select(best_model, threshold, &inliers);
  if (options.refine) RefineOnInliers(scorer, threshold, sample_size, &best_model, &inliers);
  result.num_iterations = iterations;
  result.num_inliers = static_cast<int>(inliers.size());
  for (int index : inliers) result.inlier_mask[index] = 1;
  result.success = result.num_inliers >= min_inliers;
  *model = best_model;
  return result;
}

}  // namespace omni::internal
