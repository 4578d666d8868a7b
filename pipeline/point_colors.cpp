#include "pipeline/point_colors.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <unordered_map>

#include "calib/error.h"

namespace omni {

std::string PointColorOptions::Check() const {
  if (fallback_grey < 0 || fallback_grey > 255) return "fallback_grey: expected 0 to 255";
  return {};
}

Eigen::Vector3d SampleRgbBilinear(const cv::Mat& rgb, const Eigen::Vector2d& pixel) {
  assert(rgb.type() == CV_8UC3 && !rgb.empty());
  const double x = std::clamp(pixel.x(), 0.0, rgb.cols - 1.0);
  const double y = std::clamp(pixel.y(), 0.0, rgb.rows - 1.0);
  const int x0 = std::min(static_cast<int>(x), rgb.cols - 1),
            y0 = std::min(static_cast<int>(y), rgb.rows - 1);
  const int x1 = std::min(x0 + 1, rgb.cols - 1), y1 = std::min(y0 + 1, rgb.rows - 1);
  const double ax = x - x0, ay = y - y0;
  auto at = [&rgb](int row, int col) {
    const cv::Vec3b& v = rgb.at<cv::Vec3b>(row, col);
    return Eigen::Vector3d(v[0], v[1], v[2]);
  };
  return (1 - ay) * ((1 - ax) * at(y0, x0) + ax * at(y0, x1)) +
         ay * ((1 - ax) * at(y1, x0) + ax * at(y1, x1));
}

std::vector<Rgb8> ColorPoints(const Rig& rig, const std::vector<FinalizedKeyframe>& keyframes,
                              const RgbImageLoader& load_rgb, const PointColorOptions& options,
                              PointColorStats* stats) {
  ThrowIfInvalid(options.Check(), "PointColorOptions");
  const auto start = std::chrono::steady_clock::now();
  const int num_cameras = static_cast<int>(rig.NumCameras());
  std::unordered_map<int, int> frame_of;  // tracker keyframe index -> drive frame
  for (const FinalizedKeyframe& keyframe : keyframes) frame_of[keyframe.keyframe] = keyframe.frame;

  // Every observation that projects into its image, grouped by image (frame, camera).
  struct Sample {
    size_t point;
    Eigen::Vector2d pixel;
  };
  struct Image {
    int frame, camera;
    std::vector<Sample> samples;
    std::vector<Eigen::Vector3d> colors;  // one per sample once read; empty if unreadable
  };
  std::vector<Image> images;
  std::unordered_map<long, size_t> image_of;  // frame * num_cameras + camera -> images[]
  size_t num_points = 0;
  // A sample of point num_points in image (frame, camera).
  auto add_sample = [&](int frame, int camera, const Eigen::Vector2d& pixel) {
    const long key = static_cast<long>(frame) * num_cameras + camera;
    auto [it, inserted] = image_of.emplace(key, images.size());
    if (inserted) images.push_back({frame, camera, {}, {}});
    images[it->second].samples.push_back({num_points, pixel});
  };
  for (const FinalizedKeyframe& keyframe : keyframes) {
    for (const FinalizedPoint& point : keyframe.points) {
      for (const FinalizedRay& ray : point.rays) {
        const auto frame = frame_of.find(ray.keyframe);
        if (frame == frame_of.end() || ray.camera < 0 || ray.camera >= num_cameras) continue;
        const Camera& camera = rig.cameras[ray.camera];
        Eigen::Vector2d pixel;
        if (!camera.Project(ray.bearing, &pixel) || !camera.IsInImage(pixel)) continue;
        add_sample(frame->second, ray.camera, pixel);
      }
      // A frame point (no keyframe ray): where it projects in the images of the keyframe it
      // came with, by the cameras of its frame rays (the frames' own images are not read).
      if (point.frame_point) {
        const Rigid3d rig_from_world = keyframe.world_from_rig.Inverse();
        std::vector<int> cameras;
        for (const FinalizedFrameRay& ray : point.frame_rays)
          if (ray.camera >= 0 && ray.camera < num_cameras &&
              std::find(cameras.begin(), cameras.end(), ray.camera) == cameras.end())
            cameras.push_back(ray.camera);
        for (const int c : cameras) {
          const Camera& camera = rig.cameras[c];
          Eigen::Vector2d pixel;
          if (camera.Project(camera.cam_from_rig * (rig_from_world * point.position), &pixel) &&
              camera.IsInImage(pixel))
            add_sample(keyframe.frame, c, pixel);
        }
      }
      ++num_points;
    }
  }

  // Each image read once, in parallel; a sample's colour lands in its image's slot.
  std::atomic<size_t> unreadable{0};
  tbb::parallel_for(size_t{0}, images.size(), [&](size_t i) {
    Image& image = images[i];
    cv::Mat rgb;
    try {
      rgb = load_rgb(image.frame, image.camera);
    } catch (const InputError& error) {
      spdlog::warn("point colours: {}: its observations give no colour", error.what());
      ++unreadable;
      return;
    }
    if (rgb.empty() || rgb.type() != CV_8UC3) {
      spdlog::warn("point colours: frame {} camera {}: not an 8-bit RGB image", image.frame,
                   image.camera);
      ++unreadable;
      return;
    }
    image.colors.reserve(image.samples.size());
    for (const Sample& sample : image.samples)
      image.colors.push_back(SampleRgbBilinear(rgb, sample.pixel));
  });

  std::vector<Eigen::Vector3d> sums(num_points, Eigen::Vector3d::Zero());
  std::vector<int> counts(num_points, 0);
  size_t samples = 0;
  for (const Image& image : images) {
    for (size_t s = 0; s < image.colors.size(); ++s) {
      sums[image.samples[s].point] += image.colors[s];
      ++counts[image.samples[s].point];
      ++samples;
    }
  }
  std::vector<Rgb8> colors(num_points);
  const uint8_t grey = static_cast<uint8_t>(options.fallback_grey);
  size_t uncoloured = 0;
  for (size_t p = 0; p < num_points; ++p) {
    if (counts[p] == 0) {
      colors[p] = Rgb8(grey, grey, grey);
      ++uncoloured;
      continue;
    }
    const Eigen::Vector3d mean = sums[p] / counts[p];
    for (int k = 0; k < 3; ++k)
      colors[p][k] = static_cast<uint8_t>(std::clamp(std::lround(mean[k]), 0L, 255L));
  }
  if (stats) {
    stats->images_unreadable = unreadable;
    stats->images_read = images.size() - unreadable;
    stats->samples = samples;
    stats->points_uncoloured = uncoloured;
    stats->seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  return colors;
}

ColoredSurfaces ExtractColoredSurfaces(const IncrementalSculptor& sculptor,
                                       const std::unordered_map<PointId, Rgb8>& point_colors) {
  ColoredSurfaces surfaces;
  std::vector<PointId> closed_points, observed_points;
  surfaces.closed = sculptor.ExtractMesh(&closed_points);
  surfaces.observed = sculptor.ExtractObservedMesh(&observed_points, &surfaces.observed_stats);
  ColorMeshVertices(closed_points, point_colors, &surfaces.closed);
  ColorMeshVertices(observed_points, point_colors, &surfaces.observed);
  return surfaces;
}

}  // namespace omni
