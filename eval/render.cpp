#include "eval/render.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <opencv2/imgcodecs.hpp>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "eval/surface_eval.h"

namespace omni {
namespace {

// Two unit horizontal axes (a, b) with a × b = up.
void HorizontalAxes(const Eigen::Vector3d& up, Eigen::Vector3d* a, Eigen::Vector3d* b) {
  const Eigen::Vector3d seed =
      std::abs(up.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  *a = (seed - seed.dot(up) * up).normalized();
  *b = up.cross(*a);
}

Eigen::Vector3d HueToRgb(double hue) {  // hue in [0, 1), full saturation and value
  const double h = 6.0 * (hue - std::floor(hue));
  const double x = 1.0 - std::abs(std::fmod(h, 2.0) - 1.0);
  switch (static_cast<int>(h)) {
    case 0:
      return {1, x, 0};
    case 1:
      return {x, 1, 0};
    case 2:
      return {0, 1, x};
    case 3:
      return {0, x, 1};
    case 4:
      return {x, 0, 1};
    default:
      return {1, 0, x};
  }
}

void SetPixel(cv::Mat* image, int row, int col, const Eigen::Vector3d& rgb) {
  auto to_byte = [](double v) {
    return static_cast<uint8_t>(std::clamp(std::lround(255.0 * v), 0L, 255L));
  };
  image->at<cv::Vec3b>(row, col) = cv::Vec3b(to_byte(rgb.z()), to_byte(rgb.y()), to_byte(rgb.x()));
}

}  // namespace

std::string RenderOptions::Check() const {
  if (!(up.norm() > 0.0)) return "up: must be non-zero";
  if (!(horizontal_max_angle_deg >= 0.0 && horizontal_max_angle_deg <= 90.0)) {
    return "horizontal_max_angle_deg: must be in [0, 90]";
  }
  if (!(min_shade >= 0.0 && min_shade <= 1.0)) return "min_shade: must be in [0, 1]";
  if (!(bird_margin >= 0.0)) return "bird_margin: must be >= 0";
  if (!(bird_tilt_deg >= 0.0 && bird_tilt_deg < 90.0)) return "bird_tilt_deg: must be in [0, 90)";
  return {};
}

Eigen::Vector3d NormalColor(const Eigen::Vector3d& normal, const Eigen::Vector3d& view_direction,
                            const RenderOptions& options) {
  const Eigen::Vector3d up = options.up.normalized();
  const double shade =
      options.min_shade + (1.0 - options.min_shade) * std::abs(normal.dot(view_direction));
  const double vertical = normal.dot(up);
  if (std::abs(vertical) >= std::cos(options.horizontal_max_angle_deg * M_PI / 180.0)) {
    return Eigen::Vector3d::Constant(shade);
  }
  Eigen::Vector3d a, b;
  HorizontalAxes(up, &a, &b);
  const double hue = std::atan2(normal.dot(b), normal.dot(a)) / (2.0 * M_PI) + 0.5;
  return shade * HueToRgb(hue);
}

Camera ScaleCamera(const Camera& camera, int width, int height) {
  Camera scaled = camera;
  const double sx = static_cast<double>(width) / camera.width;
  const double sy = static_cast<double>(height) / camera.height;
  scaled.width = width;
  scaled.height = height;
  scaled.params[0] *= sx;
  scaled.params[1] *= sy;
  scaled.params[2] = (camera.params[2] + 0.5) * sx - 0.5;
  scaled.params[3] = (camera.params[3] + 0.5) * sy - 0.5;
  return scaled;
}

cv::Mat RenderCameraView(const RayCaster& mesh, const Camera& camera, const Rigid3d& world_from_rig,
                         const RenderOptions& options) {
  cv::Mat image(camera.height, camera.width, CV_8UC3, cv::Scalar(0, 0, 0));
  tbb::parallel_for(
      tbb::blocked_range<int>(0, camera.height), [&](const tbb::blocked_range<int>& rows) {
        for (int row = rows.begin(); row != rows.end(); ++row) {
          for (int col = 0; col < camera.width; ++col) {
            Ray ray;
            if (!PixelRay(camera, world_from_rig, Eigen::Vector2d(col, row), &ray)) continue;
            const RayHit hit = mesh.Cast(ray);
            if (!hit.Hit()) continue;
            SetPixel(&image, row, col,
                     NormalColor(mesh.TriangleNormal(hit.triangle), ray.direction, options));
          }
        }
      });
  return image;
}

cv::Mat RenderBirdsEye(const RayCaster& mesh, int width, int height, const RenderOptions& options) {
  const Eigen::Vector3d up = options.up.normalized();
  Eigen::Vector3d right, b;
  HorizontalAxes(up, &right, &b);
  const double tilt = options.bird_tilt_deg * M_PI / 180.0;
  const Eigen::Vector3d view = (-std::cos(tilt) * up + std::sin(tilt) * b).normalized();
  const Eigen::Vector3d image_up = right.cross(view);
  // Extent of the bounding box's corners along right, image_up and the view direction.
  Eigen::Vector3d low = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d high = -low;
  for (int corner = 0; corner < 8; ++corner) {
    const Eigen::Vector3d p((corner & 1) ? mesh.MaxCorner().x() : mesh.MinCorner().x(),
                            (corner & 2) ? mesh.MaxCorner().y() : mesh.MinCorner().y(),
                            (corner & 4) ? mesh.MaxCorner().z() : mesh.MinCorner().z());
    const Eigen::Vector3d q(p.dot(right), p.dot(image_up), p.dot(view));
    low = low.cwiseMin(q);
    high = high.cwiseMax(q);
  }
  const double margin = options.bird_margin * std::max(high.x() - low.x(), high.y() - low.y());
  low.head<2>() -= Eigen::Vector2d::Constant(margin);
  high.head<2>() += Eigen::Vector2d::Constant(margin);
  const double extent_a = std::max(high.x() - low.x(), 1e-9);
  const double extent_b = std::max(high.y() - low.y(), 1e-9);
  if (height <= 0) height = std::max(1, static_cast<int>(std::lround(width * extent_b / extent_a)));
  const double pixel_size = std::max(extent_a / width, extent_b / height);
  const double start = low.z() - 1.0;  // in front of the whole box along the view
  cv::Mat image(height, width, CV_8UC3, cv::Scalar(0, 0, 0));
  const Eigen::Vector2d center(0.5 * (low.x() + high.x()), 0.5 * (low.y() + high.y()));
  tbb::parallel_for(tbb::blocked_range<int>(0, height), [&](const tbb::blocked_range<int>& rows) {
    for (int row = rows.begin(); row != rows.end(); ++row) {
      for (int col = 0; col < width; ++col) {
        const double u = center.x() + (col + 0.5 - 0.5 * width) * pixel_size;
        const double v = center.y() - (row + 0.5 - 0.5 * height) * pixel_size;
        Ray ray;
        ray.origin = u * right + v * image_up + start * view;
        ray.direction = view;
        const RayHit hit = mesh.Cast(ray);
        if (!hit.Hit()) continue;
        SetPixel(&image, row, col,
                 NormalColor(mesh.TriangleNormal(hit.triangle), ray.direction, options));
      }
    }
  });
  return image;
}

void WritePng(const cv::Mat& image, const std::filesystem::path& path) {
  std::vector<uchar> bytes;
  if (!cv::imencode(".png", image, bytes)) throw InputError(path, "", "cannot encode a PNG");
  WriteFileAtomically(
      path,
      [&bytes](std::ostream& out) {
        out.write(reinterpret_cast<const char*>(bytes.data()),
                  static_cast<std::streamsize>(bytes.size()));
      },
      /*binary=*/true);
}

}  // namespace omni
