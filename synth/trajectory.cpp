#include "synth/trajectory.h"

#include <cmath>

#include "synth/hash.h"

namespace omni::synth {
namespace {
constexpr double kPi = 3.14159265358979323846;
}

double LoopPath::Length() const {
  return 2.0 * ((x1 - x0) + (y1 - y0)) - 8.0 * radius + 2.0 * kPi * radius;
}

void LoopPath::Evaluate(double s, Eigen::Vector2d* position, Eigen::Vector2d* tangent,
                        double* curvature) const {
  const double length = Length();
  s = std::fmod(s, length);
  if (s < 0) s += length;
  // The loop starts in the middle of the bottom side (y = y0) heading +x; then four
  // (straight, corner) pieces counter-clockwise.
  const double r = radius;
  const double half_bottom = 0.5 * (x1 - x0) - r;
  const double straight[4] = {(y1 - y0) - 2 * r, (x1 - x0) - 2 * r, (y1 - y0) - 2 * r,
                              (x1 - x0) - 2 * r};
  // Corner centres after the first half of the bottom, then right, top, left sides.
  const Eigen::Vector2d centres[4] = {
      {x1 - r, y0 + r}, {x1 - r, y1 - r}, {x0 + r, y1 - r}, {x0 + r, y0 + r}};
  const double arc = 0.5 * kPi * r;
  // Heading of the straight before corner k: 0, 90, 180, 270 degrees.
  double remaining = s;
  if (remaining < half_bottom) {
    *position = {0.5 * (x0 + x1) + remaining, y0};
    *tangent = {1, 0};
    *curvature = 0;
    return;
  }
  remaining -= half_bottom;
  for (int k = 0; k < 4; ++k) {
    const double heading = 0.5 * kPi * k;
    if (remaining < arc) {
      const double angle = heading + remaining / r;  // tangent direction
      *tangent = {std::cos(angle), std::sin(angle)};
      *position = centres[k] + r * Eigen::Vector2d(std::sin(angle), -std::cos(angle));
      *curvature = 1.0 / r;
      return;
    }
    remaining -= arc;
    const double next_heading = heading + 0.5 * kPi;
    const Eigen::Vector2d direction(std::cos(next_heading), std::sin(next_heading));
    const double piece = k < 3 ? straight[k] : half_bottom;
    if (remaining < piece || k == 3) {
      const Eigen::Vector2d start =
          centres[k] + r * Eigen::Vector2d(std::sin(next_heading), -std::cos(next_heading));
      *position = start + remaining * direction;
      *tangent = direction;
      *curvature = 0;
      return;
    }
    remaining -= piece;
  }
}

LoopPath MakeLoopPath(const StreetGrid& streets, const SynthTrajectoryOptions& options) {
  // Counter-clockwise with right-hand traffic: the right lane is on the outside of the loop.
  LoopPath path;
  path.x0 = streets.x_lines[streets.loop_x_first] - options.lane_offset;
  path.x1 = streets.x_lines[streets.loop_x_last] + options.lane_offset;
  path.y0 = streets.y_lines[streets.loop_y_first] - options.lane_offset;
  path.y1 = streets.y_lines[streets.loop_y_last] + options.lane_offset;
  path.radius =
      std::min(options.corner_radius, 0.5 * std::min(path.x1 - path.x0, path.y1 - path.y0) - 0.5);
  return path;
}

Trajectory MakeTrajectory(const StreetGrid& streets, const SynthTrajectoryOptions& options,
                          uint64_t seed) {
  Trajectory trajectory;
  trajectory.path = MakeLoopPath(streets, options);
  trajectory.driven_length = trajectory.path.Length() + options.overlap;
  const int n = options.num_frames;
  const double phase = Uniform(Hash(seed, 0x5BEED), 0, 2 * kPi);
  const double pitch_phase = Uniform(Hash(seed, 0x917C), 0, 2 * kPi);
  const double roll_phase = Uniform(Hash(seed, 0x9011), 0, 2 * kPi);
  const double bounce_phase = Uniform(Hash(seed, 0xB0B), 0, 2 * kPi);
  const double deg = kPi / 180.0;
  for (int k = 0; k < n; ++k) {
    // s(u) = L (u + e (sin(2 pi m u + phase) - sin(phase)) / (2 pi m)): monotone (ds/du =
    // L (1 + e cos(...)) > 0), s(0) = 0 and s(1) = L.
    const double u = n > 1 ? static_cast<double>(k) / (n - 1) : 0.0;
    double s = u;
    if (options.speed_cycles > 0) {
      const double w = 2 * kPi * options.speed_cycles;
      s += options.speed_variation * (std::sin(w * u + phase) - std::sin(phase)) / w;
    }
    s *= trajectory.driven_length;
    Eigen::Vector2d position, tangent;
    double curvature;
    trajectory.path.Evaluate(s, &position, &tangent, &curvature);
    const double t = k / options.frame_rate;
    const double omega = 2 * kPi / options.suspension_period;
    const double pitch = options.pitch_amplitude_deg * deg * std::sin(omega * t + pitch_phase);
    // Roll: a slow oscillation, plus leaning out of the turns.
    const double roll = options.roll_amplitude_deg * deg *
                        (0.5 * std::sin(0.73 * omega * t + roll_phase) +
                         0.5 * std::min(1.0, curvature * options.corner_radius));
    const double bounce = options.bounce_amplitude * std::sin(1.31 * omega * t + bounce_phase);
    const double yaw = std::atan2(tangent.y(), tangent.x());
    const Eigen::Quaterniond world_from_rig_rotation =
        Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
        Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
        Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX());
    trajectory.arc_length.push_back(s);
    trajectory.world_from_rig.emplace_back(
        world_from_rig_rotation.normalized(),
        Eigen::Vector3d(position.x(), position.y(), options.rig_height + bounce));
  }
  return trajectory;
}

}  // namespace omni::synth
