#include "pipeline/gt_keyframes.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <random>
#include <stdexcept>
#include <unordered_map>

#include "calib/drive.h"
#include "calib/error.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "pipeline/point_colors.h"
#include "raycast/raycast.h"

namespace omni {
namespace {

// Distance to the first hit of the GT mesh along the unit direction, infinity when none.
double CastDistance(const RayCaster& caster, const Eigen::Vector3d& origin,
                    const Eigen::Vector3d& direction, double max_distance) {
  Ray ray;
  ray.origin = origin;
  ray.direction = direction;
  ray.max_distance = max_distance;
  return caster.Cast(ray).distance;
}

// The rays of a point p of keyframe t: from the centres of t and of the earlier keyframes (at
// most max_observing_keyframes) that see p unoccluded within max_distance.
void AddRays(const RayCaster& caster, const std::vector<Eigen::Vector3d>& centres, size_t t,
             const Eigen::Vector3d& p, double max_distance, const GtKeyframeOptions& options,
             SurfacePoint* point) {
  for (size_t k = t + 1; k-- > 0 && t - k < static_cast<size_t>(options.max_observing_keyframes);) {
    const Eigen::Vector3d to = p - centres[k];
    const double dist = to.norm();
    if (dist > max_distance || dist < 1e-6) continue;
    const double hit = CastDistance(caster, centres[k], to / dist, dist * 1.01 + 1e-3);
    if (hit < dist * (1.0 - 1e-3) - 1e-3) continue;  // occluded
    point->rays.push_back({KeyframeId(static_cast<uint32_t>(k)), centres[k]});
  }
}

// GtKeyframeOptions::frame_rays: the rays from the drive frames (centres of every frame;
// keyframe_frames[t] the frame of keyframe t) strictly between a point's first observing
// keyframe and the next keyframes up to its own, when they see it unoccluded.
void AddFrameRays(const TriangleMesh& mesh, const std::vector<Eigen::Vector3d>& centres,
                  const std::vector<size_t>& keyframe_frames, const GtKeyframeOptions& options,
                  std::vector<SurfaceKeyframe>* stream) {
  const RayCaster caster(mesh);
  const double max_distance = options.max_distance_factor * options.keyframe_spacing;
  for (size_t t = 0; t < stream->size(); ++t) {
    std::vector<SurfacePoint>& points = (*stream)[t].points;
    tbb::parallel_for(size_t{0}, points.size(), [&](size_t i) {
      SurfacePoint& p = points[i];
      uint32_t first = p.rays.empty() ? static_cast<uint32_t>(t) : p.rays.front().keyframe.value;
      for (const SurfaceRay& ray : p.rays) first = std::min(first, ray.keyframe.value);
      for (size_t k = first; k < t; ++k) {
        for (size_t f = keyframe_frames[k] + 1; f < keyframe_frames[k + 1]; ++f) {
          const Eigen::Vector3d to = p.position - centres[f];
          const double dist = to.norm();
          if (dist > max_distance || dist < 1e-6) continue;
          const double hit = CastDistance(caster, centres[f], to / dist, dist * 1.01 + 1e-3);
          if (hit < dist * (1.0 - 1e-3) - 1e-3) continue;  // occluded
          p.rays.push_back({KeyframeId(static_cast<uint32_t>(k)), centres[f]});
        }
      }
    });
  }
}

// GtKeyframeOptions::sky_rays_per_camera: the free rays of each keyframe, from its centre along
// the pixels of a grid of about `per_camera` pixels in each camera whose ray hits no triangle.
void AddSkyRays(const TriangleMesh& mesh, const Rig& rig,
                const std::vector<Rigid3d>& world_from_rig, int per_camera,
                std::vector<SurfaceKeyframe>* stream) {
  const RayCaster caster(mesh);
  tbb::parallel_for(size_t{0}, stream->size(), [&](size_t t) {
    SurfaceKeyframe& kf = (*stream)[t];
    for (const Camera& camera : rig.cameras) {
      const double step = std::sqrt(static_cast<double>(camera.width) * camera.height / per_camera);
      const Rigid3d world_from_cam = world_from_rig[t] * camera.cam_from_rig.Inverse();
      for (double y = 0.5 * step; y < camera.height; y += step) {
        for (double x = 0.5 * step; x < camera.width; x += step) {
          Eigen::Vector3d bearing;
          if (!camera.Unproject(Eigen::Vector2d(x - 0.5, y - 0.5), &bearing)) continue;
          const Eigen::Vector3d direction = (world_from_cam.rotation * bearing).normalized();
          if (std::isfinite(CastDistance(caster, world_from_cam.translation, direction,
                                         std::numeric_limits<double>::infinity())))
            continue;  // it sees structure
          kf.free_rays.push_back({kf.centre, direction});
        }
      }
    }
  });
}

// Pose noise of the simulated SfM (own seeded stream, so the points sampled do not change).
void ApplyPoseNoise(const GtKeyframeOptions& options, std::vector<SurfaceKeyframe>* stream) {
  if (!(options.pose_noise > 0)) return;
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::mt19937_64 pose_rng(options.seed ^ 0x9e3779b97f4a7c15ull);
  std::vector<Eigen::Vector3d> shift(stream->size());
  for (size_t t = 0; t < stream->size(); ++t) {
    shift[t] =
        options.pose_noise * Eigen::Vector3d(gauss(pose_rng), gauss(pose_rng), gauss(pose_rng));
    (*stream)[t].centre += shift[t];
  }
  for (SurfaceKeyframe& kf : *stream) {
    for (SurfacePoint& p : kf.points) {
      for (SurfaceRay& ray : p.rays) ray.origin += shift[ray.keyframe.value];
    }
  }
}

// Points already made, hashed by cells of the merge distance, to find a corner seen again.
class PointHash {
 public:
  explicit PointHash(double cell) : cell_(cell) {}
  bool HasPointWithin(const Eigen::Vector3d& p) const {
    const Eigen::Vector3i c = Cell(p);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto found = cells_.find(Key(c + Eigen::Vector3i(dx, dy, dz)));
          if (found == cells_.end()) continue;
          for (const Eigen::Vector3d& q : found->second)
            if ((q - p).squaredNorm() < cell_ * cell_) return true;
        }
    return false;
  }
  void Add(const Eigen::Vector3d& p) { cells_[Key(Cell(p))].push_back(p); }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return (p / cell_).array().floor().cast<int>();
  }
  static uint64_t Key(const Eigen::Vector3i& c) {
    return (static_cast<uint64_t>(static_cast<uint32_t>(c.x()) & 0x1fffff) << 42) |
           (static_cast<uint64_t>(static_cast<uint32_t>(c.y()) & 0x1fffff) << 21) |
           (static_cast<uint64_t>(static_cast<uint32_t>(c.z()) & 0x1fffff));
  }
  double cell_;
  std::unordered_map<uint64_t, std::vector<Eigen::Vector3d>> cells_;
};

