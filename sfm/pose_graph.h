#pragma once
// A similarity pose graph (docs/design.md §9): after a loop closure, the keyframe poses are
// corrected as Sim(3) nodes world_from_keyframe (rotation, translation and scale, so that the
// scale drift of a monocular-like SfM is corrected too, Strasdat et al., RSS 2010) under
// relative Sim(3) edges: the odometry edges between consecutive keyframes measured on the
// drifted map, and loop edges measured at the revisit. Ceres stays inside the .cpp.

#include <string>
#include <vector>

#include "calib/pose.h"

namespace omni {

struct PoseGraphOptions {
  int max_iterations = 100;
  double function_tolerance = 1e-12;
  // Weights (inverse standard deviations) of an edge's residual blocks, relative to each
  // other: translation (in units of the `from` node), rotation (radians), log scale.
  double translation_weight = 1.0;
  double rotation_weight = 1.0;
  double scale_weight = 1.0;

  std::string Check() const;
};

struct PoseGraphEdge {
  int from = 0, to = 0;  // node indices
  Sim3d from_from_to;    // measured: S_from^-1 * S_to
  double weight = 1.0;   // multiplies the edge's residual (a loop edge can count more)
};

struct PoseGraphSummary {
  bool success = false;
  int num_iterations = 0;
  double initial_cost = 0.0, final_cost = 0.0;
  std::string BriefReport() const;
};

// Refines the nodes (world_from_node) in place; the nodes listed in `fixed` do not move (at
// least one, to fix the gauge). Asserts valid indices and options.
PoseGraphSummary OptimizePoseGraph(const std::vector<PoseGraphEdge>& edges,
                                   const std::vector<int>& fixed, const PoseGraphOptions& options,
                                   std::vector<Sim3d>* world_from_node);

// The edge measured between two current nodes: S_from^-1 * S_to.
Sim3d RelativeSim3(const Sim3d& world_from_from, const Sim3d& world_from_to);

}  // namespace omni
