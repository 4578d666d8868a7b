#pragma once
// The drive's trajectory: a closed loop (a rounded rectangle in the right lane around the loop
// blocks), driven counter-clockwise a little more than once, with a speed that varies smoothly
// and small suspension motion (roll, pitch, bounce). Rig frame: x forward, y left, z up.

#include <vector>

#include "calib/pose.h"
#include "synth/city.h"
#include "synth/synth_options.h"

namespace omni::synth {

struct LoopPath {
  double x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // the rectangle the loop's straight parts lie on
  double radius = 0;                      // of the rounded corners
  double Length() const;
  // Position (z = 0) and unit tangent at arc length s (taken modulo the length), and the signed
  // curvature (positive turning left).
  void Evaluate(double s, Eigen::Vector2d* position, Eigen::Vector2d* tangent,
                double* curvature) const;
};

LoopPath MakeLoopPath(const StreetGrid& streets, const SynthTrajectoryOptions& options);

struct Trajectory {
  LoopPath path;
  double driven_length = 0;        // loop length + overlap
  std::vector<double> arc_length;  // per frame
  std::vector<Rigid3d> world_from_rig;
};

Trajectory MakeTrajectory(const StreetGrid& streets, const SynthTrajectoryOptions& options,
                          uint64_t seed);

}  // namespace omni::synth