// What both samplers share: the checked options, the GT ray caster, the seeded point stream
// and the ids of the points made so far.
class GtPointSampler {
 public:
  GtPointSampler(const TriangleMesh& mesh, const GtKeyframeOptions& options)
      : options_(CheckedOptions(options, "GtKeyframeOptions")),
        caster_(mesh),
        rng_(options.seed),
        max_distance_(options.max_distance_factor * options.keyframe_spacing) {}

  const RayCaster& caster() const { return caster_; }
  std::mt19937_64& rng() { return rng_; }
  std::normal_distribution<double>& gauss() { return gauss_; }
  double max_distance() const { return max_distance_; }

  // The keyframes to make out of `available` (options.max_keyframes, 0: all).
  size_t NumKeyframes(size_t available) const {
    return options_.max_keyframes > 0
               ? std::min(available, static_cast<size_t>(options_.max_keyframes))
               : available;
  }

  // The point of keyframe t on the surface at p, with its rays, appended to kf when at least
  // min_rays keyframes see it (then true); its position gets the point noise.
  bool AppendObservedPoint(const std::vector<Eigen::Vector3d>& centres, size_t t,
                           const Eigen::Vector3d& p, SurfaceKeyframe* kf) {
    SurfacePoint point;
    point.id = PointId(next_point_);
    AddRays(caster_, centres, t, p, max_distance_, options_, &point);
    if (static_cast<int>(point.rays.size()) < options_.min_rays) return false;
    point.position = p;
    if (options_.point_noise > 0) {
      point.position +=
          options_.point_noise * Eigen::Vector3d(gauss_(rng_), gauss_(rng_), gauss_(rng_));
    }
    ++next_point_;
    kf->points.push_back(std::move(point));
    return true;
  }

