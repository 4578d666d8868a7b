#pragma once
// Ray casting of the synthetic city (raycast/raycast.h). Rays come from the calib camera models
// (Camera::Unproject, the pipeline's own code, distortion included) through each camera's true
// pose (world_from_rig * rig_from_cam: the rig is rendered non-central).

#include <Eigen/Core>
#include <atomic>
#include <cstdint>
#include <memory>
#include <opencv2/core.hpp>
#include <optional>

#include "calib/camera.h"
#include "calib/pose.h"
#include "synth/city.h"
#include "synth/synth_options.h"

namespace omni::synth {

struct SurfaceHit {
  Eigen::Vector3d point;  // on the plane of `triangle`, in double precision
  double distance = 0;    // along the unit ray direction
  uint32_t triangle = 0;  // index into CityScene::mesh.triangles
};

class SceneRenderer {
 public:
  // Keeps a reference to `scene`, which must outlive the renderer.
  SceneRenderer(const CityScene& scene, uint64_t seed, const SynthRenderOptions& options);
  ~SceneRenderer();
  SceneRenderer(const SceneRenderer&) = delete;
  SceneRenderer& operator=(const SceneRenderer&) = delete;

  // First hit of the ray origin + t direction, t > 0; the point is recomputed in double
  // precision on the hit triangle's plane. `direction` need not be unit.
  std::optional<SurfaceHit> CastRay(const Eigen::Vector3d& origin,
                                    const Eigen::Vector3d& direction) const;
  // The ray of `pixel` (Camera::Unproject) from the camera at world_from_cam. Nothing when the
  // ray misses (sky) or the pixel cannot be unprojected.
  std::optional<SurfaceHit> CastPixel(const Camera& camera, const Rigid3d& world_from_cam,
                                      const Eigen::Vector2d& pixel) const;

  // An 8-bit grey image (CV_8UC1, camera.height x camera.width), or with options.colour an 8-bit
  // BGR image (CV_8UC3, OpenCV's channel order). `image_seed` drives the
  // supersampling jitter and the sensor noise; `gain` multiplies the exposure and `offset` (grey
  // levels) is added to it, before the noise and the quantisation. Uses every core.
  cv::Mat Render(const Camera& camera, const Rigid3d& world_from_cam, uint64_t image_seed,
                 double gain, double offset = 0.0) const;

  // The tint of options.colour for a Sample key (object * 16 + surface), red green blue in
  // (0, 1]; (1, 1, 1) for the surfaces that stay grey, the sky and without options.colour.
  Eigen::Vector3d Tint(uint32_t key) const;

  // Rays cast by Render since construction.
  uint64_t RaysCast() const { return rays_.load(); }

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
  mutable std::atomic<uint64_t> rays_{0};
};

}  // namespace omni::synth
