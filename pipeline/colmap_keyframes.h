#pragma once
// The keyframe stream of docs/design.md §7 from a COLMAP text model (cameras.txt, images.txt,
// points3D.txt), for `omnisculpt surface --colmap` and `omnisculpt merge`. Images whose names
// share a frame (the same file name in sibling camera folders, e.g. "cam0/000123.png" and
// "cam1/000123.png", or "d1/images/cam0/000123.png" and "d1/images/cam1/000123.png") form one
// keyframe, a rig frame; otherwise every image is a keyframe. Keyframes are ordered by frame
// name: the name without its camera folder ("000123.png", "d1/images/000123.png"). A point goes to
// the latest keyframe of its track (paper §3.3: observed by keyframes t' ≤ t) with one ray per
// observing image, starting at that camera's centre.

#include <filesystem>
#include <string>
#include <unordered_map>
#include <vector>

#include "calib/colmap_text.h"
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

}  // namespace omni
