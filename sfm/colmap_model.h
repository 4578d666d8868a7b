#pragma once
// A COLMAP text model (cameras.txt, images.txt, points3D.txt; colmap.github.io/format.html)
// of the finalised keyframes of the tracker: one COLMAP camera per rig camera (models
// PINHOLE, OPENCV or FULL_OPENCV, OPENCV_FISHEYE from calib's pinhole, opencv, fisheye), one
// image per camera per keyframe named by `image_name` (e.g. "images/cam0/000123.png"), and one
// 3-D point per finalised point with its observations as 2-D points; the points' rays of tracked
// frames between keyframes and the frame points go to frame_rays.txt (calib/colmap_text.h).
// COLMAP puts pixel centres at +0.5 (the image covers [0, width)), calib at integers: principal
// points and 2-D points are shifted by 0.5.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "calib/rig.h"
#include "sfm/tracker.h"

namespace omni {

struct ColmapModelStats {
  int images = 0;
  int points = 0;
  int observations = 0;                  // 2-D points with a 3-D point
  double mean_reprojection_error = 0.0;  // pixels, over the observations
  int frame_ray_points = 0;              // lines of frame_rays.txt
};

// Writes the three files into `folder` (created), each atomically, and frame_rays.txt when a
// point has frame rays (an earlier one is removed otherwise). `image_name(frame, camera)` names
// the image of a frame. Points with no observation that projects are left out.
// `colors`: empty (every point grey 128) or one RGB colour per point of `keyframes` in their
// order, keyframe by keyframe (e.g. pipeline/point_colors.h).
ColmapModelStats WriteColmapTextModel(
    const Rig& rig, const std::vector<FinalizedKeyframe>& keyframes,
    const std::function<std::string(int frame, int camera)>& image_name,
    const std::filesystem::path& folder,
    const std::vector<Eigen::Matrix<uint8_t, 3, 1>>& colors = {});

// COLMAP's name of a calib camera model and its parameters (COLMAP pixel convention).
std::string ColmapCameraModel(const Camera& camera, std::vector<double>* params);

}  // namespace omni
