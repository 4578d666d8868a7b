#pragma once
// A COLMAP text model (cameras.txt, images.txt, points3D.txt; colmap.github.io/format.html) in
// memory: read strictly (every error names the file, the line and the field) and written back.
// The values are COLMAP's own (pixel centres at +0.5, cam_from_world poses); converting them to
// calib's conventions is the caller's business.

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "calib/ply.h"
#include "calib/pose.h"

namespace omni {

struct ColmapCamera {
  uint32_t id = 0;
  std::string model;  // e.g. PINHOLE, OPENCV, OPENCV_FISHEYE
  int width = 0, height = 0;
  std::vector<double> params;
};

struct ColmapPoint2D {
  Eigen::Vector2d xy = Eigen::Vector2d::Zero();
  int64_t point3d_id = -1;  // -1: no 3-D point
};

struct ColmapImage {
  uint32_t id = 0;
  Rigid3d cam_from_world;
  uint32_t camera_id = 0;
  std::string name;  // relative path, e.g. "images/cam0/000123.png"
  std::vector<ColmapPoint2D> points2d;
};

struct ColmapTrackElement {
  uint32_t image_id = 0;
  uint32_t point2d_idx = 0;
};

struct ColmapPoint3D {
  uint32_t id = 0;
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  Rgb8 color = Rgb8(128, 128, 128);
  double error = 0.0;
  std::vector<ColmapTrackElement> track;
};

struct ColmapModel {
  std::vector<ColmapCamera> cameras;
  std::vector<ColmapImage> images;  // in the file's order
  std::vector<ColmapPoint3D> points;
};

// The three files' text.
struct ColmapTextModel {
  std::string cameras;   // cameras.txt
  std::string images;    // images.txt
  std::string points3d;  // points3D.txt
};

// Parses the text; `model` names the folder in the errors. Throws InputError naming the file and
// line: a line with the wrong number of fields, a number that is not decimal or not finite, an
// identifier that is not an unsigned 32-bit integer or is repeated, a quaternion not of unit norm
// (within 1e-3; normalised otherwise), an image whose camera is not in cameras.txt, a track naming
// an unknown image. A track's POINT2D_IDX is not checked against the image's 2D points (models
// written by other tools often leave the 2D points out).
ColmapModel ParseColmapModel(const ColmapTextModel& text, const std::filesystem::path& model);
// Reads FOLDER/cameras.txt, images.txt and points3D.txt (InputError when one is missing).
ColmapModel ReadColmapModel(const std::filesystem::path& folder);
ColmapTextModel ReadColmapText(const std::filesystem::path& folder);
// The three files' text (full precision), and the files written atomically into `folder`
// (created).
ColmapTextModel FormatColmapModel(const ColmapModel& model);
void WriteColmapModel(const ColmapModel& model, const std::filesystem::path& folder);

}  // namespace omni
