#pragma once
// Procedural textures of the synthetic city: albedo in [0, 1] at a surface point, a pure
// function of the seed, the object and the point (so textures are continuous across triangles
// and identical from every view). Rich in corners (random rectangles at several scales, tiles,
// road markings), not periodic, and band-limited by the pixel footprint so that one ray per
// pixel does not alias.

#include <Eigen/Core>
#include <cstdint>

#include "synth/city.h"

namespace omni::synth {

// `footprint`: the size on the surface of one pixel, metres; detail finer than it fades to its
// mean.
double Albedo(const StreetGrid& streets, uint64_t seed, Surface surface, uint32_t object,
              const Eigen::Vector3d& point, const Eigen::Vector3d& normal, double footprint);

}  // namespace omni::synth
