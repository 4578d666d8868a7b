#pragma once
// Camera models: a pixel <-> a unit bearing in the camera frame (x right, y down, z forward).
// Pixel convention (OpenCV): integer coordinates at pixel centres; the image covers
// [-0.5, width - 0.5) x [-0.5, height - 0.5).
//
// Models and their params (the order of rig.json):
//   pinhole   fx fy cx cy
//   opencv    fx fy cx cy k1 k2 p1 p2 k3         (Brown-Conrady radial-tangential)
//   fisheye   fx fy cx cy k1 k2 k3 k4            (equidistant / Kannala-Brandt, as cv::fisheye)

#include <Eigen/Core>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "calib/pose.h"

namespace omni {

enum class CameraModel { kPinhole, kOpenCV, kFisheye };

std::string_view CameraModelName(CameraModel model);
std::optional<CameraModel> CameraModelFromName(std::string_view name);
int NumCameraParams(CameraModel model);
// "fx fy cx cy k1 k2 p1 p2 k3", for error messages.
std::string_view CameraParamsDescription(CameraModel model);

struct Camera {
  std::string name;
  int width = 0;
  int height = 0;
  CameraModel model = CameraModel::kPinhole;
  std::vector<double> params;
  Rigid3d cam_from_rig;

  // Projects a bearing (any non-zero vector in the camera frame) to a pixel. Returns false when
  // the model cannot image that direction (behind a perspective camera, or outside the region
  // where the distortion is one-to-one). The pixel may still fall outside the image: see
  // IsInImage. d_pixel_d_bearing, when given, receives the analytic 2x3 Jacobian.
  bool Project(const Eigen::Vector3d& bearing, Eigen::Vector2d* pixel,
               Eigen::Matrix<double, 2, 3>* d_pixel_d_bearing = nullptr) const;

  // Unit bearing of a pixel (iterative undistortion). Returns false when the pixel lies outside
  // the region the model maps one-to-one (the iteration does not converge there).
  bool Unproject(const Eigen::Vector2d& pixel, Eigen::Vector3d* bearing) const;

  bool IsInImage(const Eigen::Vector2d& pixel) const {
    return pixel.x() >= -0.5 && pixel.y() >= -0.5 && pixel.x() < width - 0.5 &&
           pixel.y() < height - 0.5;
  }

  double fx() const { return params[0]; }
  double fy() const { return params[1]; }
  double cx() const { return params[2]; }
  double cy() const { return params[3]; }

  // The camera centre in the rig frame.
  Eigen::Vector3d CenterInRig() const { return cam_from_rig.Center(); }

  // Empty when valid, otherwise what is wrong ("params: expected 9 values ..."), naming the
  // field relative to this camera.
  std::string Check() const;
};

}  // namespace omni