 private:
  const GtKeyframeOptions& options_;
  const RayCaster caster_;
  std::mt19937_64 rng_;
  std::normal_distribution<double> gauss_{0.0, 1.0};
  const double max_distance_;
  uint32_t next_point_ = 0;
};

}  // namespace

std::string GtKeyframeOptions::Check() const {
  if (!(keyframe_spacing > 0)) return "keyframe_spacing must be > 0";
  if (points_per_keyframe < 0) return "points_per_keyframe must be >= 0";
  if (!(max_distance_factor > 0)) return "max_distance_factor must be > 0";
  if (max_observing_keyframes < 1) return "max_observing_keyframes must be >= 1";
  if (min_rays < 1) return "min_rays must be >= 1";
  if (!(point_noise >= 0)) return "point_noise must be >= 0";
  if (!(pose_noise >= 0)) return "pose_noise must be >= 0";
  if (!(pose_noise_deg >= 0)) return "pose_noise_deg must be >= 0";
  if (max_keyframes < 0) return "max_keyframes must be >= 0";
  if (const std::string problem = harris.Check(); !problem.empty()) return "harris." + problem;
  if (!(corner_merge_distance > 0)) return "corner_merge_distance must be > 0";
  if (sky_rays_per_camera < 0) return "sky_rays_per_camera must be >= 0";
  return "";
}

std::vector<size_t> SelectKeyframeFrames(const std::vector<Eigen::Vector3d>& centres,
                                         double spacing) {
  std::vector<size_t> frames;
  for (size_t i = 0; i < centres.size(); ++i) {
    if (frames.empty() || (centres[i] - centres[frames.back()]).norm() >= spacing) {
      frames.push_back(i);
    }
  }
  return frames;
}

std::vector<SurfaceKeyframe> MakeGtKeyframes(const TriangleMesh& mesh,
                                             const std::vector<Eigen::Vector3d>& centres,
                                             const GtKeyframeOptions& options) {
  GtPointSampler sampler(mesh, options);
  std::vector<SurfaceKeyframe> stream;
  const size_t n = sampler.NumKeyframes(centres.size());
  for (size_t t = 0; t < n; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(static_cast<uint32_t>(t));
    kf.centre = centres[t];
    const int attempts = 8 * options.points_per_keyframe;
    for (int a = 0;
         a < attempts && static_cast<int>(kf.points.size()) < options.points_per_keyframe; ++a) {
      std::normal_distribution<double>& gauss = sampler.gauss();
      Eigen::Vector3d dir(gauss(sampler.rng()), gauss(sampler.rng()), gauss(sampler.rng()));
      dir.normalize();
      const double d = CastDistance(sampler.caster(), kf.centre, dir, sampler.max_distance());
      if (!std::isfinite(d)) continue;
      sampler.AppendObservedPoint(centres, t, kf.centre + d * dir, &kf);
    }
    stream.push_back(std::move(kf));
  }
  ApplyPoseNoise(options, &stream);
  return stream;
}

