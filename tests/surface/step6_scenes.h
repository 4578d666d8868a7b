#pragma once
// Synthetic keyframe streams for the step-6 tests (genus refinement, smoothing): a street
// between two walls and the inside of a sphere, with Gaussian noise on the points.

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "surface/sculptor.h"

namespace omni::testing {

// Street along x: walls at y = ±half_width up to height, ground z = 0, keyframe t at
// (t, 0, 2) (s = 1); each point has rays to every second keyframe of the last 8 within 12 m.
inline std::vector<SurfaceKeyframe> NoisyStreet(int num_keyframes, int points_per_keyframe,
                                                double noise, uint32_t seed,
                                                double half_width = 8.0, double height = 10.0) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> gauss(0.0, noise);
  auto centre = [](int t) { return Eigen::Vector3d(t, 0.0, 2.0); };
  std::vector<SurfaceKeyframe> drive;
  uint32_t next_point = 0;
  for (int t = 0; t < num_keyframes; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(t);
    kf.centre = centre(t);
    for (int i = 0; i < points_per_keyframe; ++i) {
      SurfacePoint p;
      p.id = PointId(next_point++);
      const double x = kf.centre.x() - 3.0 + 8.0 * u(rng);
      const double side = u(rng);
      if (side < 0.35) {
        p.position = Eigen::Vector3d(x, -half_width, height * u(rng));
      } else if (side < 0.7) {
        p.position = Eigen::Vector3d(x, half_width, height * u(rng));
      } else {
        p.position = Eigen::Vector3d(x, half_width * (2.0 * u(rng) - 1.0), 0.0);
      }
      if (noise > 0.0) p.position += Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
      for (int k = std::max(0, t - 8); k <= t; k += 2) {
        if ((centre(k) - p.position).norm() <= 12.0) p.rays.push_back({KeyframeId(k), centre(k)});
      }
      if (p.rays.empty() || p.rays.back().keyframe != kf.id) p.rays.push_back({kf.id, kf.centre});
      kf.points.push_back(p);
    }
    drive.push_back(kf);
  }
  return drive;
}

// Distance of q to the street's walls and ground (the nearest of the three planes).
inline double StreetDistance(const Eigen::Vector3d& q, double half_width = 8.0) {
  return std::min({std::abs(q.y() - half_width), std::abs(q.y() + half_width), std::abs(q.z())});
}

// Keyframes on a circle of radius 2 inside a sphere of radius `radius` centred at the origin,
// points uniform on the sphere near the keyframe, with rays to the last few keyframes.
inline std::vector<SurfaceKeyframe> NoisySphere(int num_keyframes, int points_per_keyframe,
                                                double radius, double noise, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> gauss(0.0, 1.0), noise_d(0.0, noise);
  auto centre = [](int t) {
    const double a = 0.5 * t;  // 1 m apart on a circle of radius 2 (chord ≈ 0.99 m)
    return Eigen::Vector3d(2.0 * std::cos(a), 2.0 * std::sin(a), 0.0);
  };
  std::vector<SurfaceKeyframe> drive;
  uint32_t next_point = 0;
  for (int t = 0; t < num_keyframes; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(t);
    kf.centre = centre(t);
    for (int i = 0; i < points_per_keyframe; ++i) {
      SurfacePoint p;
      p.id = PointId(next_point++);
      Eigen::Vector3d d(gauss(rng), gauss(rng), gauss(rng));
      p.position = radius * d.normalized();
      if (noise > 0.0) p.position += Eigen::Vector3d(noise_d(rng), noise_d(rng), noise_d(rng));
      for (int k = std::max(0, t - 6); k <= t; k += 2) p.rays.push_back({KeyframeId(k), centre(k)});
      kf.points.push_back(p);
    }
    drive.push_back(kf);
  }
  return drive;
}

}  // namespace omni::testing
