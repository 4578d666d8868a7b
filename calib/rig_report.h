#pragma once
// What `omnisculpt calib show` prints: each camera's field of view, and how much neighbouring
// cameras overlap.

#include <string>
#include <vector>

#include "calib/rig.h"

namespace omni {

struct CameraFieldOfView {
  double horizontal_deg = 0.0;  // between the bearings of the left and right edge midpoints
  double vertical_deg = 0.0;    // between the top and bottom edge midpoints
  double diagonal_deg = 0.0;    // between opposite corners
};

CameraFieldOfView ComputeFieldOfView(const Camera& camera);

// Share of camera `from`'s pixels (sampled on a grid of about samples x samples) whose viewing
// direction, at infinity, is also imaged by camera `to`. The offsets between the centres are
// neglected, as they are against distant points.
double ComputeViewOverlap(const Rig& rig, size_t from, size_t to, int samples = 64);

// A human-readable description of the rig: cameras, models, sizes, centres, viewing
// directions in the rig frame, fields of view, and the overlaps above zero.
std::string DescribeRig(const Rig& rig);

}  // namespace omni
