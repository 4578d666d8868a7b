#include "sfm/synthetic.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <random>

#include "calib/error.h"

namespace omni {
namespace {

// cam_from_rig of a camera whose axes are given in the rig frame.
Rigid3d CamFromRigFromAxes(const Eigen::Vector3d& right, const Eigen::Vector3d& down,
                           const Eigen::Vector3d& forward, const Eigen::Vector3d& center_in_rig) {
  Eigen::Matrix3d rig_from_cam_rotation;
  rig_from_cam_rotation << right, down, forward;
  const Eigen::Matrix3d cam_from_rig_rotation = rig_from_cam_rotation.transpose();
  return Rigid3d(Eigen::Quaterniond(cam_from_rig_rotation),
                 -(cam_from_rig_rotation * center_in_rig));
}

Eigen::Vector3d RandomUnitInCone(std::mt19937& rng, double half_angle) {
  std::uniform_real_distribution<double> cos_dist(std::cos(half_angle), 1.0);
  std::uniform_real_distribution<double> phi_dist(0.0, 2.0 * M_PI);
  const double c = cos_dist(rng);
  const double s = std::sqrt(std::max(0.0, 1.0 - c * c));
  const double phi = phi_dist(rng);
  return Eigen::Vector3d(s * std::cos(phi), s * std::sin(phi), c);
}

Eigen::Vector3d AddAngularNoise(std::mt19937& rng, const Eigen::Vector3d& bearing, double noise) {
  if (noise <= 0.0) return bearing;
  std::normal_distribution<double> normal(0.0, noise);
  // Two tangent directions of the bearing.
  const Eigen::Vector3d u = bearing.unitOrthogonal();
  const Eigen::Vector3d v = bearing.cross(u);
  return (bearing + normal(rng) * u + normal(rng) * v).normalized();
}

}  // namespace

std::string SyntheticSceneOptions::Check() const {
  if (num_points < 0) return "num_points: expected a non-negative count";
  if (!(min_depth > 0.0 && max_depth >= min_depth))
    return "min_depth, max_depth: expected 0 < min_depth <= max_depth";
  if (!(half_fov > 0.0 && half_fov < M_PI)) return "half_fov: expected an angle in (0, pi)";
  if (noise < 0.0) return "noise: expected a non-negative angle";
  if (!(outlier_ratio >= 0.0 && outlier_ratio <= 1.0))
    return "outlier_ratio: expected a value in [0, 1]";
  if (!(min_outlier_angle >= 0.0 && min_outlier_angle < half_fov))
    return "min_outlier_angle: expected an angle in [0, half_fov)";
  return {};
}

Rig MakeSyntheticRingRig(int num_side_cameras, bool up_camera, double radius) {
  assert(num_side_cameras >= 0 && (num_side_cameras > 0 || up_camera));
  Rig rig;
  rig.name = "synthetic-ring";
  rig.central = radius == 0.0;
  auto add_camera = [&rig](const Rigid3d& cam_from_rig) {
    Camera camera;
    camera.name = "cam" + std::to_string(rig.cameras.size());
    camera.width = 640;
    camera.height = 480;
    camera.model = CameraModel::kPinhole;
    camera.params = {320.0, 320.0, 319.5, 239.5};
    camera.cam_from_rig = cam_from_rig;
    rig.cameras.push_back(camera);
  };
  const Eigen::Vector3d up = Eigen::Vector3d::UnitZ();
  for (int i = 0; i < num_side_cameras; ++i) {
    const double azimuth = 2.0 * M_PI * i / num_side_cameras;
    const Eigen::Vector3d forward(std::cos(azimuth), std::sin(azimuth), 0.0);
    const Eigen::Vector3d down = -up;
    add_camera(CamFromRigFromAxes(down.cross(forward), down, forward, radius * forward));
  }
  if (up_camera) {
    const Eigen::Vector3d down = Eigen::Vector3d::UnitX();
    add_camera(CamFromRigFromAxes(down.cross(up), down, up, radius * up));
  }
  return rig;
}

SyntheticScene MakeSyntheticScene(const Rig& rig, const std::vector<Rigid3d>& world_from_rig,
                                  const SyntheticSceneOptions& options) {
  ThrowIfInvalid(options.Check(), "SyntheticSceneOptions");
  assert(!rig.cameras.empty() && !world_from_rig.empty());
  SyntheticScene scene;
  scene.rig = rig;
  scene.world_from_rig = world_from_rig;
  std::mt19937 rng(options.seed);
  std::uniform_int_distribution<int> camera_dist(0, static_cast<int>(rig.NumCameras()) - 1);
  std::uniform_real_distribution<double> depth_dist(options.min_depth, options.max_depth);
  std::uniform_real_distribution<double> unit(0.0, 1.0);

  // world_from_cam of every frame and camera.
  auto world_from_cam = [&](int frame, int camera) {
    const Rigid3d& wr = world_from_rig[frame];
    const Rigid3d& cr = rig.cameras[camera].cam_from_rig;
    const Eigen::Quaterniond rotation = wr.rotation * cr.rotation.conjugate();
    return Rigid3d(rotation, wr * cr.Center());
  };

  for (int i = 0; i < options.num_points; ++i) {
    const Rigid3d seed_pose = world_from_cam(0, camera_dist(rng));
    const Eigen::Vector3d bearing = RandomUnitInCone(rng, options.half_fov);
    scene.points_in_world.push_back(seed_pose * (depth_dist(rng) * bearing));
  }
  const double cos_half_fov = std::cos(options.half_fov);
  for (int frame = 0; frame < static_cast<int>(world_from_rig.size()); ++frame) {
    for (int camera = 0; camera < static_cast<int>(rig.NumCameras()); ++camera) {
      const Rigid3d pose = world_from_cam(frame, camera);
      for (int point = 0; point < options.num_points; ++point) {
        const Eigen::Vector3d in_cam =
            pose.rotation.conjugate() * (scene.points_in_world[point] - pose.translation);
        const Eigen::Vector3d truth = in_cam.normalized();
        if (truth.z() < cos_half_fov) continue;
        SyntheticObservation observation;
        observation.frame = frame;
        observation.camera = camera;
        observation.point = point;
        observation.bearing = AddAngularNoise(rng, truth, options.noise);
        if (unit(rng) < options.outlier_ratio) {
          observation.is_outlier = true;
          do {
            observation.bearing = RandomUnitInCone(rng, options.half_fov);
          } while (AngleBetween(observation.bearing, truth) < options.min_outlier_angle);
        }
        scene.observations.push_back(observation);
      }
    }
  }
  return scene;
}

SyntheticMatches MatchSyntheticFrames(const SyntheticScene& scene, int frame1, int frame2) {
  const size_t num_points = scene.points_in_world.size();
  std::vector<int> first1(num_points, -1), first2(num_points, -1);
  for (int i = 0; i < static_cast<int>(scene.observations.size()); ++i) {
    const SyntheticObservation& observation = scene.observations[i];
    if (observation.frame == frame1 && first1[observation.point] < 0) first1[observation.point] = i;
    if (observation.frame == frame2 && first2[observation.point] < 0) first2[observation.point] = i;
  }
  SyntheticMatches matches;
  for (size_t point = 0; point < num_points; ++point) {
    if (first1[point] < 0 || first2[point] < 0) continue;
    const SyntheticObservation& a = scene.observations[first1[point]];
    const SyntheticObservation& b = scene.observations[first2[point]];
    matches.bearings1.push_back(a.bearing);
    matches.bearings2.push_back(b.bearing);
    matches.cameras1.push_back(a.camera);
    matches.cameras2.push_back(b.camera);
    matches.points.push_back(static_cast<int>(point));
    matches.is_outlier.push_back(a.is_outlier || b.is_outlier);
  }
  return matches;
}

cv::Mat MakeSyntheticTexture(int width, int height, const Eigen::Vector2d& shift, int num_shapes,
                             uint32_t seed) {
  assert(width > 0 && height > 0 && num_shapes >= 0);
  constexpr double kEdgeWidth = 0.7;  // pixels over which an edge rises (logistic scale)
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  cv::Mat accumulator(height, width, CV_64F, cv::Scalar(128.0));
  for (int s = 0; s < num_shapes; ++s) {
    const Eigen::Vector2d center(unit(rng) * width, unit(rng) * height);
    const double half_x = 4.0 + 16.0 * unit(rng), half_y = 4.0 + 16.0 * unit(rng);
    const double angle = M_PI * unit(rng);
    const double amplitude = (unit(rng) < 0.5 ? -1.0 : 1.0) * (40.0 + 60.0 * unit(rng));
    const double c = std::cos(angle), sn = std::sin(angle);
    const double reach = std::hypot(half_x, half_y) + 4.0;
    const int x0 = std::max(0, static_cast<int>(std::floor(center.x() + shift.x() - reach)));
    const int x1 = std::min(width - 1, static_cast<int>(std::ceil(center.x() + shift.x() + reach)));
    const int y0 = std::max(0, static_cast<int>(std::floor(center.y() + shift.y() - reach)));
    const int y1 =
        std::min(height - 1, static_cast<int>(std::ceil(center.y() + shift.y() + reach)));
    for (int y = y0; y <= y1; ++y) {
      double* row = accumulator.ptr<double>(y);
      for (int x = x0; x <= x1; ++x) {
        const double dx = x - shift.x() - center.x(), dy = y - shift.y() - center.y();
        const double u = c * dx + sn * dy, v = -sn * dx + c * dy;
        const double inside = std::min(half_x - std::abs(u), half_y - std::abs(v));
        row[x] += amplitude / (1.0 + std::exp(-inside / kEdgeWidth));
      }
    }
  }
  cv::Mat image;
  accumulator.convertTo(image, CV_8U);  // rounds and saturates
  return image;
}

double RotationAngleBetween(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return a.angularDistance(b);
}

double AngleBetween(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

}  // namespace omni
