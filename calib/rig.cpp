#include "calib/rig.h"

#include <algorithm>
#include <sstream>

namespace omni {

Eigen::Vector3d Rig::CentralCenterInRig() const {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  if (cameras.empty()) return sum;
  for (const Camera& camera : cameras) sum += camera.CenterInRig();
  return sum / static_cast<double>(cameras.size());
}

double Rig::MaxCenterOffset() const {
  const Eigen::Vector3d center = CentralCenterInRig();
  double offset = 0.0;
  for (const Camera& camera : cameras)
    offset = std::max(offset, (camera.CenterInRig() - center).norm());
  return offset;
}

double Rig::FinestPixelAngle() const {
  double focal = 0.0;
  for (const Camera& camera : cameras) focal = std::max({focal, camera.fx(), camera.fy()});
  return focal > 0.0 ? 1.0 / focal : 0.0;
}

std::optional<size_t> Rig::FindCamera(const std::string& camera_name) const {
  for (size_t i = 0; i < cameras.size(); ++i)
    if (cameras[i].name == camera_name) return i;
  return std::nullopt;
}

std::string Rig::Check() const {
  if (cameras.empty()) return "cameras: at least one camera is needed, got 0";
  std::ostringstream problems;
  auto add = [&problems](const std::string& problem) {
    if (problems.tellp() > 0) problems << "; ";
    problems << problem;
  };
  for (size_t i = 0; i < cameras.size(); ++i) {
    const std::string prefix = "cameras[" + std::to_string(i) + "] (" + cameras[i].name + "): ";
    const std::string camera_problem = cameras[i].Check();
    if (!camera_problem.empty()) add(prefix + camera_problem);
    const std::optional<size_t> first = FindCamera(cameras[i].name);
    if (first && *first < i)
      add(prefix + "name: duplicate of cameras[" + std::to_string(*first) + "]");
  }
  return problems.str();
}

}  // namespace omni
