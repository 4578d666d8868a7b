#include "pipeline/colmap_keyframes.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cstdint>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <unordered_map>

#include "calib/error.h"
#include "pipeline/world_up.h"

namespace omni {
namespace {

struct Image {
  Eigen::Vector3d centre;
  Eigen::Vector3d up;  // the image's up axis (−y of the camera) in the world
};

// How an image's name places it in a rig: "cam3/000123.png" (the camera's folder, the frame's
// file name) or "f000123_c3.png" (one folder, the frame and the camera index in the name).
struct ImageName {
  std::string frame_key;      // the name without its camera: "000123.png", "f000123.png"
  std::string frame_name;     // "000123"
  std::string camera_folder;  // "cam3"; empty for the f<frame>_c<index> names
  int camera_index = -1;      // 3 for "f000123_c3.png"; -1 for the folder names
};

ImageName ParseImageName(const std::string& name) {
  const std::filesystem::path path(name);
  const std::string stem = path.stem().string();
  ImageName parsed;
  const size_t c = stem.rfind("_c");
  if (stem.size() > 1 && stem[0] == 'f' && c != std::string::npos && c > 1 && c + 2 < stem.size() &&
      std::all_of(stem.begin() + static_cast<long>(c) + 2, stem.end(),
                  [](char ch) { return ch >= '0' && ch <= '9'; }) &&
      stem.size() - c - 2 <= 6) {
    parsed.frame_name = stem.substr(1, c - 1);
    parsed.camera_index = std::stoi(stem.substr(c + 2));
    parsed.frame_key = (path.parent_path() / ("f" + parsed.frame_name + path.extension().string()))
                           .generic_string();
    return parsed;
  }
  parsed.frame_name = stem;
  parsed.camera_folder = path.parent_path().filename().string();
  parsed.frame_key = (path.parent_path().parent_path() / path.filename()).generic_string();
  return parsed;
}

std::string FrameKey(const std::string& name) { return ParseImageName(name).frame_key; }

// The frames of a model: frame key -> indices into model.images, ordered by key.
std::map<std::string, std::vector<size_t>> FramesOf(const ColmapModel& colmap) {
  std::map<std::string, std::vector<size_t>> frames;
  for (size_t i = 0; i < colmap.images.size(); ++i)
    frames[FrameKey(colmap.images[i].name)].push_back(i);
  return frames;
}

// The rays of frame_rays.txt (calib/colmap_text.h): a point of the model gets its rays of the
// frames between keyframes; a frame point goes to the latest keyframe at or before the last
// frame that saw it (the first keyframe when none is), as the SfM hands it over, with an id
// after the model's.
void AddFrameRays(const ColmapModel& colmap,
                  const std::map<std::string, std::vector<uint32_t>>& frames,
                  std::unordered_map<PointId, Rgb8>* point_colors,
                  std::vector<SurfaceKeyframe>* keyframes) {
  if (colmap.frame_rays.empty() || keyframes->empty()) return;
  std::unordered_map<uint32_t, std::pair<size_t, size_t>> where;  // point id -> keyframe, index
  uint64_t next_id = 1;
  for (size_t k = 0; k < keyframes->size(); ++k)
    for (size_t i = 0; i < (*keyframes)[k].points.size(); ++i)
      where[(*keyframes)[k].points[i].id.value] = {k, i};
  for (const ColmapPoint3D& point : colmap.points)
    next_id = std::max(next_id, uint64_t{point.id} + 1);
  std::vector<std::string> keys;  // the keyframes' frame keys, in keyframe order
  for (const auto& entry : frames) keys.push_back(entry.first);
  for (const ColmapFrameRayPoint& line : colmap.frame_rays) {
    if (line.point3d_id != 0) {
      const auto it = where.find(line.point3d_id);
      if (it == where.end()) continue;  // a point without a ray from the model's images
      SurfaceKeyframe& keyframe = (*keyframes)[it->second.first];
      SurfacePoint& point = keyframe.points[it->second.second];
      for (const ColmapFrameRay& ray : line.rays) point.rays.push_back({keyframe.id, ray.centre});
      continue;
    }
    std::string last;
    for (const ColmapFrameRay& ray : line.rays) last = std::max(last, FrameKey(ray.image_name));
    const auto after = std::upper_bound(keys.begin(), keys.end(), last);
    SurfaceKeyframe& keyframe =
        (*keyframes)[after == keys.begin() ? 0 : static_cast<size_t>(after - keys.begin()) - 1];
    if (next_id > std::numeric_limits<uint32_t>::max())
      throw InputError("frame_rays.txt", "",
                       "no point id is left for the frame points (points3D.txt uses the last)");
    SurfacePoint point;
    point.id = PointId(static_cast<uint32_t>(next_id++));
    point.position = line.xyz;
    for (const ColmapFrameRay& ray : line.rays) point.rays.push_back({keyframe.id, ray.centre});
    if (point_colors) (*point_colors)[point.id] = line.color;
    keyframe.points.push_back(std::move(point));
  }
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
  for (const auto& [frame, indices] : FramesOf(colmap)) {
    for (size_t i : indices) frames[frame].push_back(colmap.images[i].id);
  }
  for (const ColmapImage& colmap_image : colmap.images) {
    const Eigen::Matrix3d r = colmap_image.cam_from_world.rotation.toRotationMatrix();
    Image image;
    image.centre = colmap_image.cam_from_world.Center();
    image.up = -r.row(1).transpose();
    images.emplace(colmap_image.id, image);
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
  AddFrameRays(colmap, frames, point_colors, &keyframes);
  return keyframes;
}

ColmapRigPoses ColmapKeyframeRigPoses(const ColmapModel& colmap, const Rig& rig) {
  // Each image's rig camera.
  std::vector<size_t> camera_of(colmap.images.size());
  for (size_t i = 0; i < colmap.images.size(); ++i) {
    const std::string& name = colmap.images[i].name;
    const ImageName parsed = ParseImageName(name);
    if (parsed.camera_index >= 0) {
      if (static_cast<size_t>(parsed.camera_index) >= rig.cameras.size()) {
        throw InputError(name, "",
                         "camera index " + std::to_string(parsed.camera_index) +
                             " is not in the rig (" + std::to_string(rig.cameras.size()) +
                             " cameras)");
      }
      camera_of[i] = static_cast<size_t>(parsed.camera_index);
    } else {
      const std::optional<size_t> camera = rig.FindCamera(parsed.camera_folder);
      if (!camera) {
        throw InputError(name, "",
                         "no rig camera is named after its folder '" + parsed.camera_folder +
                             "' (and the name is not f<frame>_c<camera index>)");
      }
      camera_of[i] = *camera;
    }
  }
  const std::map<std::string, std::vector<size_t>> frames = FramesOf(colmap);
  ColmapRigPoses result;
  // The model's scale: distances between the camera centres of a frame, model against rig.
  double model_rig = 0.0, rig_rig = 0.0;
  for (const auto& [frame, indices] : frames) {
    for (size_t a = 0; a < indices.size(); ++a) {
      for (size_t b = a + 1; b < indices.size(); ++b) {
        const double in_rig = (rig.cameras[camera_of[indices[a]]].CenterInRig() -
                               rig.cameras[camera_of[indices[b]]].CenterInRig())
                                  .norm();
        if (!(in_rig > 1e-9)) continue;
        const double in_model = (colmap.images[indices[a]].cam_from_world.Center() -
                                 colmap.images[indices[b]].cam_from_world.Center())
                                    .norm();
        model_rig += in_model * in_rig;
        rig_rig += in_rig * in_rig;
        ++result.camera_pairs;
      }
    }
  }
  if (rig_rig > 0.0 && model_rig > 0.0) result.model_units_per_metre = model_rig / rig_rig;
  const double scale = result.model_units_per_metre;
  for (const auto& [frame, indices] : frames) {
    ColmapKeyframePose pose;
    pose.frame_name = ParseImageName(colmap.images[indices.front()].name).frame_name;
    pose.images = indices.size();
    // The mean rotation (quaternions on one hemisphere, summed and normalised).
    Eigen::Vector4d sum = Eigen::Vector4d::Zero();
    for (size_t i : indices) {
      const Camera& camera = rig.cameras[camera_of[i]];
      const Eigen::Quaterniond world_from_rig =
          colmap.images[i].cam_from_world.rotation.conjugate() * camera.cam_from_rig.rotation;
      Eigen::Vector4d q = world_from_rig.normalized().coeffs();
      if (sum.dot(q) < 0.0) q = -q;
      sum += q;
    }
    pose.world_from_rig.rotation = Eigen::Quaterniond(sum.normalized());
    // The rig's centre (CentralCenterInRig, the point eval registers) in the model's units; the
    // rig's origin at its metric offset from that centre.
    const Eigen::Vector3d rig_centre = rig.CentralCenterInRig();
    Eigen::Vector3d centre = Eigen::Vector3d::Zero();
    for (size_t i : indices) {
      centre += colmap.images[i].cam_from_world.Center() -
                pose.world_from_rig.rotation *
                    (scale * (rig.cameras[camera_of[i]].CenterInRig() - rig_centre));
    }
    centre /= static_cast<double>(indices.size());
    pose.world_from_rig.translation = centre - pose.world_from_rig.rotation * rig_centre;
    result.keyframes.push_back(std::move(pose));
  }
  return result;
}

}  // namespace omni
