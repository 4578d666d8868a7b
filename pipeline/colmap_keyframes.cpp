#include "pipeline/colmap_keyframes.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <map>
#include <string>
#include <unordered_map>

#include "pipeline/world_up.h"

namespace omni {
namespace {

struct Image {
  Eigen::Vector3d centre;
  Eigen::Vector3d up;  // the image's up axis (−y of the camera) in the world
};

// The frame an image belongs to: its name without the camera folder.
std::string FrameKey(const std::string& name) {
  const std::filesystem::path path(name);
  return (path.parent_path().parent_path() / path.filename()).generic_string();
}

}  // namespace

std::vector<SurfaceKeyframe> LoadColmapKeyframes(const std::filesystem::path& model,
                                                 std::unordered_map<PointId, Rgb8>* point_colors,
                                                 Eigen::Vector3d* world_up) {
  return ParseColmapKeyframes(ReadColmapText(model), model, point_colors, world_up);
}

std::vector<SurfaceKeyframe> ParseColmapKeyframes(const ColmapTextModel& text,
                                                  const std::filesystem::path& model,
                                                  std::unordered_map<PointId, Rgb8>* point_colors,
                                                  Eigen::Vector3d* world_up) {
  return ColmapKeyframes(ParseColmapModel(text, model), point_colors, world_up);
}

std::vector<SurfaceKeyframe> ColmapKeyframes(const ColmapModel& colmap,
                                             std::unordered_map<PointId, Rgb8>* point_colors,
                                             Eigen::Vector3d* world_up) {
  std::unordered_map<uint32_t, Image> images;
  std::map<std::string, std::vector<uint32_t>> frames;  // frame key -> image ids
  for (const ColmapImage& colmap_image : colmap.images) {
    const Eigen::Matrix3d r = colmap_image.cam_from_world.rotation.toRotationMatrix();
    Image image;
    image.centre = colmap_image.cam_from_world.Center();
    image.up = -r.row(1).transpose();
    images.emplace(colmap_image.id, image);
    frames[FrameKey(colmap_image.name)].push_back(colmap_image.id);
  }
  if (world_up) {
    std::vector<Eigen::Vector3d> centres, ups;
    for (const ColmapImage& colmap_image : colmap.images) {
      centres.push_back(images.at(colmap_image.id).centre);
      ups.push_back(images.at(colmap_image.id).up);
    }
    *world_up = EstimateWorldUp(centres, ups);
  }
  // Keyframes by frame name; the centre is the mean of the camera centres.
  std::vector<SurfaceKeyframe> keyframes;
  std::unordered_map<uint32_t, size_t> keyframe_of;  // image id -> keyframe index
  for (const auto& [frame, ids] : frames) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(static_cast<uint32_t>(keyframes.size()));
    for (uint32_t id : ids) {
      kf.centre += images.at(id).centre;
      keyframe_of[id] = keyframes.size();
    }
    kf.centre /= static_cast<double>(ids.size());
    keyframes.push_back(kf);
  }
  // A point goes to the latest keyframe of its track, with one ray per observing image.
  for (const ColmapPoint3D& colmap_point : colmap.points) {
    SurfacePoint point;
    point.id = PointId(colmap_point.id);
    point.position = colmap_point.xyz;
    if (point_colors) (*point_colors)[point.id] = colmap_point.color;
    size_t latest = 0;
    for (const ColmapTrackElement& element : colmap_point.track) {
      const size_t kf = keyframe_of.at(element.image_id);
      latest = std::max(latest, kf);
      point.rays.push_back({keyframes[kf].id, images.at(element.image_id).centre});
    }
    if (point.rays.empty()) continue;  // no observation: no ray
    keyframes[latest].points.push_back(std::move(point));
  }
  return keyframes;
}

}  // namespace omni
