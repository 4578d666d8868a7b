#include "sfm/bundle_adjustment.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <random>
#include <vector>

#include "sfm/internal/angular_residual.h"
#include "sfm/synthetic.h"
#include "tests/calib/options_error_check.h"

namespace omni {
namespace {

// Six keyframes 1 m apart along a gently turning path; the first two fixed (they fix the
// gauge: rotation, translation and scale).
std::vector<Rigid3d> Trajectory() {
  std::vector<Rigid3d> poses;
  for (int i = 0; i < 6; ++i)
    poses.emplace_back(Eigen::Quaterniond(Eigen::AngleAxisd(0.05 * i, Eigen::Vector3d::UnitZ())),
                       Eigen::Vector3d(1.0 * i, 0.1 * i * i, 0.02 * i));
  return poses;
}

BundleAdjustmentProblem ProblemFromScene(const SyntheticScene& scene, int num_fixed) {
  BundleAdjustmentProblem problem;
  for (size_t i = 0; i < scene.world_from_rig.size(); ++i)
    problem.keyframes.push_back({scene.world_from_rig[i], static_cast<int>(i) < num_fixed});
  problem.points_in_world = scene.points_in_world;
  for (const SyntheticObservation& observation : scene.observations)
    problem.observations.push_back(
        {observation.frame, observation.camera, observation.point, observation.bearing});
  return problem;
}

void Perturb(BundleAdjustmentProblem* problem, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  auto random_vector = [&]() { return Eigen::Vector3d(normal(rng), normal(rng), normal(rng)); };
  for (BundleAdjustmentKeyframe& keyframe : problem->keyframes) {
    if (keyframe.fixed) continue;
    const Eigen::Vector3d axis_angle = 0.01 * random_vector();
    keyframe.world_from_rig.rotation =
        Eigen::Quaterniond(Eigen::AngleAxisd(axis_angle.norm(), axis_angle.normalized())) *
        keyframe.world_from_rig.rotation;
    keyframe.world_from_rig.translation += 0.05 * random_vector();
  }
  for (Eigen::Vector3d& point : problem->points_in_world) point += 0.05 * random_vector();
}

struct Case {
  BundleAdjustmentOptions::Mode mode;
  BundleAdjustmentOptions::LinearSolver solver;
  double rig_radius;
};

class BundleAdjustmentTest : public ::testing::TestWithParam<Case> {};

TEST_P(BundleAdjustmentTest, ConvergesToTruthAndRemovesInjectedOutlier) {
  // Central mode is exact only for a rig whose cameras share one centre (radius 0).
  const Rig rig = MakeSyntheticRingRig(5, true, GetParam().rig_radius);
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 250;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  scene_options.seed = 11;
  const SyntheticScene scene = MakeSyntheticScene(rig, Trajectory(), scene_options);
  BundleAdjustmentProblem problem = ProblemFromScene(scene, 2);

  // Every point must be seen at least twice for the truth to be the unique optimum.
  std::vector<int> views(problem.points_in_world.size(), 0);
  for (const auto& observation : problem.observations) ++views[observation.point];
  ASSERT_GE(*std::min_element(views.begin(), views.end()), 2);

  // One observation turned by 3°: an outlier the adjustment must remove.
  const int outlier = static_cast<int>(problem.observations.size() / 2);
  Eigen::Vector3d& bearing = problem.observations[outlier].bearing;
  bearing = Eigen::AngleAxisd(0.05, bearing.unitOrthogonal()) * bearing;

  Perturb(&problem, 5);
  BundleAdjustmentOptions options;
  options.mode = GetParam().mode;
  options.linear_solver = GetParam().solver;
  const BundleAdjustmentSummary summary = LocalBundleAdjust(rig, options, &problem);
  ASSERT_TRUE(summary.success) << summary.BriefReport();

  EXPECT_GT(summary.rms_angle_before, 0.005);
  EXPECT_LT(summary.rms_angle_after, 1e-6) << summary.BriefReport();
  ASSERT_EQ(summary.removed_observations.size(), 1u) << summary.BriefReport();
  EXPECT_EQ(summary.removed_observations[0], outlier);
  EXPECT_EQ(problem.observations.size(), scene.observations.size() - 1);

  for (size_t i = 0; i < problem.keyframes.size(); ++i) {
    EXPECT_LT(RotationAngleBetween(problem.keyframes[i].world_from_rig.rotation,
                                   scene.world_from_rig[i].rotation),
              1e-6)
        << "keyframe " << i;
    EXPECT_LT(
        (problem.keyframes[i].world_from_rig.translation - scene.world_from_rig[i].translation)
            .norm(),
        1e-5)
        << "keyframe " << i;
  }
  double max_point_error = 0.0;
  for (size_t i = 0; i < problem.points_in_world.size(); ++i)
    max_point_error =
        std::max(max_point_error, (problem.points_in_world[i] - scene.points_in_world[i]).norm());
  EXPECT_LT(max_point_error, 1e-4);
}

INSTANTIATE_TEST_SUITE_P(
    Modes, BundleAdjustmentTest,
    ::testing::Values(Case{BundleAdjustmentOptions::Mode::kCentral,
                           BundleAdjustmentOptions::LinearSolver::kSparseSchur, 0.0},
                      Case{BundleAdjustmentOptions::Mode::kNonCentral,
                           BundleAdjustmentOptions::LinearSolver::kSparseSchur, 0.4},
                      Case{BundleAdjustmentOptions::Mode::kNonCentral,
                           BundleAdjustmentOptions::LinearSolver::kDenseSchur, 0.4}));

TEST(BundleAdjustment, CentralModeIsBiasedOnAWideRig) {
  // The same adjustment in central mode on a rig with 0.4 m offsets cannot fit the
  // observations: the central approximation is wrong there, which is what non-central mode is
  // for.
  const Rig rig = MakeSyntheticRingRig(5, true, 0.4);
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 150;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  const SyntheticScene scene = MakeSyntheticScene(rig, Trajectory(), scene_options);
  BundleAdjustmentOptions options;
  options.max_outlier_angle = M_PI;  // keep everything: compare the fits
  BundleAdjustmentProblem central = ProblemFromScene(scene, 2);
  BundleAdjustmentProblem noncentral = central;
  options.mode = BundleAdjustmentOptions::Mode::kCentral;
  const BundleAdjustmentSummary central_summary = LocalBundleAdjust(rig, options, &central);
  options.mode = BundleAdjustmentOptions::Mode::kNonCentral;
  const BundleAdjustmentSummary noncentral_summary = LocalBundleAdjust(rig, options, &noncentral);
  ASSERT_TRUE(central_summary.success && noncentral_summary.success);
  EXPECT_LT(noncentral_summary.rms_angle_after, 1e-9);
  EXPECT_GT(central_summary.rms_angle_after, 1e-3);
}

TEST(BundleAdjustment, EstimatesTheScaleOfTheOffsetsInAMapThatIsNotMetric) {
  // The scene of a rig with 0.4 m offsets in a map of 2.5 units per metre (poses and points
  // scaled, the offsets in rig.json still in metres): with the offsets at scale 1 the
  // observations cannot be fitted; with their scale estimated (from 1) they are, at 2.5.
  const Rig rig = MakeSyntheticRingRig(5, true, 0.4);
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 200;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  scene_options.seed = 3;
  const SyntheticScene scene = MakeSyntheticScene(rig, Trajectory(), scene_options);
  const double map_units_per_metre = 2.5;
  BundleAdjustmentProblem problem = ProblemFromScene(scene, 2);
  for (BundleAdjustmentKeyframe& keyframe : problem.keyframes)
    keyframe.world_from_rig.translation *= map_units_per_metre;
  for (Eigen::Vector3d& point : problem.points_in_world) point *= map_units_per_metre;
  BundleAdjustmentOptions options;
  options.mode = BundleAdjustmentOptions::Mode::kNonCentral;
  options.max_outlier_angle = M_PI;  // keep everything: compare the fits
  BundleAdjustmentProblem unit_offsets = problem;
  const BundleAdjustmentSummary unit = LocalBundleAdjust(rig, options, &unit_offsets);
  options.estimate_offset_scale = true;
  const BundleAdjustmentSummary scaled = LocalBundleAdjust(rig, options, &problem);
  ASSERT_TRUE(unit.success && scaled.success);
  EXPECT_GT(unit.rms_angle_after, 1e-3);
  EXPECT_LT(scaled.rms_angle_after, 1e-7) << scaled.BriefReport();
  EXPECT_NEAR(scaled.offset_scale, map_units_per_metre, 1e-4);
  EXPECT_DOUBLE_EQ(unit.offset_scale, 1.0);
}

TEST(BundleAdjustment, FixedPointsDoNotMove) {
  const Rig rig = MakeSyntheticRingRig(5, true, 0.4);
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 150;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  const SyntheticScene scene = MakeSyntheticScene(rig, Trajectory(), scene_options);
  BundleAdjustmentProblem problem = ProblemFromScene(scene, 2);
  Perturb(&problem, 3);
  // The first 20 points are fixed at their perturbed positions.
  problem.point_fixed.assign(problem.points_in_world.size(), 0);
  std::fill(problem.point_fixed.begin(), problem.point_fixed.begin() + 20, 1);
  const std::vector<Eigen::Vector3d> before = problem.points_in_world;
  BundleAdjustmentOptions options;
  options.mode = BundleAdjustmentOptions::Mode::kNonCentral;
  options.max_outlier_angle = M_PI;
  const BundleAdjustmentSummary summary = LocalBundleAdjust(rig, options, &problem);
  ASSERT_TRUE(summary.success);
  for (int i = 0; i < 20; ++i) EXPECT_EQ(problem.points_in_world[i], before[i]);
  EXPECT_NE(problem.points_in_world[20], before[20]);
}

// Makes the allocator's next request of lower_bytes land below its next request of
// upper_bytes (with glibc's per-thread caches of freed blocks: each is handed the block of its
// size freed last): both sizes drained from the caches, then one block of each size freed, the
// upper one above the lower one. Holds what it drained until destroyed.
class NextBlocksInOrder {
 public:
  NextBlocksInOrder(size_t lower_bytes, size_t upper_bytes) {
    held_.reserve(4096);
    for (int i = 0; i < 16; ++i) {
      held_.push_back(std::make_unique<char[]>(lower_bytes));
      held_.push_back(std::make_unique<char[]>(upper_bytes));
    }
    std::unique_ptr<char[]> lower = std::make_unique<char[]>(lower_bytes);
    std::unique_ptr<char[]> upper;
    while (held_.size() + 1 < held_.capacity()) {
      upper = std::make_unique<char[]>(upper_bytes);
      if (reinterpret_cast<uintptr_t>(upper.get()) > reinterpret_cast<uintptr_t>(lower.get()))
        break;
      held_.push_back(std::move(upper));
    }
    upper.reset();
    lower.reset();
  }

