#include "synth/renderer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>
#include <map>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "raycast/raycast.h"
#include "synth/hash.h"
#include "synth/texture.h"

namespace omni::synth {
namespace {

constexpr uint32_t kSky = std::numeric_limits<uint32_t>::max();
constexpr uint32_t kNoHit = std::numeric_limits<uint32_t>::max();

struct Sample {
  float value = 0.0f;   // shaded albedo, [0, 1.5]
  uint32_t key = kSky;  // object and surface hit, for edge detection
};

}  // namespace

struct SceneRenderer::Impl {
  const CityScene& scene;
  uint64_t seed;
  SynthRenderOptions options;
  Eigen::Vector3d sun;
  RayCaster caster;  // the city as it is (not recentred), traced coherently
  mutable std::mutex bearings_mutex;
  mutable std::map<std::string, std::unique_ptr<std::vector<Eigen::Vector3d>>> bearings_cache;

  Impl(const CityScene& s, uint64_t sd, const SynthRenderOptions& o)
      : scene(s), seed(sd), options(o), caster(s.mesh, CasterOptions()) {
    sun = Eigen::Vector3d(o.sun_direction[0], o.sun_direction[1], o.sun_direction[2]).normalized();
  }

  static RayCasterOptions CasterOptions() {
    RayCasterOptions caster_options;
    caster_options.recentre = false;
    caster_options.robust = false;
    caster_options.coherent = true;
    return caster_options;
  }

  // Unit bearings of a camera's pixel centres (NaN where Unproject fails), computed once.
  const std::vector<Eigen::Vector3d>& CentreBearings(const Camera& camera) const {
    std::ostringstream key;
    key.precision(17);
    key << camera.name << ' ' << camera.width << ' ' << camera.height << ' '
        << static_cast<int>(camera.model);
    for (double p : camera.params) key << ' ' << p;
    std::lock_guard<std::mutex> lock(bearings_mutex);
    std::unique_ptr<std::vector<Eigen::Vector3d>>& bearings = bearings_cache[key.str()];
    if (!bearings) {
      bearings = std::make_unique<std::vector<Eigen::Vector3d>>(
          static_cast<size_t>(camera.width) * camera.height,
          Eigen::Vector3d::Constant(std::numeric_limits<double>::quiet_NaN()));
      for (int y = 0; y < camera.height; ++y) {
        for (int x = 0; x < camera.width; ++x) {
          Eigen::Vector3d bearing;
          if (camera.Unproject(Eigen::Vector2d(x, y), &bearing)) {
            (*bearings)[static_cast<size_t>(y) * camera.width + x] = bearing;
          }
        }
      }
    }
    return *bearings;
  }

  // Triangle index and distance of the first hit, or false.
  bool Intersect(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                 uint32_t* triangle, float* distance) const {
    Ray ray;
    ray.origin = origin;
    ray.direction = direction;
    const RayHit hit = caster.Cast(ray);
    if (!hit.Hit()) return false;
    *triangle = static_cast<uint32_t>(hit.triangle);
    *distance = static_cast<float>(hit.distance);
    return true;
  }

  // First hits of up to 8 rays from one origin (one packet of the ray caster; ray k is valid
  // when valid[k]). triangles[k] is kNoHit on a miss.
  void Intersect8(const Eigen::Vector3d& origin, const Eigen::Vector3d* directions,
                  const bool* valid, uint32_t* triangles, float* distances) const {
    static_assert(RayCaster::kPacketSize == 8, "the renderer casts its pixels 8 at a time");
    Ray rays[8];
    RayHit hits[8];
    for (int k = 0; k < 8; ++k) {
      rays[k].origin = origin;
      if (valid[k]) rays[k].direction = directions[k];
    }
    caster.CastPacket(rays, valid, hits);
    for (int k = 0; k < 8; ++k) {
      triangles[k] = hits[k].Hit() ? static_cast<uint32_t>(hits[k].triangle) : kNoHit;
      distances[k] = hits[k].Hit() ? static_cast<float>(hits[k].distance) : 0.0f;
    }
  }

  // The sky seen along a unit ray.
  Sample Sky(const Eigen::Vector3d& direction) const {
    Sample sample;
    const double elevation = std::max(0.0, direction.z());
    sample.value = static_cast<float>(options.sky_horizon +
                                      (options.sky_zenith - options.sky_horizon) * elevation);
    return sample;
  }

