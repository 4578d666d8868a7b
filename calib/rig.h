#pragma once
// A rig: any number of cameras (1 and up), each with its cam_from_rig. The rig frame is whatever
// those transforms define (docs/design.md §5). In central mode the SfM treats the rig as one camera
// whose single centre is the mean of the camera centres (the paper's approximation).

#include <optional>
#include <string>
#include <vector>

#include "calib/camera.h"

namespace omni {

struct Rig {
  std::string name;
  bool central = true;
  std::vector<Camera> cameras;

  size_t NumCameras() const { return cameras.size(); }
  // Mean of the camera centres, in the rig frame (the central approximation's single centre).
  Eigen::Vector3d CentralCenterInRig() const;
  // Largest distance from a camera centre to CentralCenterInRig(): how wrong the central
  // approximation is, to compare with the scene depth.
  double MaxCenterOffset() const;
  // The angle one pixel spans at the centre of the finest camera (radians; 1 / the largest
  // focal length in pixels).
  double FinestPixelAngle() const;
  std::optional<size_t> FindCamera(const std::string& camera_name) const;
  // Empty when valid (at least one camera, unique names, every camera valid).
  std::string Check() const;
};

}  // namespace omni
