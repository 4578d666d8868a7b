#include "sfm/track_builder.h"

#include <algorithm>
#include <cassert>

namespace omni {

std::string TrackBuilderOptions::Check() const {
  if (const std::string problem = harris.Check(); !problem.empty()) return "harris." + problem;
  if (const std::string problem = zncc.Check(); !problem.empty()) return "zncc." + problem;
  if (!(search_radius > 0.0)) return "search_radius: expected a positive number of pixels";
  return {};
}

TrackBuilder::TrackBuilder(const Rig& rig, const TrackBuilderOptions& options)
    : rig_(rig), options_(options), cameras_(rig.NumCameras()) {
  assert(options.Check().empty());
}

TrackedFrame TrackBuilder::AddFrame(const std::vector<cv::Mat>& images) {
  assert(images.size() == rig_.NumCameras());
  TrackedFrame frame;
  for (size_t c = 0; c < images.size(); ++c) {
    CameraState& state = cameras_[c];
    const cv::Mat prepared = PrepareImage(images[c], options_.harris);
    std::vector<Eigen::Vector2d> corners;
    for (const Corner& corner : DetectHarrisCorners(prepared, options_.harris))
      corners.push_back(corner.pixel);
    std::vector<int> tracks(corners.size(), -1);

    if (!state.corners.empty()) {
      std::vector<SearchRegion> regions;
      for (const Eigen::Vector2d& previous : state.corners)
        regions.push_back({previous + state.flow, options_.search_radius});
      const std::vector<ZnccMatch> matches =
          MatchZncc(state.prepared, state.corners, regions, prepared, corners, options_.zncc);
      std::vector<double> dx, dy;
      for (const ZnccMatch& match : matches) {
        tracks[match.index2] = state.tracks[match.index1];
        dx.push_back(corners[match.index2].x() - state.corners[match.index1].x());
        dy.push_back(corners[match.index2].y() - state.corners[match.index1].y());
      }
      frame.num_matched += static_cast<int>(matches.size());
      if (!dx.empty()) {
        std::nth_element(dx.begin(), dx.begin() + dx.size() / 2, dx.end());
        std::nth_element(dy.begin(), dy.begin() + dy.size() / 2, dy.end());
        state.flow = Eigen::Vector2d(dx[dx.size() / 2], dy[dy.size() / 2]);
      }
    }
    const Camera& camera = rig_.cameras[c];
    for (size_t i = 0; i < corners.size(); ++i) {
      if (tracks[i] < 0) tracks[i] = next_track_++;
      const Eigen::Vector2d pixel = PreparedToInputPixel(corners[i], options_.harris.downscale);
      Eigen::Vector3d bearing;
      if (!camera.Unproject(pixel, &bearing)) continue;
      frame.observations.push_back({tracks[i], static_cast<int>(c), bearing});
      frame.pixels.push_back(pixel);
    }
    frame.num_corners += static_cast<int>(corners.size());
    state.prepared = prepared;
    state.corners = std::move(corners);
    state.tracks = std::move(tracks);
  }
  return frame;
}

}  // namespace omni
