#include "calib/pose.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace omni {
namespace {

Eigen::Quaterniond RandomRotation(std::mt19937* rng) {
  std::normal_distribution<double> normal(0.0, 1.0);
  return Eigen::Quaterniond(normal(*rng), normal(*rng), normal(*rng), normal(*rng)).normalized();
}

Eigen::Vector3d RandomVector(std::mt19937* rng, double sigma) {
  std::normal_distribution<double> normal(0.0, sigma);
  return Eigen::Vector3d(normal(*rng), normal(*rng), normal(*rng));
}

Rigid3d RandomRigid(std::mt19937* rng) {
  return Rigid3d(RandomRotation(rng), RandomVector(rng, 3.0));
}

TEST(Rigid3d, InverseComposesToIdentity) {
  std::mt19937 rng(1);
  for (int i = 0; i < 50; ++i) {
    const Rigid3d b_from_a = RandomRigid(&rng);
    const Rigid3d a_from_a = b_from_a.Inverse() * b_from_a;
    const Rigid3d b_from_b = b_from_a * b_from_a.Inverse();
    EXPECT_LT(a_from_a.rotation.angularDistance(Eigen::Quaterniond::Identity()), 1e-12);
    EXPECT_LT(a_from_a.translation.norm(), 1e-12);
    EXPECT_LT(b_from_b.rotation.angularDistance(Eigen::Quaterniond::Identity()), 1e-12);
    EXPECT_LT(b_from_b.translation.norm(), 1e-12);
    const Eigen::Vector3d point_in_a = RandomVector(&rng, 5.0);
    EXPECT_LT((b_from_a.Inverse() * (b_from_a * point_in_a) - point_in_a).norm(), 1e-12);
  }
}

TEST(Rigid3d, CompositionMapsPointsLikeSuccessiveTransforms) {
  std::mt19937 rng(2);
  for (int i = 0; i < 50; ++i) {
    const Rigid3d b_from_a = RandomRigid(&rng);
    const Rigid3d c_from_b = RandomRigid(&rng);
    const Rigid3d d_from_c = RandomRigid(&rng);
    const Eigen::Vector3d point_in_a = RandomVector(&rng, 5.0);
    const Rigid3d c_from_a = c_from_b * b_from_a;
    EXPECT_LT((c_from_a * point_in_a - c_from_b * (b_from_a * point_in_a)).norm(), 1e-12);
    // Associativity.
    const Rigid3d left = (d_from_c * c_from_b) * b_from_a;
    const Rigid3d right = d_from_c * (c_from_b * b_from_a);
    EXPECT_LT(left.rotation.angularDistance(right.rotation), 1e-12);
    EXPECT_LT((left.translation - right.translation).norm(), 1e-12);
    // (c_from_b * b_from_a)^-1 = b_from_a^-1 * c_from_b^-1.
    const Rigid3d a_from_c = b_from_a.Inverse() * c_from_b.Inverse();
    EXPECT_LT((a_from_c * (c_from_a * point_in_a) - point_in_a).norm(), 1e-12);
  }
}

TEST(Rigid3d, CenterIsTheOriginOfTheTargetFrame) {
  std::mt19937 rng(3);
  const Rigid3d cam_from_rig = RandomRigid(&rng);
  EXPECT_LT((cam_from_rig * cam_from_rig.Center()).norm(), 1e-12);
  EXPECT_LT((cam_from_rig.Center() - cam_from_rig.Inverse().translation).norm(), 1e-12);
}

TEST(Rigid3d, MatrixRoundTripAndProjectionToRotation) {
  std::mt19937 rng(4);
  for (int i = 0; i < 20; ++i) {
    const Rigid3d b_from_a = RandomRigid(&rng);
    const Eigen::Matrix<double, 3, 4> matrix = b_from_a.ToMatrix();
    const Eigen::Vector3d point = RandomVector(&rng, 2.0);
    EXPECT_LT((matrix * point.homogeneous() - b_from_a * point).norm(), 1e-12);
    const Rigid3d back = Rigid3d::FromMatrix(matrix);
    EXPECT_LT(back.rotation.angularDistance(b_from_a.rotation), 1e-12);
    EXPECT_LT((back.translation - b_from_a.translation).norm(), 1e-12);

    // A perturbed, non-orthonormal R is projected onto the nearest rotation.
    Eigen::Matrix<double, 3, 4> noisy = matrix;
    noisy.leftCols<3>() += 1e-3 * Eigen::Matrix3d::Random();
    const Rigid3d projected = Rigid3d::FromMatrix(noisy);
    EXPECT_NEAR(projected.rotation.norm(), 1.0, 1e-12);
    const Eigen::Matrix3d r = projected.rotation.toRotationMatrix();
    EXPECT_LT((r.transpose() * r - Eigen::Matrix3d::Identity()).norm(), 1e-12);
    EXPECT_LT(projected.rotation.angularDistance(b_from_a.rotation), 1e-2);
    EXPECT_GT(projected.rotation.angularDistance(b_from_a.rotation), 0.0);
    EXPECT_EQ(projected.translation, noisy.col(3));
  }
  // A reflection is not returned: det must stay +1.
  Eigen::Matrix<double, 3, 4> reflection = Eigen::Matrix<double, 3, 4>::Zero();
  reflection.leftCols<3>() = Eigen::Vector3d(1.0, 1.0, -1.0).asDiagonal();
  const Rigid3d from_reflection = Rigid3d::FromMatrix(reflection);
  EXPECT_NEAR(from_reflection.rotation.toRotationMatrix().determinant(), 1.0, 1e-12);
}

Sim3d RandomSim(std::mt19937* rng) {
  std::uniform_real_distribution<double> scale(0.2, 5.0);
  return Sim3d(scale(*rng), RandomRotation(rng), RandomVector(rng, 3.0));
}

TEST(Sim3d, InverseAndComposition) {
  std::mt19937 rng(5);
  for (int i = 0; i < 50; ++i) {
    const Sim3d b_from_a = RandomSim(&rng);
    const Sim3d c_from_b = RandomSim(&rng);
    const Eigen::Vector3d point = RandomVector(&rng, 5.0);
    EXPECT_LT((b_from_a.Inverse() * (b_from_a * point) - point).norm(), 1e-11);
    const Sim3d identity = b_from_a.Inverse() * b_from_a;
    EXPECT_NEAR(identity.scale, 1.0, 1e-14);
    EXPECT_LT(identity.rotation.angularDistance(Eigen::Quaterniond::Identity()), 1e-12);
    EXPECT_LT(identity.translation.norm(), 1e-11);
    const Sim3d c_from_a = c_from_b * b_from_a;
    EXPECT_NEAR(c_from_a.scale, c_from_b.scale * b_from_a.scale, 1e-14);
    EXPECT_LT((c_from_a * point - c_from_b * (b_from_a * point)).norm(), 1e-11);
    EXPECT_LT((c_from_a.ToMatrix() * point.homogeneous() - c_from_a * point).norm(), 1e-11);
  }
}

TEST(TransformPose, RigPointsMapThroughTheSimilarity) {
  std::mt19937 rng(6);
  for (int i = 0; i < 50; ++i) {
    const Sim3d new_from_old = RandomSim(&rng);
    const Rigid3d old_from_rig = RandomRigid(&rng);
    const Rigid3d new_from_rig = TransformPose(new_from_old, old_from_rig);
    // The rig origin and the rig orientation follow the similarity; rig lengths are not scaled.
    EXPECT_LT((new_from_rig.translation - new_from_old * old_from_rig.translation).norm(), 1e-11);
    EXPECT_LT(new_from_rig.rotation.angularDistance(new_from_old.rotation * old_from_rig.rotation),
              1e-12);
    const Eigen::Vector3d point_in_rig = RandomVector(&rng, 0.2);
    const Eigen::Vector3d expected = new_from_old * old_from_rig.translation +
                                     new_from_old.rotation * (old_from_rig.rotation * point_in_rig);
    EXPECT_LT((new_from_rig * point_in_rig - expected).norm(), 1e-11);
    // A rigid new_from_old (scale 1) maps rig points exactly like the composition.
    const Sim3d rigid(1.0, new_from_old.rotation, new_from_old.translation);
    const Rigid3d via_rigid = TransformPose(rigid, old_from_rig);
    EXPECT_LT((via_rigid * point_in_rig - rigid * (old_from_rig * point_in_rig)).norm(), 1e-11);
  }
}

TEST(Umeyama, RecoversSimilarityFromNoisyPoints) {
  std::mt19937 rng(7);
  const Sim3d dst_from_src(2.5, RandomRotation(&rng), Eigen::Vector3d(10.0, -4.0, 2.5));
  std::vector<Eigen::Vector3d> src, dst;
  for (int i = 0; i < 200; ++i) {
    src.push_back(RandomVector(&rng, 10.0));
    dst.push_back(dst_from_src * src.back() + RandomVector(&rng, 0.01));
  }
  const Sim3d estimate = EstimateSim3Umeyama(src, dst);
  EXPECT_NEAR(estimate.scale, 2.5, 2.5e-4);
  EXPECT_LT(estimate.rotation.angularDistance(dst_from_src.rotation), 1e-4);
  EXPECT_LT((estimate.translation - dst_from_src.translation).norm(), 5e-3);
  // The residual is the noise: 1 cm per axis, sqrt(3) cm per point.
  const double rms = AlignmentRms(estimate, src, dst);
  EXPECT_GT(rms, 0.012);
  EXPECT_LT(rms, 0.022);
  EXPECT_GT(AlignmentRms(Sim3d(), src, dst), 1.0);
}

TEST(Umeyama, WithoutScaleRecoversRigidTransform) {
  std::mt19937 rng(8);
  const Sim3d dst_from_src(1.0, RandomRotation(&rng), Eigen::Vector3d(-3.0, 1.0, 7.0));
  std::vector<Eigen::Vector3d> src, dst;
  for (int i = 0; i < 200; ++i) {
    src.push_back(RandomVector(&rng, 10.0));
    dst.push_back(dst_from_src * src.back() + RandomVector(&rng, 0.01));
  }
  const Sim3d estimate = EstimateSim3Umeyama(src, dst, /*estimate_scale=*/false);
  EXPECT_EQ(estimate.scale, 1.0);
  EXPECT_LT(estimate.rotation.angularDistance(dst_from_src.rotation), 1e-4);
  EXPECT_LT((estimate.translation - dst_from_src.translation).norm(), 5e-3);

  // With scaled data the rigid fit keeps scale 1 and leaves a large residual.
  std::vector<Eigen::Vector3d> scaled;
  for (const Eigen::Vector3d& p : dst) scaled.push_back(2.0 * p);
  const Sim3d rigid = EstimateSim3Umeyama(src, scaled, false);
  EXPECT_EQ(rigid.scale, 1.0);
  EXPECT_GT(AlignmentRms(rigid, src, scaled), 1.0);
  EXPECT_LT(AlignmentRms(EstimateSim3Umeyama(src, scaled, true), src, scaled), 0.05);
}

}  // namespace
}  // namespace omni
