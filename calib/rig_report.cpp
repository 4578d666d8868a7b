#include "calib/rig_report.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <sstream>

namespace omni {
namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

// Angle between the bearings of two pixels, degrees; NaN when either does not unproject.
double AngleBetweenPixels(const Camera& camera, const Eigen::Vector2d& a,
                          const Eigen::Vector2d& b) {
  Eigen::Vector3d bearing_a, bearing_b;
  if (!camera.Unproject(a, &bearing_a) || !camera.Unproject(b, &bearing_b)) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  return std::atan2(bearing_a.cross(bearing_b).norm(), bearing_a.dot(bearing_b)) * kRadToDeg;
}

// Values printed with 3 decimals; those that would print as -0.000 print as 0.000.
double Clean(double value) { return std::abs(value) < 5e-4 ? 0.0 : value; }

std::string Format(const char* format, double a, double b, double c) {
  char buffer[128];
  std::snprintf(buffer, sizeof(buffer), format, Clean(a), Clean(b), Clean(c));
  return buffer;
}

std::string FormatAngle(double degrees) {
  if (!std::isfinite(degrees)) return "n/a";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.1f", degrees);
  return buffer;
}

}  // namespace

CameraFieldOfView ComputeFieldOfView(const Camera& camera) {
  // The image covers [-0.5, width - 0.5) x [-0.5, height - 0.5) (pixel centres at integers),
  // so its edges are at -0.5 and width - 0.5, its middle at (width - 1) / 2.
  const double left = -0.5, right = camera.width - 0.5;
  const double top = -0.5, bottom = camera.height - 0.5;
  const double middle_u = (camera.width - 1) / 2.0, middle_v = (camera.height - 1) / 2.0;
  CameraFieldOfView fov;
  fov.horizontal_deg = AngleBetweenPixels(camera, {left, middle_v}, {right, middle_v});
  fov.vertical_deg = AngleBetweenPixels(camera, {middle_u, top}, {middle_u, bottom});
  fov.diagonal_deg = std::max(AngleBetweenPixels(camera, {left, top}, {right, bottom}),
                              AngleBetweenPixels(camera, {right, top}, {left, bottom}));
  return fov;
}

double ComputeViewOverlap(const Rig& rig, size_t from, size_t to, int samples) {
  const Camera& source = rig.cameras.at(from);
  const Camera& target = rig.cameras.at(to);
  samples = std::max(samples, 1);
  // to_from_from, rotation only: directions at infinity do not see the centres' offsets.
  const Eigen::Quaterniond to_from_from =
      target.cam_from_rig.rotation * source.cam_from_rig.rotation.conjugate();
  int sampled = 0, seen = 0;
  for (int row = 0; row < samples; ++row) {
    for (int col = 0; col < samples; ++col) {
      // Centres of a samples x samples grid of cells over the image.
      const Eigen::Vector2d pixel(-0.5 + (col + 0.5) * source.width / samples,
                                  -0.5 + (row + 0.5) * source.height / samples);
      Eigen::Vector3d bearing;
      if (!source.Unproject(pixel, &bearing)) continue;
      ++sampled;
      Eigen::Vector2d projected;
      if (target.Project(to_from_from * bearing, &projected) && target.IsInImage(projected)) {
        ++seen;
      }
    }
  }
  return sampled > 0 ? static_cast<double>(seen) / sampled : 0.0;
}

std::string DescribeRig(const Rig& rig) {
  std::ostringstream out;
  out << "rig \"" << rig.name << "\": " << rig.NumCameras() << " camera"
      << (rig.NumCameras() == 1 ? "" : "s") << "\n";

  size_t name_width = 4;
  for (const Camera& camera : rig.cameras) name_width = std::max(name_width, camera.name.size());
  auto pad = [](const std::string& text, size_t width) {
    return text.size() >= width ? text : text + std::string(width - text.size(), ' ');
  };
  auto right = [](const std::string& text, size_t width) {
    return text.size() >= width ? text : std::string(width - text.size(), ' ') + text;
  };

  out << pad("name", name_width) << "  " << pad("model", 7) << "  " << pad("size", 9) << "  "
      << right("fx", 8) << " " << right("fy", 8) << " " << right("cx", 8) << " " << right("cy", 8)
      << "  " << pad("centre in rig (m)", 24) << "  " << pad("viewing direction (rig)", 24) << "  "
      << right("hfov", 6) << " " << right("vfov", 6) << " " << right("diag", 6) << " (deg)\n";
  for (const Camera& camera : rig.cameras) {
    const Eigen::Vector3d centre = camera.CenterInRig();
    const Eigen::Vector3d direction =
        camera.cam_from_rig.rotation.conjugate() * Eigen::Vector3d::UnitZ();
    const CameraFieldOfView fov = ComputeFieldOfView(camera);
    char numbers[64];
    std::snprintf(numbers, sizeof(numbers), "%8.2f %8.2f %8.2f %8.2f", camera.params.at(0),
                  camera.params.at(1), camera.params.at(2), camera.params.at(3));
    out << pad(camera.name, name_width) << "  "
        << pad(std::string(CameraModelName(camera.model)), 7) << "  "
        << pad(std::to_string(camera.width) + "x" + std::to_string(camera.height), 9) << "  "
        << numbers << "  "
        << pad(Format("%7.3f %7.3f %7.3f", centre.x(), centre.y(), centre.z()), 24) << "  "
        << pad(Format("%7.3f %7.3f %7.3f", direction.x(), direction.y(), direction.z()), 24) << "  "
        << right(FormatAngle(fov.horizontal_deg), 6) << " "
        << right(FormatAngle(fov.vertical_deg), 6) << " " << right(FormatAngle(fov.diagonal_deg), 6)
        << "\n";
    if (camera.params.size() > 4) {
      out << pad("", name_width) << "  distortion:";
      for (size_t i = 4; i < camera.params.size(); ++i) out << " " << camera.params[i];
      out << "\n";
    }
  }

  const Eigen::Vector3d single_centre = rig.CentralCenterInRig();
  char central[160];
  std::snprintf(central, sizeof(central),
                "central: %s (single centre %.3f %.3f %.3f m in the rig frame; max centre "
                "offset %.3f m)\n",
                rig.central ? "yes" : "no", Clean(single_centre.x()), Clean(single_centre.y()),
                Clean(single_centre.z()), rig.MaxCenterOffset());
  out << central;

  out << "overlapping views (share of each camera's pixels whose direction the other also "
         "images):\n";
  bool any = false;
  for (size_t i = 0; i < rig.NumCameras(); ++i) {
    for (size_t j = i + 1; j < rig.NumCameras(); ++j) {
      const double i_in_j = ComputeViewOverlap(rig, i, j);
      const double j_in_i = ComputeViewOverlap(rig, j, i);
      if (i_in_j <= 0.0 && j_in_i <= 0.0) continue;
      any = true;
      char line[256];
      std::snprintf(line, sizeof(line), "  %s / %s: %.1f %% of %s, %.1f %% of %s\n",
                    rig.cameras[i].name.c_str(), rig.cameras[j].name.c_str(), 100.0 * i_in_j,
                    rig.cameras[i].name.c_str(), 100.0 * j_in_i, rig.cameras[j].name.c_str());
      out << line;
    }
  }
  if (!any) out << "  none\n";
  return out.str();
}

}  // namespace omni
