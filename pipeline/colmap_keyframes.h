#pragma once
// The keyframe stream of docs/design.md §7 from a COLMAP text model (cameras.txt, images.txt,
// points3D.txt), for `omnisculpt surface --colmap` and `omnisculpt merge`. Images whose names
// share a frame (the same file name in sibling camera folders, e.g. "cam0/000123.png" and
// "cam1/000123.png", or "d1/images/cam0/000123.png" and "d1/images/cam1/000123.png") form one
// keyframe, a rig frame, and so do images named f<frame>_c<camera index> in one folder
// ("f000123_c0.png", "f000123_c1.png": docs/figures.md F33); otherwise every image is a keyframe.
// Keyframes are ordered by frame key: the name without its camera folder ("000123.png",
// "d1/images/000123.png") or camera suffix ("f000123.png"). A point goes to
// the latest keyframe of its track (paper §3.3: observed by keyframes t' ≤ t) with one ray per
// observing image, starting at that camera's centre. A model with frame_rays.txt (our own:
// calib/colmap_text.h) adds to a point the rays of the frames between keyframes that saw it, and
// its frame points, each to the latest keyframe at or before the last frame that saw it.

#include <filesystem>
#include <string>
#include <unordered_map>
#include <vector>

#include "calib/colmap_text.h"
#include "calib/pose.h"
#include "calib/rig.h"
#include "surface/sculptor.h"

namespace omni {

// Throws InputError naming the file and line when a file is missing or malformed: a line with
// the wrong number of fields, a number that is not decimal or not finite, an identifier that is
// not an unsigned 32-bit integer or is repeated, a quaternion not of unit norm (within 1e-3), an
// image whose camera is not in cameras.txt or without its line of 2D points, a track naming an
// unknown image. point_colors, when given, receives the R G B of
// each point of points3D.txt; world_up, the model's up direction from its cameras
// (EstimateWorldUp of pipeline/world_up.h over the images' centres and up axes).
std::vector<SurfaceKeyframe> LoadColmapKeyframes(
    const std::filesystem::path& model, std::unordered_map<PointId, Rgb8>* point_colors = nullptr,
    Eigen::Vector3d* world_up = nullptr);

// LoadColmapKeyframes on text in memory; `model` names the folder in the errors.
std::vector<SurfaceKeyframe> ParseColmapKeyframes(
    const ColmapTextModel& text, const std::filesystem::path& model,
    std::unordered_map<PointId, Rgb8>* point_colors = nullptr, Eigen::Vector3d* world_up = nullptr);

// The keyframe stream of a model in memory (ReadColmapModel of calib/colmap_text.h).
std::vector<SurfaceKeyframe> ColmapKeyframes(
    const ColmapModel& model, std::unordered_map<PointId, Rgb8>* point_colors = nullptr,
    Eigen::Vector3d* world_up = nullptr);

// The rig pose of one keyframe of ColmapKeyframes, in the model's world and units.
struct ColmapKeyframePose {
  std::string frame_name;  // the frame's name in a drive: "000123" from "cam0/000123.png" or
                           // from "f000123_c0.png"
  Rigid3d world_from_rig;
  size_t images = 0;  // registered images of the frame the pose is from
};

struct ColmapRigPoses {
  std::vector<ColmapKeyframePose> keyframes;  // in the order of ColmapKeyframes
  // The model's length unit per metre of the rig: the least-squares ratio of the distances
  // between the camera centres of a frame in the model to those in rig.json, over every pair of
  // registered images of a frame; 1 when no frame has two registered images of distinct centres.
  double model_units_per_metre = 1.0;
  size_t camera_pairs = 0;  // the pairs that measured it
};

// The rig poses of the keyframes of ColmapKeyframes(model): each image's camera is the rig camera
// of its folder's name ("cam3/000123.png": the camera named cam3) or of its index ("f000123_c3":
// the fourth camera of rig.json); world_from_rig's rotation is the mean over the frame's images
// of world_from_cam · cam_from_rig; it maps the rig's centre (Rig::CentralCenterInRig, what
// `omnisculpt eval` registers) to the mean over the images of the image's centre moved by its
// camera's offset from that centre (scaled by model_units_per_metre). Throws InputError naming the
// image when its camera is not in the rig or its name has no camera.
ColmapRigPoses ColmapKeyframeRigPoses(const ColmapModel& model, const Rig& rig);

}  // namespace omni
