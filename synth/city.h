#pragma once
// The procedural city of a synthetic drive: ground, raised blocks with kerbs and sidewalks,
// buildings with relief facades (recessed windows and doors, balconies, cornices), poles, trees
// and parked cars. Every triangle carries the surface it belongs to, for the textures.

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "calib/ply.h"
#include "synth/synth_options.h"

namespace omni::synth {

enum class Surface : uint8_t {
  kRoad,
  kSidewalk,
  kKerb,
  kWall,
  kReveal,  // the sides of a window or door recess
  kGlass,
  kDoor,
  kRoof,
  kTrim,  // cornices, balconies, railings
  kPole,
  kTrunk,
  kCrown,
  kCar,
};

// The surfaces' names, in the enum's order ("road", "sidewalk", ..., "car"): the labels of the
// ground truth's triangles (gt/mesh.ply's face property label, gt/scene.json "mesh_labels").
const std::vector<std::string>& SurfaceNames();

// The street network, for the road markings and the trajectory.
struct StreetGrid {
  std::vector<double> x_lines;  // centre lines of the streets parallel to y, increasing
  std::vector<double> y_lines;  // centre lines of the streets parallel to x, increasing
  double road_half_width = 0.0;
  // The loop drives around the blocks between these centre lines.
  int loop_x_first = 0, loop_x_last = 0, loop_y_first = 0, loop_y_last = 0;
};

struct CityScene {
  // Vertices are float-representable doubles, so that the binary PLY (float coordinates) holds
  // exactly the rendered triangles. Triangles face the free space (counter-clockwise from there).
  TriangleMesh mesh;              // its labels: the surfaces, as numbers
  std::vector<Surface> surfaces;  // per triangle
  std::vector<uint32_t> objects;  // per triangle: which building, tree, car... (texture seed)
  std::vector<Eigen::Vector3d> normals;  // per triangle, unit, outward
  StreetGrid streets;
  int num_buildings = 0, num_poles = 0, num_trees = 0, num_cars = 0;
};

CityScene BuildCity(const SynthCityOptions& options, uint64_t seed);

}  // namespace omni::synth
