#pragma once
// Synthetic bearing problems with known poses, shared by the sfm tests and benchmarks (COLMAP's
// scene/synthetic.h habit): a rig, a trajectory of world_from_rig poses, world points, and the
// bearings each camera of each frame sees, with angular noise and outliers.

#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"

namespace omni {

struct SyntheticSceneOptions {
  int num_points = 200;
  // Points are seeded along a random bearing of a random camera of frame 0, at a depth drawn
  // uniformly in [min_depth, max_depth] (metres).
  double min_depth = 2.0;
  double max_depth = 10.0;
  double half_fov = 1.0;           // each camera sees a cone of this half-angle (radians)
  double noise = 0.0;              // standard deviation of the angular noise (radians)
  double outlier_ratio = 0.0;      // share of observations replaced by a wrong bearing
  double min_outlier_angle = 0.1;  // an outlier bearing is at least this far from the truth
  uint32_t seed = 1;

  std::string Check() const;
};

struct SyntheticObservation {
  int frame = 0;
  int camera = 0;
  int point = 0;
  Eigen::Vector3d bearing = Eigen::Vector3d::UnitZ();  // unit, in the camera frame
  bool is_outlier = false;
};

struct SyntheticScene {
  Rig rig;
  std::vector<Rigid3d> world_from_rig;  // one per frame
  std::vector<Eigen::Vector3d> points_in_world;
  std::vector<SyntheticObservation> observations;  // sorted by frame, then camera, then point
};

// A ring of num_side_cameras cameras looking outwards horizontally at distance radius from the
// rig origin, plus optionally one looking up (at height radius). Rig frame: z up; camera 0
// looks along +x. Pinhole 640x480 intrinsics with f = 320 (only for completeness: the
// synthetic problems work on bearings).
Rig MakeSyntheticRingRig(int num_side_cameras, bool up_camera, double radius);

// Observes points seeded from frame 0 in every camera of every frame whose cone contains them.
SyntheticScene MakeSyntheticScene(const Rig& rig, const std::vector<Rigid3d>& world_from_rig,
                                  const SyntheticSceneOptions& options);

// Correspondences between two frames: for each point seen in both, its first observation in
// each frame (the camera of that observation in cameras1/cameras2).
struct SyntheticMatches {
  std::vector<Eigen::Vector3d> bearings1, bearings2;
  std::vector<int> cameras1, cameras2;
  std::vector<int> points;
  std::vector<char> is_outlier;  // either observation is an outlier
};
SyntheticMatches MatchSyntheticFrames(const SyntheticScene& scene, int frame1, int frame2);

// A grey 8-bit image of random soft-edged rotated rectangles on a mid-grey background, corners
// everywhere: I(x, y) = T(x − shift.x, y − shift.y), so that two calls with different shifts
// give the same texture moved by an exact (possibly subpixel) amount. Rectangle edges are
// blurred over about a pixel, so the shift is well defined below the pixel.
cv::Mat MakeSyntheticTexture(int width, int height, const Eigen::Vector2d& shift, int num_shapes,
                             uint32_t seed);

// Angle of the rotation between two orientations (radians).
double RotationAngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b);
// Angle between two non-zero vectors (radians).
double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b);

}  // namespace omni
