#include "sfm/colmap_model.h"

#include <cassert>
#include <iomanip>
#include <sstream>
#include <unordered_map>

#include "calib/atomic_file.h"
#include "calib/colmap_text.h"

namespace omni {

std::string ColmapCameraModel(const Camera& camera, std::vector<double>* params) {
  *params = camera.params;
  (*params)[2] += 0.5;  // cx, cy: COLMAP's pixel centres are at +0.5
  (*params)[3] += 0.5;
  switch (camera.model) {
    case CameraModel::kPinhole:
      return "PINHOLE";  // fx fy cx cy
    case CameraModel::kOpenCV:
      // calib: fx fy cx cy k1 k2 p1 p2 k3. COLMAP's OPENCV stops at p2; with k3, FULL_OPENCV
      // (fx fy cx cy k1 k2 p1 p2 k3 k4 k5 k6, the rational terms zero).
      if (camera.params[8] == 0.0) {
        params->resize(8);
        return "OPENCV";
      }
      params->insert(params->end(), {0.0, 0.0, 0.0});
      return "FULL_OPENCV";
    case CameraModel::kFisheye:
      return "OPENCV_FISHEYE";  // fx fy cx cy k1 k2 k3 k4
  }
  return "PINHOLE";
}

ColmapModelStats WriteColmapTextModel(
    const Rig& rig, const std::vector<FinalizedKeyframe>& keyframes,
    const std::function<std::string(int frame, int camera)>& image_name,
    const std::filesystem::path& folder, const std::vector<Eigen::Matrix<uint8_t, 3, 1>>& colors) {
  std::filesystem::create_directories(folder);
  const int num_cameras = static_cast<int>(rig.NumCameras());
  ColmapModelStats stats;
  size_t num_points = 0;
  for (const FinalizedKeyframe& keyframe : keyframes) num_points += keyframe.points.size();
  assert(colors.empty() || colors.size() == num_points);
  (void)num_points;

  std::ostringstream cameras;
  cameras << std::setprecision(17);
  cameras << "# Camera list with one line of data per camera:\n"
          << "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
          << "# Number of cameras: " << num_cameras << "\n";
  for (int c = 0; c < num_cameras; ++c) {
    std::vector<double> params;
    const std::string model = ColmapCameraModel(rig.cameras[c], &params);
    cameras << c + 1 << ' ' << model << ' ' << rig.cameras[c].width << ' ' << rig.cameras[c].height;
    for (double p : params) cameras << ' ' << p;
    cameras << '\n';
  }

  // Image ids: keyframe position k, camera c -> k * num_cameras + c + 1.
  std::unordered_map<int, int> position_of;  // tracker keyframe index -> position
  for (size_t k = 0; k < keyframes.size(); ++k)
    position_of[keyframes[k].keyframe] = static_cast<int>(k);
  struct Point2D {
    Eigen::Vector2d pixel;
    long point3d;
  };
  std::vector<std::vector<Point2D>> points2d(keyframes.size() * num_cameras);

  std::ostringstream points;
  points << std::setprecision(10);
  std::ostringstream tracks;
  std::vector<ColmapFrameRayPoint> frame_rays;
  double error_sum = 0.0;
  long point_id = 0;
  size_t point_index = 0;  // into colors
  for (const FinalizedKeyframe& keyframe : keyframes) {
    for (const FinalizedPoint& point : keyframe.points) {
      const size_t index = point_index++;
      tracks.str("");
      double point_error = 0.0;
      int observations = 0;
      const long id = ++point_id;
      for (const FinalizedRay& ray : point.rays) {
        const auto it = position_of.find(ray.keyframe);
        if (it == position_of.end() || ray.camera < 0 || ray.camera >= num_cameras) continue;
        const Camera& camera = rig.cameras[ray.camera];
        Eigen::Vector2d observed, reprojected;
        if (!camera.Project(ray.bearing, &observed)) continue;
        const Rigid3d cam_from_world =
            camera.cam_from_rig * keyframes[it->second].world_from_rig.Inverse();
        const double error = camera.Project(cam_from_world * point.position, &reprojected)
                                 ? (reprojected - observed).norm()
                                 : 0.0;
        const int image = it->second * num_cameras + ray.camera;
        tracks << ' ' << image + 1 << ' ' << points2d[image].size();
        points2d[image].push_back({observed + Eigen::Vector2d(0.5, 0.5), id});
        point_error += error;
        ++observations;
      }
      const Rgb8 color = index < colors.size() ? colors[index] : Rgb8(128, 128, 128);
      if (!point.frame_rays.empty() && (observations > 0 || point.frame_point)) {
        ColmapFrameRayPoint frame_ray_point;
        frame_ray_point.point3d_id = observations > 0 ? static_cast<uint32_t>(id) : 0;
        frame_ray_point.xyz = point.position;
        frame_ray_point.color = color;
        for (const FinalizedFrameRay& ray : point.frame_rays)
          frame_ray_point.rays.push_back({image_name(ray.frame, ray.camera), ray.center});
        frame_rays.push_back(std::move(frame_ray_point));
      }
      if (observations == 0) {
        --point_id;
        continue;
      }
      points << id << ' ' << point.position.x() << ' ' << point.position.y() << ' '
             << point.position.z();
      points << ' ' << int{color[0]} << ' ' << int{color[1]} << ' ' << int{color[2]} << ' ';
      points << point_error / observations << tracks.str() << '\n';
      error_sum += point_error;
      stats.observations += observations;
      ++stats.points;
    }
  }
  stats.mean_reprojection_error = stats.observations > 0 ? error_sum / stats.observations : 0.0;

  std::ostringstream images;
  images << std::setprecision(17);
  images << "# Image list with two lines of data per image:\n"
         << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
         << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
         << "# Number of images: " << keyframes.size() * num_cameras << "\n";
  for (size_t k = 0; k < keyframes.size(); ++k) {
    for (int c = 0; c < num_cameras; ++c) {
      const Rigid3d cam_from_world =
          rig.cameras[c].cam_from_rig * keyframes[k].world_from_rig.Inverse();
      const Eigen::Quaterniond& q = cam_from_world.rotation;
      const Eigen::Vector3d& t = cam_from_world.translation;
      const int image = static_cast<int>(k) * num_cameras + c;
      images << image + 1 << ' ' << q.w() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' '
             << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << c + 1 << ' '
             << image_name(keyframes[k].frame, c) << '\n';
      std::ostringstream line;
      line << std::setprecision(10);
      for (size_t i = 0; i < points2d[image].size(); ++i)
        line << (i ? " " : "") << points2d[image][i].pixel.x() << ' '
             << points2d[image][i].pixel.y() << ' ' << points2d[image][i].point3d;
      images << line.str() << '\n';
      ++stats.images;
    }
  }

  WriteTextFileAtomically(folder / "cameras.txt", cameras.str());
  WriteTextFileAtomically(folder / "images.txt", images.str());
  WriteTextFileAtomically(folder / "points3D.txt",
                          "# 3D point list with one line of data per point:\n"
                          "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, "
                          "POINT2D_IDX)\n# Number of points: " +
                              std::to_string(stats.points) + "\n" + points.str());
  // The rays of the frames between keyframes, which images.txt cannot hold.
  if (!frame_rays.empty())
    WriteTextFileAtomically(folder / "frame_rays.txt", FormatColmapFrameRays(frame_rays));
  else
    std::filesystem::remove(folder / "frame_rays.txt");
  stats.frame_ray_points = static_cast<int>(frame_rays.size());
  return stats;
}

}  // namespace omni
