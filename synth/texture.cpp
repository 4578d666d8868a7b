#include "synth/texture.h"

#include <algorithm>
#include <cmath>

#include "synth/hash.h"

namespace omni::synth {
namespace {

double Clamp01(double x) { return std::min(1.0, std::max(0.0, x)); }

// How much of a detail of size `size` survives a footprint: 1 when much larger, 0 at or below
// the footprint.
double Keep(double size, double footprint) { return Clamp01(size / footprint - 1.0); }

// Box-filtered indicator of [a, b] at x over a footprint w.
double Coverage(double x, double a, double b, double w) {
  return Clamp01((x - a) / w + 0.5) * Clamp01((b - x) / w + 0.5);
}

int64_t Cell(double x) { return static_cast<int64_t>(std::floor(x)); }

// Value noise on a lattice of step `scale` metres, in [-1, 1], smooth (quintic fade).
double ValueNoise(uint64_t seed, double u, double v, double scale) {
  const double x = u / scale, y = v / scale;
  const int64_t i = Cell(x), j = Cell(y);
  const double fx = x - i, fy = y - j;
  auto fade = [](double t) { return t * t * t * (t * (t * 6 - 15) + 10); };
  auto value = [&](int64_t a, int64_t b) { return 2.0 * Uniform(CellHash(seed, a, b)) - 1.0; };
  const double sx = fade(fx), sy = fade(fy);
  const double top = value(i, j) + sx * (value(i + 1, j) - value(i, j));
  const double bottom = value(i, j + 1) + sx * (value(i + 1, j + 1) - value(i, j + 1));
  return top + sy * (bottom - top);
}

double Noise(uint64_t seed, double u, double v, double scale, double footprint) {
  const double keep = Keep(scale, 2.0 * footprint);
  return keep > 0 ? keep * ValueNoise(seed, u, v, scale) : 0.0;
}

// A layer of random rectangles: the plane is cut into cells of `cell` metres; a cell holds,
// with probability `probability`, one rectangle covering a random part of it, brighter or darker
// by up to `amplitude`. Returns the change of albedo.
double Rectangles(uint64_t seed, double u, double v, double cell, double probability,
                  double amplitude, double footprint) {
  const double keep = Keep(cell, 1.5 * footprint);
  if (keep <= 0) return 0.0;
  const int64_t i = Cell(u / cell), j = Cell(v / cell);
  const uint64_t h = CellHash(seed, i, j);
  if (Uniform(h) >= probability) return 0.0;
  const uint64_t g = Mix64(h);
  const double x0 = cell * (i + 0.4 * Field16(g, 0));
  const double x1 = cell * (i + 0.6 + 0.4 * Field16(g, 1));
  const double y0 = cell * (j + 0.4 * Field16(g, 2));
  const double y1 = cell * (j + 0.6 + 0.4 * Field16(g, 3));
  // Mostly strong steps, of either sign: corners real streets have (signs, posters, stains).
  const double magnitude = amplitude * (0.7 + 0.3 * Field16(h, 1));
  const double delta = (h & 1) ? magnitude : -magnitude;
  return keep * delta * Coverage(u, x0, x1, footprint) * Coverage(v, y0, y1, footprint);
}

// Tiles of size `size` with a random tone each and darker joints of width `joint`.
double Tiles(uint64_t seed, double u, double v, double size, double tone, double joint,
             double footprint) {
  const double keep = Keep(size, 2.0 * footprint);
  if (keep <= 0) return 0.0;
  const int64_t i = Cell(u / size), j = Cell(v / size);
  const double fu = u - i * size, fv = v - j * size;
  double value = tone * (2.0 * Uniform(CellHash(seed, i, j)) - 1.0);
  const double w = std::max(footprint, joint);
  const double in_joint = 1.0 - Coverage(fu, joint, size, w) * Coverage(fv, joint, size, w);
  value -= 0.15 * (joint / w) * in_joint;
  return keep * value;
}

// Road markings: dashed centre lines and zebra crossings before the intersections.
double RoadMarking(const StreetGrid& streets, uint64_t seed, double x, double y, double footprint) {
  auto nearest = [](const std::vector<double>& lines, double x, int* index) {
    auto it = std::lower_bound(lines.begin(), lines.end(), x);
    int k = static_cast<int>(it - lines.begin());
    if (k == static_cast<int>(lines.size()) || (k > 0 && x - lines[k - 1] < lines[k] - x)) --k;
    *index = k;
    return x - lines[k];
  };
  int ix, iy;
  const double dx = nearest(streets.x_lines, x, &ix), dy = nearest(streets.y_lines, y, &iy);
  const double rhw = streets.road_half_width;
  double paint = 0.0;
  // A street along x has lateral offset dy and meets crossings at distance |dx|; and vice versa.
  for (int axis = 0; axis < 2; ++axis) {
    const double lateral = axis == 0 ? dy : dx;
    const double to_crossing = std::abs(axis == 0 ? dx : dy);
    const double along = axis == 0 ? x : y;
    const uint64_t street = Hash(seed, axis, axis == 0 ? iy : ix);
    if (std::abs(lateral) > rhw || to_crossing < rhw) continue;
    if (to_crossing > rhw + 0.8 && to_crossing < rhw + 3.8) {  // zebra
      const double stripe = std::fmod(lateral + rhw + 10.0, 1.0);
      paint = std::max(paint, Coverage(stripe, 0.25, 0.75, footprint) *
                                  Coverage(std::abs(lateral), -1.0, rhw - 0.5, footprint));
    } else if (to_crossing > rhw + 5.0) {  // dashes of varying length
      const double period = 6.0;
      const int64_t dash = Cell(along / period);
      const double length = 2.0 + 2.5 * Uniform(Hash(street, dash));
      const double f = along - dash * period;
      paint = std::max(paint, Coverage(f, 0.5, 0.5 + length, footprint) *
                                  Coverage(lateral, -0.075, 0.075, footprint));
    }
  }
  return paint;
}

}  // namespace

double Albedo(const StreetGrid& streets, uint64_t seed, Surface surface, uint32_t object,
              const Eigen::Vector3d& p, const Eigen::Vector3d& n, double footprint) {
  // Surface coordinates: horizontal faces use (x, y); vertical ones (along, z); others the
  // plane of their dominant axis.
  double u, v;
  if (std::abs(n.z()) > 0.7) {
    u = p.x();
    v = p.y();
  } else if (std::abs(n.z()) < 0.3) {
    const double h = std::hypot(n.x(), n.y());
    u = (-n.y() * p.x() + n.x() * p.y()) / h;
    v = p.z();
  } else {
    u = std::abs(n.x()) > std::abs(n.y()) ? p.y() : p.x();
    v = p.z();
  }
  const uint64_t s = Hash(seed, (static_cast<uint64_t>(surface) << 32) | object);
  const double tone = Uniform(Mix64(s));
  double a = 0;
  switch (surface) {
    case Surface::kRoad: {
      a = 0.3 + 0.05 * Noise(s + 1, u, v, 3.0, footprint);
      a += Rectangles(s + 2, u, v, 2.7, 0.3, 0.08, footprint);    // patches
      a += Rectangles(s + 3, u, v, 0.55, 0.4, 0.12, footprint);   // stains
      a += Rectangles(s + 4, u, v, 0.17, 0.55, 0.25, footprint);  // speckle
      a += Rectangles(s + 5, u, v, 0.07, 0.45, 0.22, footprint);
      const double paint = RoadMarking(streets, seed, p.x(), p.y(), footprint);
      a = a + paint * (0.6 - a);
      break;
    }
    case Surface::kSidewalk:
      a = 0.5 + Tiles(s + 1, u, v, 0.5, 0.12, 0.015, footprint);
      a += 0.05 * Noise(s + 2, u, v, 2.0, footprint);
      a += Rectangles(s + 3, u, v, 1.3, 0.3, 0.1, footprint);
      a += Rectangles(s + 4, u, v, 0.11, 0.5, 0.25, footprint);
      break;
    case Surface::kKerb:
      a = 0.6 + Tiles(s + 1, u, 4.0 * v, 1.0, 0.15, 0.01, footprint);
      break;
    case Surface::kWall:
    case Surface::kReveal: {
      a = 0.3 + 0.35 * tone + 0.06 * Noise(s + 1, u, v, 2.5, footprint);
      a += 0.04 * Noise(s + 2, u, v, 0.6, footprint);
      a += Rectangles(s + 3, u, v, 1.7, 0.45, 0.12, footprint);
      a += Rectangles(s + 4, u + 0.3, v + 0.2, 0.6, 0.5, 0.18, footprint);
      a += Rectangles(s + 5, u, v, 0.23, 0.55, 0.28, footprint);
      a += Rectangles(s + 6, u + 0.05, v, 0.09, 0.5, 0.25, footprint);
      if (surface == Surface::kReveal) a *= 0.85;
      break;
    }
    case Surface::kGlass:
      a = 0.12 + 0.12 * tone + 0.06 * Noise(s + 1, u, v, 1.5, footprint);
      a += Rectangles(s + 2, u, v, 0.7, 0.6, 0.15, footprint);
      a += Rectangles(s + 3, u, v, 0.25, 0.55, 0.18, footprint);
      a += Rectangles(s + 4, u, v, 0.09, 0.5, 0.15, footprint);
      break;
    case Surface::kDoor:
      a = 0.22 + 0.25 * tone + Rectangles(s + 1, u, v, 0.45, 0.8, 0.25, footprint);
      break;
    case Surface::kRoof:
      a = 0.35 + 0.2 * tone + 0.08 * Noise(s + 1, u, v, 1.5, footprint) +
          Rectangles(s + 2, u, v, 1.2, 0.5, 0.25, footprint);
      break;
    case Surface::kTrim:
      a = 0.6 + 0.25 * tone + 0.05 * Noise(s + 1, u, v, 0.8, footprint) +
          Rectangles(s + 2, u, v, 0.35, 0.5, 0.2, footprint);
      break;
    case Surface::kPole:
      a = 0.25 + 0.1 * tone + Rectangles(s + 1, u, v, 0.3, 0.5, 0.1, footprint);
      break;
    case Surface::kTrunk:
      a = 0.22 + 0.06 * Noise(s + 1, u, v, 0.2, footprint) +
          Rectangles(s + 2, u, v, 0.15, 0.5, 0.08, footprint);
      break;
    case Surface::kCrown: {
      // Leaves: 3D-ish blotches from two projections.
      a = 0.32 + 0.1 * tone + Rectangles(s + 1, u, v, 0.35, 0.7, 0.25, footprint) +
          Rectangles(s + 2, p.x() + p.y(), p.z(), 0.17, 0.6, 0.15, footprint);
      break;
    }
    case Surface::kCar:
      a = 0.15 + 0.6 * tone + Rectangles(s + 1, u, v, 0.6, 0.6, 0.2, footprint);
      break;
  }
  return Clamp01(a);
}

}  // namespace omni::synth
