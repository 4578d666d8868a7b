#include "apps/surface/gt_keyframes.h"

#include <embree3/rtcore.h>

#include <Eigen/Geometry>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>

#include "calib/error.h"
#include "calib/rig_io.h"
#include "calib/tum.h"

namespace omni {
namespace {

class RayCaster {
 public:
  explicit RayCaster(const TriangleMesh& mesh) {
    device_ = rtcNewDevice(nullptr);
    if (!device_) throw std::runtime_error("Embree: rtcNewDevice failed");
    scene_ = rtcNewScene(device_);
    RTCGeometry geometry = rtcNewGeometry(device_, RTC_GEOMETRY_TYPE_TRIANGLE);
    auto* vertices = static_cast<float*>(
        rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                3 * sizeof(float), mesh.vertices.size()));
    auto* indices = static_cast<unsigned*>(
        rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(unsigned), mesh.triangles.size()));
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      for (int k = 0; k < 3; ++k) vertices[3 * i + k] = static_cast<float>(mesh.vertices[i][k]);
    }
    for (size_t i = 0; i < mesh.triangles.size(); ++i) {
      for (int k = 0; k < 3; ++k) indices[3 * i + k] = static_cast<unsigned>(mesh.triangles[i][k]);
    }
    rtcCommitGeometry(geometry);
    rtcAttachGeometry(scene_, geometry);
    rtcReleaseGeometry(geometry);
    rtcCommitScene(scene_);
  }
  ~RayCaster() {
    rtcReleaseScene(scene_);
    rtcReleaseDevice(device_);
  }
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  // Distance to the first hit along the unit direction, infinity when none.
  double Cast(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction,
              double max_distance) const {
    RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    RTCRayHit rh;
    rh.ray.org_x = static_cast<float>(origin.x());
    rh.ray.org_y = static_cast<float>(origin.y());
    rh.ray.org_z = static_cast<float>(origin.z());
    rh.ray.dir_x = static_cast<float>(direction.x());
    rh.ray.dir_y = static_cast<float>(direction.y());
    rh.ray.dir_z = static_cast<float>(direction.z());
    rh.ray.tnear = 0.0f;
    rh.ray.tfar = static_cast<float>(max_distance);
    rh.ray.mask = 0xFFFFFFFFu;
    rh.ray.time = 0.0f;
    rh.ray.flags = 0;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    rtcIntersect1(scene_, &context, &rh);
    if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return std::numeric_limits<double>::infinity();
    return rh.ray.tfar;
  }

 private:
  RTCDevice device_ = nullptr;
  RTCScene scene_ = nullptr;
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
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument("GtKeyframeOptions: " + problem);
  const RayCaster caster(mesh);
  std::mt19937_64 rng(options.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  const double max_distance = options.max_distance_factor * options.keyframe_spacing;
  std::vector<SurfaceKeyframe> stream;
  uint32_t next_point = 0;
  const size_t n = options.max_keyframes > 0
                       ? std::min(centres.size(), static_cast<size_t>(options.max_keyframes))
                       : centres.size();
  for (size_t t = 0; t < n; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(static_cast<uint32_t>(t));
    kf.centre = centres[t];
    const int attempts = 8 * options.points_per_keyframe;
    for (int a = 0;
         a < attempts && static_cast<int>(kf.points.size()) < options.points_per_keyframe; ++a) {
      Eigen::Vector3d dir(gauss(rng), gauss(rng), gauss(rng));
      dir.normalize();
      const double d = caster.Cast(kf.centre, dir, max_distance);
      if (!std::isfinite(d)) continue;
      const Eigen::Vector3d p = kf.centre + d * dir;
      SurfacePoint point;
      point.id = PointId(next_point);
      // Rays from the earlier keyframes (and this one) that see p unoccluded.
      for (size_t k = t + 1;
           k-- > 0 && t - k < static_cast<size_t>(options.max_observing_keyframes);) {
        const Eigen::Vector3d to = p - centres[k];
        const double dist = to.norm();
        if (dist > max_distance || dist < 1e-6) continue;
        const double hit = caster.Cast(centres[k], to / dist, dist * 1.01 + 1e-3);
        if (hit < dist * (1.0 - 1e-3) - 1e-3) continue;  // occluded
        point.rays.push_back({KeyframeId(static_cast<uint32_t>(k)), centres[k]});
      }
      if (static_cast<int>(point.rays.size()) < options.min_rays) continue;
      point.position = p;
      if (options.point_noise > 0) {
        point.position += options.point_noise * Eigen::Vector3d(gauss(rng), gauss(rng), gauss(rng));
      }
      ++next_point;
      kf.points.push_back(std::move(point));
    }
    stream.push_back(std::move(kf));
  }
  if (options.pose_noise > 0) {
    std::mt19937_64 pose_rng(options.seed ^ 0x9e3779b97f4a7c15ull);
    std::vector<Eigen::Vector3d> shift(stream.size());
    for (size_t t = 0; t < stream.size(); ++t) {
      shift[t] =
          options.pose_noise * Eigen::Vector3d(gauss(pose_rng), gauss(pose_rng), gauss(pose_rng));
      stream[t].centre += shift[t];
    }
    for (SurfaceKeyframe& kf : stream) {
      for (SurfacePoint& p : kf.points) {
        for (SurfaceRay& ray : p.rays) ray.origin += shift[ray.keyframe.value];
      }
    }
  }
  return stream;
}

std::vector<SurfaceKeyframe> LoadGtKeyframes(const std::filesystem::path& drive,
                                             const GtKeyframeOptions& options,
                                             TriangleMesh* gt_mesh,
                                             std::vector<StampedPose>* keyframe_poses) {
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
  auto stream = MakeGtKeyframes(mesh, keyframe_centres, options);
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
  return stream;
}

}  // namespace omni