std::vector<SurfaceKeyframe> MakeGtKeyframesAtCorners(const TriangleMesh& mesh, const Rig& rig,
                                                      const std::vector<Rigid3d>& world_from_rig,
                                                      const GtKeyframeImages& images,
                                                      const GtKeyframeOptions& options) {
  GtPointSampler sampler(mesh, options);
  const size_t n = sampler.NumKeyframes(world_from_rig.size());
  const Eigen::Vector3d centre_in_rig = rig.CentralCenterInRig();
  std::vector<Eigen::Vector3d> centres;
  for (size_t t = 0; t < n; ++t) centres.push_back(world_from_rig[t] * centre_in_rig);
  PointHash made(options.corner_merge_distance);
  std::vector<SurfaceKeyframe> stream;
  for (size_t t = 0; t < n; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(static_cast<uint32_t>(t));
    kf.centre = centres[t];
    // Every corner of every camera (input-image pixels), in a seeded random order.
    const std::vector<cv::Mat> frame_images = images(t);
    if (frame_images.size() != rig.NumCameras())
      throw std::invalid_argument("MakeGtKeyframesAtCorners: expected one image per camera");
    std::vector<std::pair<int, Eigen::Vector2d>> corners;
    for (size_t c = 0; c < rig.NumCameras(); ++c) {
      const cv::Mat prepared = PrepareImage(frame_images[c], options.harris);
      for (const Corner& corner : DetectHarrisCorners(prepared, options.harris))
        corners.emplace_back(static_cast<int>(c),
                             PreparedToInputPixel(corner.pixel, options.harris.downscale));
    }
    std::shuffle(corners.begin(), corners.end(), sampler.rng());
    for (const auto& [c, pixel] : corners) {
      if (static_cast<int>(kf.points.size()) >= options.points_per_keyframe) break;
      const Camera& camera = rig.cameras[c];
      Eigen::Vector3d bearing;
      if (!camera.Unproject(pixel, &bearing)) continue;
      const Rigid3d world_from_cam = world_from_rig[t] * camera.cam_from_rig.Inverse();
      const Eigen::Vector3d direction = (world_from_cam.rotation * bearing).normalized();
      const double d = CastDistance(sampler.caster(), world_from_cam.translation, direction,
                                    sampler.max_distance());
      if (!std::isfinite(d)) continue;
      const Eigen::Vector3d p = world_from_cam.translation + d * direction;
      if (made.HasPointWithin(p)) continue;  // a corner seen again: the same track
      if (sampler.AppendObservedPoint(centres, t, p, &kf)) made.Add(p);
    }
    stream.push_back(std::move(kf));
  }
  ApplyPoseNoise(options, &stream);
  return stream;
}

std::vector<SurfaceKeyframe> LoadGtKeyframes(const std::filesystem::path& drive,
                                             const GtKeyframeOptions& options,
                                             TriangleMesh* gt_mesh,
                                             std::vector<StampedPose>* keyframe_poses,
                                             std::vector<size_t>* keyframe_frames) {
  const Rig rig = ReadRigJson(drive / "rig.json");
  const std::vector<StampedPose> poses = ReadTum(drive / "gt" / "poses.tum");
  if (poses.empty()) throw InputError(drive / "gt" / "poses.tum", "", "no pose");
  TriangleMesh mesh = ReadPlyMesh(drive / "gt" / "mesh.ply");
  if (mesh.triangles.empty()) throw InputError(drive / "gt" / "mesh.ply", "", "no triangle");
  const Eigen::Vector3d centre_in_rig = rig.CentralCenterInRig();
  std::vector<Eigen::Vector3d> centres;
  for (const StampedPose& pose : poses) centres.push_back(pose.world_from_rig * centre_in_rig);
  const std::vector<size_t> frames = SelectKeyframeFrames(centres, options.keyframe_spacing);
  std::vector<Eigen::Vector3d> keyframe_centres;
  for (size_t frame : frames) keyframe_centres.push_back(centres[frame]);
  // The corner mode needs the images of the ground-truth frames: a drive whose frames are the
  // poses of gt/poses.tum, one for one.
  std::optional<Drive> images;
  if (options.corner_points && std::filesystem::is_directory(drive / "images")) {
    images = Drive::Open(drive);
    if (images->NumFrames() != poses.size()) {
      spdlog::warn(
          "{}: {} frames of images but {} ground-truth poses: points sampled uniformly instead "
          "of at corners",
          drive.string(), images->NumFrames(), poses.size());
      images.reset();
    }
  }
  std::vector<SurfaceKeyframe> stream;
  if (images) {
    std::vector<Rigid3d> keyframe_world_from_rig;
    for (size_t frame : frames) keyframe_world_from_rig.push_back(poses[frame].world_from_rig);
    stream = MakeGtKeyframesAtCorners(
        mesh, rig, keyframe_world_from_rig,
        [&](size_t t) {
          std::vector<cv::Mat> frame_images;
          for (size_t c = 0; c < rig.NumCameras(); ++c)
            frame_images.push_back(images->LoadGray(frames[t], c));
          return frame_images;
        },
        options);
  } else {
    stream = MakeGtKeyframes(mesh, keyframe_centres, options);
  }
  if (options.frame_rays) AddFrameRays(mesh, centres, frames, options, &stream);
  if (options.sky_rays_per_camera > 0) {
    std::vector<Rigid3d> keyframe_world_from_rig;
    for (size_t t = 0; t < stream.size(); ++t)
      keyframe_world_from_rig.push_back(poses[frames[t]].world_from_rig);
    AddSkyRays(mesh, rig, keyframe_world_from_rig, options.sky_rays_per_camera, &stream);
  }
  if (keyframe_poses) {
    keyframe_poses->clear();
    std::mt19937_64 rng(options.seed ^ 0x5851f42d4c957f2dull);
    std::normal_distribution<double> gauss(0.0, options.pose_noise_deg * M_PI / 180.0);
    for (size_t t = 0; t < stream.size(); ++t) {
      StampedPose pose = poses[frames[t]];
      if (options.pose_noise_deg > 0) {
        const Eigen::Vector3d w(gauss(rng), gauss(rng), gauss(rng));
        pose.world_from_rig.rotation =
            (Eigen::Quaterniond(Eigen::AngleAxisd(w.norm(), w.normalized())) *
             pose.world_from_rig.rotation)
                .normalized();
      }
      // The rig centre at the (noisy) keyframe centre.
      pose.world_from_rig.translation += stream[t].centre - pose.world_from_rig * centre_in_rig;
      keyframe_poses->push_back(pose);
    }
  }
  if (gt_mesh) *gt_mesh = std::move(mesh);
  if (keyframe_frames) keyframe_frames->assign(frames.begin(), frames.begin() + stream.size());
  return stream;
}

