// The Sim(3) pose graph of loop closure: a drifted loop is pulled back to the truth.

#include "sfm/pose_graph.h"

#include <gtest/gtest.h>

#include <cmath>

#include "tests/calib/options_error_check.h"

namespace omni {
namespace {

constexpr int kNodes = 36;

// Ground truth: a rig driving a circle of radius 20 m, facing along the circle, scale 1.
std::vector<Sim3d> CircleTruth() {
  std::vector<Sim3d> nodes;
  for (int i = 0; i < kNodes; ++i) {
    const double a = 2.0 * M_PI * i / kNodes;
    nodes.emplace_back(1.0, Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ())),
                       Eigen::Vector3d(20.0 * std::sin(a), 20.0 - 20.0 * std::cos(a), 0.0));
  }
  return nodes;
}

// The odometry S_i^-1 S_{i+1} with a systematic drift: 1 % scale, 0.4° yaw, 0.2° pitch a step.
Sim3d Drifted(const Sim3d& relative) {
  const Eigen::Quaterniond drift =
      Eigen::Quaterniond(Eigen::AngleAxisd(0.007, Eigen::Vector3d::UnitZ())) *
      Eigen::Quaterniond(Eigen::AngleAxisd(0.0035, Eigen::Vector3d::UnitY()));
  return relative * Sim3d(1.01, drift, Eigen::Vector3d::Zero());
}

std::vector<Sim3d> Chain(const Sim3d& first, const std::vector<Sim3d>& relatives) {
  std::vector<Sim3d> nodes = {first};
  for (const Sim3d& relative : relatives) nodes.push_back(nodes.back() * relative);
  return nodes;
}

double MaxPositionError(const std::vector<Sim3d>& a, const std::vector<Sim3d>& b) {
  double worst = 0.0;
  for (size_t i = 0; i < a.size(); ++i)
    worst = std::max(worst, (a[i].translation - b[i].translation).norm());
  return worst;
}

TEST(PoseGraph, RecoversTheTruthFromADriftedStart) {
  const std::vector<Sim3d> truth = CircleTruth();
  std::vector<PoseGraphEdge> edges;
  std::vector<Sim3d> drifted_relatives;
  for (int i = 0; i + 1 < kNodes; ++i) {
    edges.push_back({i, i + 1, RelativeSim3(truth[i], truth[i + 1])});
    drifted_relatives.push_back(Drifted(edges.back().from_from_to));
  }
  edges.push_back({kNodes - 1, 0, RelativeSim3(truth[kNodes - 1], truth[0])});
  std::vector<Sim3d> nodes = Chain(truth[0], drifted_relatives);
  ASSERT_GT(MaxPositionError(nodes, truth), 5.0);  // the start is far off

  const PoseGraphSummary summary = OptimizePoseGraph(edges, {0}, PoseGraphOptions(), &nodes);
  ASSERT_TRUE(summary.success) << summary.BriefReport();
  EXPECT_LT(summary.final_cost, 1e-12);
  EXPECT_LT(MaxPositionError(nodes, truth), 1e-5);
  for (int i = 0; i < kNodes; ++i) {
    EXPECT_NEAR(nodes[i].scale, 1.0, 1e-6) << i;
    EXPECT_LT(nodes[i].rotation.angularDistance(truth[i].rotation), 1e-6) << i;
  }
}

TEST(PoseGraph, ALoopEdgeRemovesMostOfASystematicDriftAndCloseTheLoop) {
  const std::vector<Sim3d> truth = CircleTruth();
  std::vector<PoseGraphEdge> edges;
  std::vector<Sim3d> drifted_relatives;
  for (int i = 0; i + 1 < kNodes; ++i) {
    drifted_relatives.push_back(Drifted(RelativeSim3(truth[i], truth[i + 1])));
    edges.push_back({i, i + 1, drifted_relatives.back()});  // the odometry, drift included
  }
  std::vector<Sim3d> nodes = Chain(truth[0], drifted_relatives);
  const double error_before = MaxPositionError(nodes, truth);
  const Sim3d loop_truth = RelativeSim3(truth[kNodes - 1], truth[0]);
  const double gap_before =
      (RelativeSim3(nodes[kNodes - 1], nodes[0]).translation - loop_truth.translation).norm();
  // The loop edge, measured at the revisit, without drift; weighted like ten odometry edges.
  edges.push_back({kNodes - 1, 0, loop_truth, 10.0});

  const PoseGraphSummary summary = OptimizePoseGraph(edges, {0}, PoseGraphOptions(), &nodes);
  ASSERT_TRUE(summary.success) << summary.BriefReport();
  const double error_after = MaxPositionError(nodes, truth);
  const double gap_after =
      (RelativeSim3(nodes[kNodes - 1], nodes[0]).translation - loop_truth.translation).norm();
  EXPECT_LT(error_after, 0.2 * error_before) << error_before << " -> " << error_after;
  EXPECT_LT(gap_after, 0.05 * gap_before) << gap_before << " -> " << gap_after;
  // The scale drift is spread along the loop: the last node's scale comes back near 1.
  EXPECT_LT(std::abs(std::log(nodes[kNodes - 1].scale)), 0.2 * std::log(std::pow(1.01, 35)));
}

TEST(PoseGraph, OptionsCheck) {
  EXPECT_TRUE(PoseGraphOptions().Check().empty());
  PoseGraphOptions options;
  options.scale_weight = 0.0;
  EXPECT_FALSE(options.Check().empty());
}

TEST(PoseGraph, BadOptionsThrowNamingTheField) {
  std::vector<Sim3d> nodes = CircleTruth();
  PoseGraphOptions options;
  options.scale_weight = 0.0;
  const std::vector<PoseGraphEdge> edges = {{0, 1, RelativeSim3(nodes[0], nodes[1])}};
  EXPECT_THROW(OptimizePoseGraph(edges, {0}, options, &nodes), OptionsError);
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { OptimizePoseGraph(edges, {0}, options, &nodes); },
                                          "PoseGraphOptions."));
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { OptimizePoseGraph(edges, {0}, options, &nodes); },
                                          "scale_weight"));
}

}  // namespace
}  // namespace omni
