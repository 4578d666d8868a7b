#include "pipeline/colmap_keyframes.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <unordered_map>

#include "calib/error.h"

namespace omni {
namespace {

// The non-comment, non-empty lines of a COLMAP text file, with their line numbers.
std::vector<std::pair<int, std::string>> DataLines(const std::filesystem::path& path) {
  std::ifstream stream(path);
  if (!stream) throw InputError(path, "", "cannot open");
  std::vector<std::pair<int, std::string>> lines;
  std::string line;
  int number = 0;
  while (std::getline(stream, line)) {
    ++number;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') {
      // images.txt: an image's second line (its 2D points) may be empty; keep it.
      if (path.filename() == "images.txt" && first == std::string::npos) {
        lines.emplace_back(number, "");
      }
      continue;
    }
    lines.emplace_back(number, line);
  }
  return lines;
}

struct Image {
  Eigen::Vector3d centre;
  std::string frame;  // the file name without its folder
};

}  // namespace

std::vector<SurfaceKeyframe> LoadColmapKeyframes(const std::filesystem::path& model,
                                                 std::unordered_map<PointId, Rgb8>* point_colors) {
  if (!std::filesystem::exists(model / "cameras.txt")) {
    throw InputError(model / "cameras.txt", "", "cannot open (a COLMAP text model is expected)");
  }
  // Images: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a line of 2D points.
  const std::filesystem::path images_path = model / "images.txt";
  const auto image_lines = DataLines(images_path);
  std::unordered_map<long, Image> images;
  std::map<std::string, std::vector<long>> frames;  // frame name -> image ids
  for (size_t i = 0; i < image_lines.size(); ++i) {
    const auto& [number, text] = image_lines[i];
    if (text.empty()) continue;
    std::istringstream in(text);
    long id, camera;
    double qw, qx, qy, qz, tx, ty, tz;
    std::string name;
    if (!(in >> id >> qw >> qx >> qy >> qz >> tx >> ty >> tz >> camera >> name)) {
      throw InputError(images_path, "line " + std::to_string(number),
                       "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    }
    ++i;  // skip the 2D points line
    const Eigen::Quaterniond cam_from_world_q(qw, qx, qy, qz);
    if (!(cam_from_world_q.norm() > 0.5)) {
      throw InputError(images_path, "line " + std::to_string(number), "invalid quaternion");
    }
    const Eigen::Matrix3d r = cam_from_world_q.normalized().toRotationMatrix();
    Image image;
    image.centre = -r.transpose() * Eigen::Vector3d(tx, ty, tz);
    image.frame = std::filesystem::path(name).filename().string();
    if (!images.emplace(id, image).second) {
      throw InputError(images_path, "line " + std::to_string(number),
                       "repeated IMAGE_ID " + std::to_string(id));
    }
    frames[image.frame].push_back(id);
  }
  // Keyframes by frame name; the centre is the mean of the camera centres.
  std::vector<SurfaceKeyframe> keyframes;
  std::unordered_map<long, size_t> keyframe_of;  // image id -> keyframe index
  for (const auto& [frame, ids] : frames) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(static_cast<uint32_t>(keyframes.size()));
    for (long id : ids) {
      kf.centre += images.at(id).centre;
      keyframe_of[id] = keyframes.size();
    }
    kf.centre /= static_cast<double>(ids.size());
    keyframes.push_back(kf);
  }
  // Points: POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX).
  const std::filesystem::path points_path = model / "points3D.txt";
  for (const auto& [number, text] : DataLines(points_path)) {
    std::istringstream in(text);
    long id;
    double x, y, z, error;
    int r, g, b;
    if (!(in >> id >> x >> y >> z >> r >> g >> b >> error)) {
      throw InputError(points_path, "line " + std::to_string(number),
                       "expected POINT3D_ID X Y Z R G B ERROR TRACK[]");
    }
    SurfacePoint point;
    point.id = PointId(static_cast<uint32_t>(id));
    point.position = Eigen::Vector3d(x, y, z);
    if (point_colors) {
      auto channel = [](int value) { return static_cast<uint8_t>(std::clamp(value, 0, 255)); };
      (*point_colors)[point.id] = Rgb8(channel(r), channel(g), channel(b));
    }
    long image_id, index;
    size_t latest = 0;
    while (in >> image_id >> index) {
      const auto it = images.find(image_id);
      if (it == images.end()) {
        throw InputError(points_path, "line " + std::to_string(number),
                         "unknown IMAGE_ID " + std::to_string(image_id));
      }
      const size_t k = keyframe_of.at(image_id);
      latest = std::max(latest, k);
      point.rays.push_back({keyframes[k].id, it->second.centre});
    }
    if (point.rays.empty()) continue;  // no observation: no ray
    keyframes[latest].points.push_back(std::move(point));
  }
  return keyframes;
}

}  // namespace omni
