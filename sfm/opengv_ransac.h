#pragma once
// Internal to sfm/ (not a public header): runs an OpenGV sample-consensus problem with the
// options of sfm/ransac.h, seeded, and refines the best model on its inliers.

#include <cmath>
#include <functional>
#include <memory>
#include <opengv/sac/Ransac.hpp>
#include <opengv/types.hpp>
#include <vector>

#include "calib/pose.h"
#include "sfm/ransac.h"

namespace omni::internal {

inline opengv::bearingVectors_t ToOpengvVectors(const std::vector<Eigen::Vector3d>& vectors) {
  return opengv::bearingVectors_t(vectors.begin(), vectors.end());
}

// OpenGV transformations are [R t] of the second frame seen in the first: first_from_second.
inline Rigid3d FromOpengvTransformation(const opengv::transformation_t& first_from_second) {
  const Eigen::Matrix3d rotation = first_from_second.leftCols<3>();
  return Rigid3d(Eigen::Quaterniond(rotation).normalized(), first_from_second.col(3));
}

// OpenGV's per-view score is 1 − cos(angle).
inline double AngleToOpengvScore(double angle) { return 1.0 - std::cos(angle); }

// The problem's generator is a copy of rng_alg_ bound at construction: reseed both.
template <typename Problem>
void SeedOpengvProblem(Problem* problem, uint32_t seed) {
  problem->rng_alg_.seed(seed);
  problem->rng_gen_ =
      std::make_shared<std::function<int()>>(std::bind(*problem->rng_dist_, problem->rng_alg_));
}

template <typename Problem>
RansacResult RunOpengvRansac(const std::shared_ptr<Problem>& problem, size_t num_correspondences,
                             int sample_size, double threshold, const RansacOptions& options,
                             typename Problem::model_t* model) {
  RansacResult result;
  result.inlier_mask.assign(num_correspondences, 0);
  const int min_inliers = std::max(options.min_inliers, sample_size);
  if (static_cast<int>(num_correspondences) < min_inliers) return result;

  SeedOpengvProblem(problem.get(), options.seed);

  opengv::sac::Ransac<Problem> ransac;
  ransac.sac_model_ = problem;
  ransac.threshold_ = threshold;
  ransac.max_iterations_ = options.max_iterations;
  ransac.probability_ = options.confidence;
  if (!ransac.computeModel(0)) return result;

  typename Problem::model_t best = ransac.model_coefficients_;
  std::vector<int> inliers = ransac.inliers_;
  if (options.refine && static_cast<int>(inliers.size()) > sample_size) {
    typename Problem::model_t refined;
    problem->optimizeModelCoefficients(inliers, best, refined);
    std::vector<int> refined_inliers;
    if (refined.allFinite()) {
      problem->selectWithinDistance(refined, threshold, refined_inliers);
      if (refined_inliers.size() >= inliers.size()) {
        best = refined;
        inliers = refined_inliers;
      }
    }
  }
  result.num_iterations = ransac.iterations_;
  result.num_inliers = static_cast<int>(inliers.size());
  for (int index : inliers) result.inlier_mask[index] = 1;
  result.success = result.num_inliers >= min_inliers;
  *model = best;
  return result;
}

}  // namespace omni::internal