  // Shaded albedo of a hit along a unit ray; `pixel_angle` is the angle one pixel spans.
  Sample ShadeHit(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
                  uint32_t triangle, float distance, double pixel_angle) const {
    Sample sample;
    if (triangle == kNoHit) return Sky(direction);
    const Eigen::Vector3d point = origin + static_cast<double>(distance) * direction;
    Eigen::Vector3d normal = scene.normals[triangle];
    double cosine = normal.dot(direction);
    if (cosine > 0) normal = -normal;  // seen from behind
    cosine = std::max(0.2, std::abs(cosine));
    const double footprint = distance * pixel_angle / cosine;
    const Surface surface = scene.surfaces[triangle];
    const uint32_t object = scene.objects[triangle];
    const double albedo = Albedo(scene.streets, seed, surface, object, point, normal, footprint);
    const double light = options.ambient + options.diffuse * std::max(0.0, normal.dot(sun));
    sample.value = static_cast<float>(albedo * light);
    sample.key = object * 16u + static_cast<uint32_t>(surface);
    return sample;
  }

  Sample Shade(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
               double pixel_angle) const {
    uint32_t triangle;
    float distance;
    if (!Intersect(origin, direction, &triangle, &distance)) return Sky(direction);
    return ShadeHit(origin, direction, triangle, distance, pixel_angle);
  }
};

SceneRenderer::SceneRenderer(const CityScene& scene, uint64_t seed,
                             const SynthRenderOptions& options)
    : impl_(std::make_unique<Impl>(scene, seed, options)) {}

SceneRenderer::~SceneRenderer() = default;

Eigen::Vector3d SceneRenderer::Tint(uint32_t key) const {
  if (!impl_->options.colour || key == kSky) return Eigen::Vector3d::Ones();
  const auto surface = static_cast<Surface>(key % 16u);
  if (surface != Surface::kWall && surface != Surface::kDoor && surface != Surface::kTrim &&
      surface != Surface::kReveal) {
    return Eigen::Vector3d::Ones();
  }
  // A saturated colour per building: each channel in [0.35, 1], one of them 1.
  const uint64_t h = Hash(impl_->seed, 0xC0102u, key / 16u);
  Eigen::Vector3d tint(0.35 + 0.65 * Uniform(h), 0.35 + 0.65 * Uniform(Mix64(h)),
                       0.35 + 0.65 * Uniform(Mix64(Mix64(h))));
  return tint / tint.maxCoeff();
}

std::optional<SurfaceHit> SceneRenderer::CastRay(const Eigen::Vector3d& origin,
                                                 const Eigen::Vector3d& direction) const {
  const Eigen::Vector3d unit = direction.normalized();
  uint32_t triangle;
  float distance;
  if (!impl_->Intersect(origin, unit, &triangle, &distance)) return std::nullopt;
  const Eigen::Vector3i& t = impl_->scene.mesh.triangles[triangle];
  const Eigen::Vector3d& a = impl_->scene.mesh.vertices[t[0]];
  const Eigen::Vector3d& normal = impl_->scene.normals[triangle];
  const double denominator = normal.dot(unit);
  SurfaceHit hit;
  hit.triangle = triangle;
  hit.distance = std::abs(denominator) > 1e-12 ? normal.dot(a - origin) / denominator
                                               : static_cast<double>(distance);
  hit.point = origin + hit.distance * unit;
  return hit;
}

std::optional<SurfaceHit> SceneRenderer::CastPixel(const Camera& camera,
                                                   const Rigid3d& world_from_cam,
                                                   const Eigen::Vector2d& pixel) const {
  Eigen::Vector3d bearing;
  if (!camera.Unproject(pixel, &bearing)) return std::nullopt;
  return CastRay(world_from_cam.translation, world_from_cam.rotation * bearing);
}

cv::Mat SceneRenderer::Render(const Camera& camera, const Rigid3d& world_from_cam,
                              uint64_t image_seed, double gain, double offset) const {
  const int width = camera.width, height = camera.height;
  const SynthRenderOptions& options = impl_->options;
  const double pixel_angle = 1.0 / std::max(camera.fx(), camera.fy());
  const Eigen::Matrix3d world_from_cam_rotation = world_from_cam.rotation.toRotationMatrix();
  const Eigen::Vector3d origin = world_from_cam.translation;
  // Bearings of the pixel centres, unprojected once per camera (they are the same in every
  // frame); the supersampling rays are unprojected one by one.
  const std::vector<Eigen::Vector3d>& centre_bearings = impl_->CentreBearings(camera);
  auto sample_at = [&](double x, double y) {
    Eigen::Vector3d bearing;
    if (!camera.Unproject(Eigen::Vector2d(x, y), &bearing)) return Sample{};
    return impl_->Shade(origin, (world_from_cam_rotation * bearing).normalized(), pixel_angle);
  };

  const int n = options.supersampling;
  auto supersample = [&](int x, int y) {
    double sum = 0.0;
    const uint64_t pixel_seed = Hash(image_seed, static_cast<uint64_t>(y) * width + x);
    for (int a = 0; a < n; ++a) {
      for (int b = 0; b < n; ++b) {
        const uint64_t h = Hash(pixel_seed, a * n + b);
        const double dx = (a + Uniform(h)) / n - 0.5;
        const double dy = (b + Uniform(Mix64(h))) / n - 0.5;
        sum += sample_at(x + dx, y + dy).value;
      }
    }
    return static_cast<float>(sum / (n * n));
  };

  std::vector<Sample> centre(static_cast<size_t>(width) * height);
  std::atomic<uint64_t> rays{0};
  // Pass 1: one ray through every pixel centre, in packets of 8.
  {
    tbb::parallel_for(tbb::blocked_range<int>(0, height, 4), [&](const tbb::blocked_range<int>& r) {
      Eigen::Vector3d directions[8];
      bool valid[8];
      uint32_t triangles[8];
      float distances[8];
      for (int y = r.begin(); y < r.end(); ++y) {
        for (int x0 = 0; x0 < width; x0 += 8) {
          for (int k = 0; k < 8; ++k) {
            const int x = x0 + k;
            valid[k] = false;
            if (x >= width) continue;
            const Eigen::Vector3d& bearing = centre_bearings[static_cast<size_t>(y) * width + x];
            valid[k] = bearing.allFinite();
            if (valid[k]) directions[k] = (world_from_cam_rotation * bearing).normalized();
          }
          impl_->Intersect8(origin, directions, valid, triangles, distances);
          for (int k = 0; k < 8 && x0 + k < width; ++k) {
            centre[static_cast<size_t>(y) * width + x0 + k] =
                valid[k] ? impl_->ShadeHit(origin, directions[k], triangles[k], distances[k],
                                           pixel_angle)
                         : Sample{};  // outside the camera model: black
          }
        }
      }
      rays += static_cast<uint64_t>(r.size()) * width;
    });
  }
  cv::Mat image(height, width, options.colour ? CV_8UC3 : CV_8UC1);
  const double sigma = options.noise_sigma;
  tbb::parallel_for(tbb::blocked_range<int>(0, height, 4), [&](const tbb::blocked_range<int>& r) {
    uint64_t local_rays = 0;
    for (int y = r.begin(); y < r.end(); ++y) {
      auto* row = image.ptr<uint8_t>(y);
      for (int x = 0; x < width; ++x) {
        const size_t i = static_cast<size_t>(y) * width + x;
        // Pass 2: supersampling where the centres show an edge (another object or surface, or
        // a contrast step), or everywhere when not adaptive.
        const Sample& c = centre[i];
        auto differs = [&](int xx, int yy) {
          if (xx < 0 || yy < 0 || xx >= width || yy >= height) return false;
          const Sample& o = centre[static_cast<size_t>(yy) * width + xx];
          return o.key != c.key || std::abs(o.value - c.value) > options.refine_contrast;
        };
        const bool refine = n > 1 && (!options.adaptive || differs(x - 1, y) || differs(x + 1, y) ||
                                      differs(x, y - 1) || differs(x, y + 1));
        float v = c.value;
        if (refine) {
          v = supersample(x, y);
          local_rays += n * n;
        }
        const double noise = sigma > 0 ? sigma * Gaussian(Hash(image_seed, 0x401CE, i)) : 0.0;
        auto quantise = [&](double value) {
          const double level = std::round(255.0 * gain * value + offset + noise);
          return static_cast<uint8_t>(std::min(255.0, std::max(0.0, level)));
        };
        if (options.colour) {
          const Eigen::Vector3d tint = Tint(c.key);
          for (int k = 0; k < 3; ++k) row[3 * x + k] = quantise(v * tint[2 - k]);  // BGR
        } else {
          row[x] = quantise(v);
        }
      }
    }
    rays += local_rays;
  });
  rays_ += rays.load();
  return image;
}

}  // namespace omni::synth
