#include "eval/pose_eval.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "calib/error.h"

namespace omni {
namespace {

// A drive along a curved street at 15 frames/s: about 1 m per frame, 300 m long.
std::vector<StampedPose> MakeGroundTruth(int frames) {
  std::vector<StampedPose> poses;
  for (int f = 0; f < frames; ++f) {
    const double s = f * 1.0;
    const double heading = 0.004 * s;
    StampedPose pose;
    pose.timestamp = f / 15.0;
    pose.world_from_rig.translation =
        Eigen::Vector3d(100.0 * std::sin(heading) / 0.4, 100.0 * (1 - std::cos(heading)) / 0.4,
                        1.5 + 0.2 * std::sin(0.05 * s));
    pose.world_from_rig.rotation = Eigen::AngleAxisd(heading, Eigen::Vector3d::UnitZ());
    poses.push_back(pose);
  }
  return poses;
}

std::vector<StampedPose> ApplySimilarity(const std::vector<StampedPose>& gt,
                                         const Sim3d& estimated_from_gt, double noise,
                                         unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0.0, noise);
  std::vector<StampedPose> estimated;
  for (const StampedPose& pose : gt) {
    StampedPose e = pose;
    e.world_from_rig = TransformPose(estimated_from_gt, pose.world_from_rig);
    e.world_from_rig.translation += Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
    estimated.push_back(e);
  }
  return estimated;
}

TEST(PoseEval, RecoversKnownSimilarity) {
  const auto gt = MakeGroundTruth(300);
  const Sim3d estimated_from_gt(
      0.37, Eigen::Quaterniond(Eigen::AngleAxisd(0.8, Eigen::Vector3d(1, 2, 3).normalized())),
      Eigen::Vector3d(5, -3, 2));
  const double noise = 0.01;  // in estimated units
  auto estimated = ApplySimilarity(gt, estimated_from_gt, noise, 7);
  estimated.erase(estimated.begin() + 100);  // a frame that is not a keyframe
  const PoseEvalResult result = EvaluatePoses(estimated, gt);
  EXPECT_EQ(result.matches.size(), 299u);
  const Sim3d expected = estimated_from_gt.Inverse();
  EXPECT_NEAR(result.gt_from_estimated.scale, expected.scale, 1e-3 * expected.scale);
  EXPECT_LT(result.gt_from_estimated.rotation.angularDistance(expected.rotation), 1e-3);
  EXPECT_LT((result.gt_from_estimated.translation - expected.translation).norm(), 0.05);
  // Isotropic noise of σ per axis in estimated units: RMS ≈ √3 σ / scale in metres.
  const double expected_rms = std::sqrt(3.0) * noise * expected.scale;
  EXPECT_NEAR(result.registration_rms, expected_rms, 0.15 * expected_rms);
  EXPECT_NEAR(result.ate_translation.rmse, result.registration_rms, 1e-9);
  EXPECT_LT(result.ate_rotation_deg.max, 0.05);  // only the error of S's rotation
  EXPECT_NEAR(result.gt_length, 299.0, 0.5);
  ASSERT_EQ(result.rpe.size(), 2u);
  EXPECT_GT(result.rpe[0].pairs, 250);
  EXPECT_GT(result.rpe[1].pairs, 150);
  EXPECT_LT(result.rpe[1].translation_percent, result.rpe[0].translation_percent);
  EXPECT_NEAR(result.scale_drift_min, 1.0, 0.05);
  EXPECT_NEAR(result.scale_drift_max, 1.0, 0.05);
}

TEST(PoseEval, ExactSimilarityGivesZeroErrors) {
  const auto gt = MakeGroundTruth(150);
  const Sim3d estimated_from_gt(
      2.5, Eigen::Quaterniond(Eigen::AngleAxisd(-1.2, Eigen::Vector3d::UnitZ())),
      Eigen::Vector3d(1, 2, 3));
  const PoseEvalResult result = EvaluatePoses(ApplySimilarity(gt, estimated_from_gt, 0.0, 1), gt);
  EXPECT_LT(result.registration_rms, 1e-6);
  EXPECT_LT(result.rpe[0].translation_percent, 1e-5);
  EXPECT_LT(result.rpe[0].rotation_deg_per_100m, 1e-5);
  EXPECT_EQ(result.rpe[1].pairs, 150 - 100);
}

TEST(PoseEval, DetectsScaleDrift) {
  auto gt = MakeGroundTruth(200);
  auto estimated = gt;
  // The estimated steps shrink along the drive: scale 1 at the start, 0.8 at the end.
  Eigen::Vector3d position = gt[0].world_from_rig.translation;
  for (size_t i = 1; i < gt.size(); ++i) {
    const double factor = 1.0 - 0.2 * i / (gt.size() - 1.0);
    position += factor * (gt[i].world_from_rig.translation - gt[i - 1].world_from_rig.translation);
    estimated[i].world_from_rig.translation = position;
  }
  const PoseEvalResult result = EvaluatePoses(estimated, gt);
  ASSERT_GE(result.scale_drift.size(), 5u);
  EXPECT_LT(result.scale_drift.front().relative_scale, result.scale_drift.back().relative_scale);
  EXPECT_NEAR(result.scale_drift.back().relative_scale / result.scale_drift.front().relative_scale,
              1.0 / 0.8, 0.05);
}

TEST(PoseEval, MatchesByFrameIndex) {
  const auto gt = MakeGroundTruth(50);
  auto estimated = gt;
  for (size_t i = 0; i < estimated.size(); ++i) estimated[i].timestamp = static_cast<double>(i);
  PoseEvalOptions options;
  options.matching = PoseMatching::kFrameIndex;
  const PoseEvalResult result = EvaluatePoses(estimated, gt, options);
  EXPECT_EQ(result.matches.size(), 50u);
  EXPECT_LT(result.registration_rms, 1e-9);
}

TEST(PoseEval, NoCommonTimestampsIsInputError) {
  const auto gt = MakeGroundTruth(50);
  auto estimated = gt;
  for (auto& pose : estimated) pose.timestamp += 1.0 / 30.0;  // between the frames
  try {
    EvaluatePoses(estimated, gt);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("only 0 of 50"), std::string::npos) << error.what();
  }
}

TEST(PoseEval, QuantileInterpolates) {
  EXPECT_DOUBLE_EQ(QuantileOfSorted({0.0, 1.0, 2.0, 3.0, 4.0}, 0.5), 2.0);
  EXPECT_DOUBLE_EQ(QuantileOfSorted({0.0, 10.0}, 0.25), 2.5);
  EXPECT_TRUE(std::isnan(QuantileOfSorted({}, 0.5)));
}

}  // namespace
}  // namespace omni
