#pragma once
// Colours of the SfM points for points.ply and the COLMAP model's points3D.txt (`omnisculpt
// sfm` and `reconstruct`): each point gets the mean, over its observations, of the image
// colour at the observed pixel (bilinear), as COLMAP's
// Reconstruction::ExtractColorsForAllImages. Done at output time from the finalised keyframes,
// so the SfM thread never reads a colour image; each keyframe image is read once.

#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <unordered_map>
#include <vector>

#include "calib/ply.h"
#include "calib/rig.h"
#include "sfm/tracker.h"
#include "surface/sculptor.h"

namespace omni {

struct PointColorOptions {
  // Colour of a point none of whose observations could be sampled (outside its image, or the
  // image unreadable): the grey of the files before points had colours.
  int fallback_grey = 128;

  std::string Check() const;
};

struct PointColorStats {
  size_t images_read = 0;
  size_t images_unreadable = 0;  // skipped with a warning: their observations give no colour
  size_t samples = 0;            // observations sampled
  size_t points_uncoloured = 0;  // given fallback_grey
  double seconds = 0.0;
};

// The image of `camera` at drive frame `frame`, 8-bit RGB (CV_8UC3, e.g. Drive::LoadRgb); it
// may throw InputError (the image is then skipped).
using RgbImageLoader = std::function<cv::Mat(int frame, int camera)>;

// One colour per point of `keyframes`, in their order (keyframe by keyframe, then its points:
// the order of points.ply and of the COLMAP writer). An observation is a ray of the point: its
// keyframe's frame, its camera, and the pixel its bearing projects to.
std::vector<Rgb8> ColorPoints(const Rig& rig, const std::vector<FinalizedKeyframe>& keyframes,
                              const RgbImageLoader& load_rgb, const PointColorOptions& options = {},
                              PointColorStats* stats = nullptr);

// A sculptor's two surfaces, each vertex coloured as its point (ColorMeshVertices of
// surface/sculptor.h; grey for a Steiner vertex or a point without a colour): the closed δO
// (surface_closed.ply) and its observed part (surface.ply).
struct ColoredSurfaces {
  TriangleMesh closed, observed;
  ObservedMeshStats observed_stats;
};
ColoredSurfaces ExtractColoredSurfaces(const IncrementalSculptor& sculptor,
                                       const std::unordered_map<PointId, Rgb8>& point_colors);

// Bilinear sample of an 8-bit RGB image at a pixel (integer coordinates at pixel centres, as
// calib), the border pixels repeated outside.
Eigen::Vector3d SampleRgbBilinear(const cv::Mat& rgb, const Eigen::Vector2d& pixel);

}  // namespace omni
