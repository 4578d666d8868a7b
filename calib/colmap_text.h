#pragma once
// A COLMAP text model (cameras.txt, images.txt, points3D.txt; colmap.github.io/format.html) in
// memory: read strictly (every error names the file, the line and the field) and written back.
// The values are COLMAP's own (pixel centres at +0.5, cam_from_world poses); converting them to
// calib's conventions is the caller's business.
//
// Beside the three files, omnisculpt's models may hold a fourth that COLMAP ignores,
// frame_rays.txt: the rays of the tracked frames between keyframes, which the surface sculpts
// with but images.txt cannot hold (those frames have no image in the model). One line per point
// that has such rays:
//   POINT3D_ID X Y Z R G B NUM_RAYS RAYS[] as (IMAGE_NAME CX CY CZ)
// POINT3D_ID is a point of points3D.txt (whose keyframe rays the line completes), or 0 for a
// frame point: a track that lived between two keyframes only, in no image of the model. X Y Z
// and R G B are the point's position and colour. Each ray names the image of the frame and
// camera that observed the point, as images.txt would name it, and gives that camera's optical
// centre CX CY CZ in the model's world.

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

// A ray of frame_rays.txt (see top).
struct ColmapFrameRay {
  std::string image_name;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
};

// A line of frame_rays.txt (see top).
struct ColmapFrameRayPoint {
  uint32_t point3d_id = 0;  // 0: a frame point
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  Rgb8 color = Rgb8(128, 128, 128);
  std::vector<ColmapFrameRay> rays;  // at least one
};

struct ColmapModel {
  std::vector<ColmapCamera> cameras;
  std::vector<ColmapImage> images;  // in the file's order
  std::vector<ColmapPoint3D> points;
  std::vector<ColmapFrameRayPoint> frame_rays;  // frame_rays.txt; empty without the file
};

// The files' text.
struct ColmapTextModel {
  std::string cameras;     // cameras.txt
  std::string images;      // images.txt
  std::string points3d;    // points3D.txt
  std::string frame_rays;  // frame_rays.txt, empty when the model has none
};

// Parses the text; `model` names the folder in the errors. Throws InputError naming the file and
// line: a line with the wrong number of fields, a number that is not decimal or not finite, an
// identifier that is not an unsigned 32-bit integer or is repeated, a quaternion not of unit norm
// (within 1e-3; normalised otherwise), an image whose camera is not in cameras.txt, a track naming
// an unknown image; in frame_rays.txt, a POINT3D_ID neither 0 nor in points3D.txt, or a count of
// rays that is not the line's. A track's POINT2D_IDX is not checked against the image's 2D points
// (models written by other tools often leave the 2D points out).
ColmapModel ParseColmapModel(const ColmapTextModel& text, const std::filesystem::path& model);
// Reads FOLDER/cameras.txt, images.txt and points3D.txt (InputError when one is missing), and
// FOLDER/frame_rays.txt when it exists.
ColmapModel ReadColmapModel(const std::filesystem::path& folder);
// The angle one pixel spans at the centre of the model's finest camera (radians; 1 / the
// largest focal length, the first parameter of every COLMAP camera model); 0 without cameras.
double ColmapFinestPixelAngle(const ColmapModel& model);
ColmapTextModel ReadColmapText(const std::filesystem::path& folder);
// The files' text (full precision), and the files written atomically into `folder` (created);
// frame_rays.txt only when the model has frame rays.
ColmapTextModel FormatColmapModel(const ColmapModel& model);
void WriteColmapModel(const ColmapModel& model, const std::filesystem::path& folder);
// The text of frame_rays.txt.
std::string FormatColmapFrameRays(const std::vector<ColmapFrameRayPoint>& points);

}  // namespace omni