 private:
  std::vector<std::unique_ptr<char[]>> held_;
};

TEST(BundleAdjustment, TheSolutionDoesNotDependOnWhereTheAllocatorPutsTheParameters) {
  // Ceres orders the parameter blocks of one elimination group by their addresses. The same
  // noisy problem solved with arrays of the sizes of per-keyframe rotations (4 values) and
  // translations (3 values) placed one below the other, then the other way round, gives the
  // same keyframes and points to the last bit, in either linear solver.
  const Rig rig = MakeSyntheticRingRig(5, true, 0.4);
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 200;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 12.0;
  scene_options.noise = 0.001;
  scene_options.seed = 17;
  const SyntheticScene scene = MakeSyntheticScene(rig, Trajectory(), scene_options);
  BundleAdjustmentProblem noisy = ProblemFromScene(scene, 1);
  Perturb(&noisy, 9);
  const size_t num_keyframes = noisy.keyframes.size();
  const size_t rotations_bytes = 4 * sizeof(double) * num_keyframes;
  const size_t translations_bytes = 3 * sizeof(double) * num_keyframes;
  for (const auto solver : {BundleAdjustmentOptions::LinearSolver::kSparseSchur,
                            BundleAdjustmentOptions::LinearSolver::kDenseSchur}) {
    BundleAdjustmentOptions options;
    options.mode = BundleAdjustmentOptions::Mode::kNonCentral;
    options.linear_solver = solver;
    std::vector<BundleAdjustmentProblem> solved;
    for (const bool rotations_below : {true, false}) {
      BundleAdjustmentProblem problem = noisy;
      const NextBlocksInOrder order(rotations_below ? rotations_bytes : translations_bytes,
                                    rotations_below ? translations_bytes : rotations_bytes);
      ASSERT_TRUE(LocalBundleAdjust(rig, options, &problem).success);
      solved.push_back(std::move(problem));
    }
    for (size_t k = 0; k < num_keyframes; ++k) {
      EXPECT_EQ(solved[0].keyframes[k].world_from_rig.rotation.coeffs(),
                solved[1].keyframes[k].world_from_rig.rotation.coeffs())
          << "keyframe " << k;
      EXPECT_EQ(solved[0].keyframes[k].world_from_rig.translation,
                solved[1].keyframes[k].world_from_rig.translation)
          << "keyframe " << k;
    }
    EXPECT_EQ(solved[0].points_in_world, solved[1].points_in_world);
  }
}

// The closed-form Jacobians of the angular residual against central differences of the residual
// itself, at random poses (quaternions near unit and not), points, bearings, camera poses in
// the rig and offset scales; and the residual's norm is 2 tan(θ/2) of the angle θ between the
// bearing and the direction to the point.
TEST(AngularResidualModel, ClosedFormJacobiansMatchFiniteDifferences) {
  std::mt19937 random(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  const auto random_vector = [&] {
    return Eigen::Vector3d(normal(random), normal(random), normal(random));
  };
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Quaterniond frame_rotation = Eigen::Quaterniond::UnitRandom();
    const Eigen::Vector3d frame_translation = 0.5 * random_vector();
    double q[4];
    Eigen::Map<Eigen::Vector4d> q_map(q);
    q_map = Eigen::Quaterniond::UnitRandom().coeffs();
    if (trial % 2 == 1) q_map *= 1.0 + 0.2 * normal(random);  // not unit: the formula's derivative
    double t[3], x[3];
    Eigen::Map<Eigen::Vector3d> t_map(t);
    t_map = 3.0 * random_vector();
    Eigen::Map<Eigen::Vector3d> x_map(x);
    x_map = t_map + 10.0 * random_vector();
    const double scale = 0.5 + std::abs(normal(random));
    // The bearing: the true direction turned by up to about 20 degrees.
    const Eigen::Quaterniond unit_q = Eigen::Quaterniond(q_map).normalized();
    const Eigen::Vector3d x_frame =
        frame_rotation * (unit_q.conjugate() * (x_map - t_map)) + scale * frame_translation;
    const Eigen::Vector3d bearing = (x_frame.normalized() + 0.2 * random_vector()).normalized();
    const internal::AngularResidualModel model(frame_rotation.toRotationMatrix(), frame_translation,
                                               bearing);
    double r[2], jq[8], jt[6], jx[6], js[2];
    model.Evaluate(q, t, x, scale, r, jq, jt, jx, js);
    if (trial % 2 == 0) {
      const double angle = std::atan2(x_frame.cross(bearing).norm(), x_frame.dot(bearing));
      EXPECT_NEAR(Eigen::Vector2d(r[0], r[1]).norm(), 2.0 * std::tan(0.5 * angle), 1e-9);
    }
    // Central differences, step h in each coordinate of each block.
    const double h = 1e-6;
    const auto check = [&](double* block, int size, const double* jacobian, const char* name) {
      for (int k = 0; k < size; ++k) {
        const double saved = block[k];
        double plus[2], minus[2];
        block[k] = saved + h;
        model.Evaluate(q, t, x, scale, plus, nullptr, nullptr, nullptr, nullptr);
        block[k] = saved - h;
        model.Evaluate(q, t, x, scale, minus, nullptr, nullptr, nullptr, nullptr);
        block[k] = saved;
        for (int i = 0; i < 2; ++i) {
          const double numeric = (plus[i] - minus[i]) / (2.0 * h);
          EXPECT_NEAR(jacobian[i * size + k], numeric, 1e-6 * (1.0 + std::abs(numeric)))
              << name << " row " << i << " column " << k << " trial " << trial;
        }
      }
    };
    check(q, 4, jq, "q");
    check(t, 3, jt, "t");
    check(x, 3, jx, "point");
    double s[1] = {scale};
    double plus[2], minus[2];
    model.Evaluate(q, t, x, s[0] + h, plus, nullptr, nullptr, nullptr, nullptr);
    model.Evaluate(q, t, x, s[0] - h, minus, nullptr, nullptr, nullptr, nullptr);
    for (int i = 0; i < 2; ++i)
      EXPECT_NEAR(js[i], (plus[i] - minus[i]) / (2.0 * h), 1e-6) << "scale row " << i;
  }
}

TEST(BundleAdjustment, ObservationAngleMeasuresTheError) {
  const Rig rig = MakeSyntheticRingRig(4, false, 0.5);
  const Rigid3d world_from_rig(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ())),
                               Eigen::Vector3d(1, 2, 3));
  const Eigen::Vector3d point = world_from_rig * Eigen::Vector3d(6.0, 1.0, 0.5);
  const Rigid3d& cam_from_rig = rig.cameras[0].cam_from_rig;
  const Eigen::Vector3d in_cam = cam_from_rig * (world_from_rig.Inverse() * point);
  const Eigen::Vector3d turned =
      Eigen::AngleAxisd(0.01, in_cam.unitOrthogonal()) * in_cam.normalized();
  EXPECT_NEAR(ObservationAngle(rig, BundleAdjustmentOptions::Mode::kNonCentral, world_from_rig,
                               point, 0, in_cam.normalized()),
              0.0, 1e-12);
  EXPECT_NEAR(ObservationAngle(rig, BundleAdjustmentOptions::Mode::kNonCentral, world_from_rig,
                               point, 0, turned),
              0.01, 1e-12);
}

TEST(BundleAdjustmentOptions, CheckRejectsABadOffsetScale) {
  BundleAdjustmentOptions options;
  options.offset_scale = 0.0;
  EXPECT_NE(options.Check().find("offset_scale"), std::string::npos);
}

TEST(BundleAdjustmentOptions, CheckRejectsBadValues) {
  BundleAdjustmentOptions options;
  EXPECT_TRUE(options.Check().empty());
  options.loss_scale = 0.0;
  EXPECT_FALSE(options.Check().empty());
  options = BundleAdjustmentOptions();
  options.max_outlier_angle = -1.0;
  EXPECT_FALSE(options.Check().empty());
}

TEST(BundleAdjustment, BadOptionsThrowNamingTheField) {
  const Rig rig = MakeSyntheticRingRig(2, false, 0.0);
  BundleAdjustmentOptions options;
  options.loss_scale = 0.0;
  BundleAdjustmentProblem problem;
  EXPECT_THROW(LocalBundleAdjust(rig, options, &problem), OptionsError);
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { LocalBundleAdjust(rig, options, &problem); },
                                          "BundleAdjustmentOptions.loss_scale: expected"));
}

}  // namespace
}  // namespace omni