std::unordered_map<PointId, Rgb8> GtPointColors(const std::filesystem::path& drive,
                                                const std::vector<SurfaceKeyframe>& stream,
                                                const std::vector<size_t>& keyframe_frames) {
  std::unordered_map<PointId, Rgb8> colors;
  if (!std::filesystem::is_directory(drive / "images")) return colors;
  const Drive images = Drive::Open(drive);
  const std::vector<StampedPose> poses = ReadTum(drive / "gt" / "poses.tum");
  if (images.NumFrames() != poses.size()) return colors;
  const Rig& rig = images.rig();
  // The keyframes as the SfM would hand them over: each ray of a point observed by the cameras
  // of its keyframe in whose image the point falls.
  std::unordered_map<uint32_t, size_t> index_of;  // KeyframeId value -> stream index
  for (size_t t = 0; t < stream.size(); ++t) index_of[stream[t].id.value] = t;
  std::vector<FinalizedKeyframe> keyframes(stream.size());
  for (size_t t = 0; t < stream.size(); ++t) {
    FinalizedKeyframe& keyframe = keyframes[t];
    keyframe.keyframe = static_cast<int>(t);
    keyframe.frame = static_cast<int>(keyframe_frames.at(t));
    keyframe.world_from_rig = poses.at(keyframe_frames[t]).world_from_rig;
  }
  std::vector<PointId> ids;
  for (size_t t = 0; t < stream.size(); ++t) {
    for (const SurfacePoint& point : stream[t].points) {
      FinalizedPoint finalized;
      finalized.point = static_cast<int>(ids.size());
      finalized.position = point.position;
      for (const SurfaceRay& ray : point.rays) {
        const auto k = index_of.find(ray.keyframe.value);
        if (k == index_of.end()) continue;
        const Rigid3d rig_from_world = keyframes[k->second].world_from_rig.Inverse();
        for (size_t c = 0; c < rig.NumCameras(); ++c) {
          const Camera& camera = rig.cameras[c];
          const Eigen::Vector3d in_camera = camera.cam_from_rig * (rig_from_world * point.position);
          Eigen::Vector2d pixel;
          if (!camera.Project(in_camera.normalized(), &pixel) || !camera.IsInImage(pixel)) {
            continue;
          }
          FinalizedRay observation;
          observation.keyframe = static_cast<int>(k->second);
          observation.camera = static_cast<int>(c);
          observation.bearing = in_camera.normalized();
          finalized.rays.push_back(observation);
        }
      }
      keyframes[t].points.push_back(std::move(finalized));
      ids.push_back(point.id);
    }
  }
  const std::vector<Rgb8> point_colors = ColorPoints(
      rig, keyframes, [&images](int frame, int camera) { return images.LoadRgb(frame, camera); });
  for (size_t i = 0; i < ids.size(); ++i) colors[ids[i]] = point_colors[i];
  return colors;
}

}  // namespace omni
