#include "sfm/absolute_pose_noncentral.h"

#include <algorithm>
#include <cassert>
#include <climits>
#include <memory>
#include <opengv/absolute_pose/CentralAbsoluteAdapter.hpp>
#include <opengv/absolute_pose/NoncentralAbsoluteAdapter.hpp>
#include <opengv/sac_problems/absolute_pose/AbsolutePoseSacProblem.hpp>

#include "calib/error.h"
#include "sfm/absolute_pose_ransac.h"
#include "sfm/opengv_rig.h"

namespace omni {
namespace {

using Problem = opengv::sac_problems::absolute_pose::AbsolutePoseSacProblem;

// OpenGV's KNEIP problem on a non-central adapter solves the P3P of the camera of a sample's
// first correspondence and takes the solutions to the rig with that camera's offset and
// rotation: right when the sample's first three correspondences are all of that camera. This
// problem draws its samples so: the first correspondence uniformly among those whose camera has
// at least three, two more of the same camera, and a fourth (which picks among the P3P's
// solutions, with its own camera's offset) from the rest. The problem's own generator, so that
// SeedOpengvProblem seeds it.
class CameraP3pProblem : public Problem {
 public:
  CameraP3pProblem(adapter_t& adapter, const std::vector<int>& cameras)
      : Problem(adapter, Problem::KNEIP, /*randomSeed=*/false), cameras_(cameras) {
    int num_cameras = 0;
    for (int camera : cameras) num_cameras = std::max(num_cameras, camera + 1);
    by_camera_.resize(num_cameras);
    for (int i = 0; i < static_cast<int>(cameras.size()); ++i) by_camera_[cameras[i]].push_back(i);
    for (int i = 0; i < static_cast<int>(cameras.size()); ++i)
      if (by_camera_[cameras[i]].size() >= 3) eligible_.push_back(i);
  }

  // True when some camera has three correspondences (and there are four in all).
  bool CanSample() const { return !eligible_.empty() && cameras_.size() >= 4; }

  void getSamples(int& iterations, std::vector<int>& samples) override {
    if (!CanSample()) {
      samples.clear();
      iterations = INT_MAX - 1;
      return;
    }
    samples.resize(4);
    samples[0] = eligible_[static_cast<size_t>(rnd()) % eligible_.size()];
    const std::vector<int>& same = by_camera_[cameras_[samples[0]]];
    // Distinct draws: the camera has at least 3 correspondences and the frame at least 4.
    const auto drawn = [&samples](int k, int index) {
      return std::find(samples.begin(), samples.begin() + k, index) != samples.begin() + k;
    };
    for (int k = 1; k < 3; ++k) {
      do {
        samples[k] = same[static_cast<size_t>(rnd()) % same.size()];
      } while (drawn(k, samples[k]));
    }
    do {
      samples[3] = static_cast<int>(static_cast<size_t>(rnd()) % cameras_.size());
    } while (drawn(3, samples[3]));
  }

 private:
  const std::vector<int>& cameras_;
  std::vector<std::vector<int>> by_camera_;  // correspondences per camera
  std::vector<int> eligible_;                // those whose camera has at least three
};

}  // namespace

RansacResult EstimateNoncentralAbsolutePose(const Rig& rig,
                                            const std::vector<Eigen::Vector3d>& bearings,
                                            const std::vector<int>& cameras,
                                            const std::vector<Eigen::Vector3d>& points_in_world,
                                            const NoncentralAbsolutePoseOptions& options,
                                            Rigid3d* world_from_rig, const PosePrior* prior) {
  assert(bearings.size() == points_in_world.size() && cameras.size() == bearings.size());
  ThrowIfInvalid(options.Check(), "NoncentralAbsolutePoseOptions");
  const opengv::bearingVectors_t f = internal::ToOpengvVectors(bearings);
  const opengv::points_t points(points_in_world.begin(), points_in_world.end());
  opengv::translations_t cam_offsets;
  opengv::rotations_t cam_rotations;
  internal::ToOpengvRig(rig, &cam_offsets, &cam_rotations);
  opengv::transformation_t model;
  const internal::AbsolutePoseScorer scorer(bearings, points_in_world, &cameras, &cam_rotations,
                                            &cam_offsets);
  const double threshold = internal::AngleToOpengvScore(options.ransac.max_angle_error);
  const double consensus_threshold =
      internal::AngleToOpengvScore(options.consensus_angle_factor * options.ransac.max_angle_error);
  RansacResult result;
  if (options.hypotheses == NoncentralHypotheses::kRigCentreP3p) {
    // The bearings in the rig's axes, from the mean camera centre.
    opengv::bearingVectors_t rig_bearings(f.size());
    for (size_t i = 0; i < f.size(); ++i) rig_bearings[i] = cam_rotations[cameras[i]] * f[i];
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (const opengv::translation_t& offset : cam_offsets) centre += offset;
    centre /= static_cast<double>(cam_offsets.size());
    opengv::absolute_pose::CentralAbsoluteAdapter adapter(rig_bearings, points);
    auto problem = std::make_shared<Problem>(adapter, Problem::KNEIP, /*randomSeed=*/false);
    result = internal::RunAbsolutePoseRansac(problem, scorer, threshold, options.ransac, &model,
                                             prior, &centre, consensus_threshold);
  } else {
    opengv::absolute_pose::NoncentralAbsoluteAdapter adapter(f, cameras, points, cam_offsets,
                                                             cam_rotations);
    std::shared_ptr<Problem> problem;
    if (options.hypotheses == NoncentralHypotheses::kCameraP3p) {
      auto camera_problem = std::make_shared<CameraP3pProblem>(adapter, cameras);
      if (camera_problem->CanSample()) problem = camera_problem;
    }
    if (!problem) problem = std::make_shared<Problem>(adapter, Problem::GP3P, /*randomSeed=*/false);
    result = internal::RunAbsolutePoseRansac(problem, scorer, threshold, options.ransac, &model,
                                             prior, nullptr, consensus_threshold);
  }
  if (result.success) *world_from_rig = internal::FromOpengvTransformation(model);
  return result;
}

}  // namespace omni
