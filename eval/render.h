#pragma once
// Renders of a mesh with Embree, coloured by triangle normal as in the paper's Fig. 4: the
// ground (and any horizontal face) white, walls coloured by the direction of their horizontal
// normal, shaded by |n·view|; no hit (the sky) black.

#include <Eigen/Core>
#include <filesystem>
#include <opencv2/core.hpp>
#include <string>

#include "calib/camera.h"
#include "raycast/raycast.h"

namespace omni {

struct RenderOptions {
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();  // world vertical (synth: z up)
  // A face whose normal is within this angle of the vertical is "ground" (white), degrees.
  double horizontal_max_angle_deg = 30.0;
  // Brightness of a face seen edge-on; 1 for a face seen straight on.
  double min_shade = 0.25;
  // Bird's-eye view: margin around the mesh's bounding box, as a fraction of its size.
  double bird_margin = 0.02;
  // Bird's-eye view: tilt of the viewing direction from the vertical, degrees (0: straight
  // down, everything horizontal is white; the paper's Fig. 4 global view is oblique).
  double bird_tilt_deg = 30.0;

  std::string Check() const;
};

// RGB in [0, 1] for a face of unit normal `normal` seen along unit `view_direction`.
Eigen::Vector3d NormalColor(const Eigen::Vector3d& normal, const Eigen::Vector3d& view_direction,
                            const RenderOptions& options);

// The image the camera of a rig at world_from_rig would see (8-bit BGR, camera size).
cv::Mat RenderCameraView(const RayCaster& mesh, const Camera& camera, const Rigid3d& world_from_rig,
                         const RenderOptions& options = {});
// An orthographic view from above over the mesh's bounding box, `width` pixels wide (height
// from the aspect ratio when 0). Image right = the first horizontal axis (x for z up), image
// up = the second (y) when not tilted; the tilt looks towards +y.
cv::Mat RenderBirdsEye(const RayCaster& mesh, int width, int height = 0,
                       const RenderOptions& options = {});

// The camera with its image scaled to width x height (intrinsics scaled; distortion kept).
Camera ScaleCamera(const Camera& camera, int width, int height);

// PNG written atomically. Throws InputError if it cannot be written.
void WritePng(const cv::Mat& image, const std::filesystem::path& path);

}  // namespace omni
