#include "sfm/track_builder.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <stdexcept>

#include "calib/error.h"

namespace omni {

std::string TrackBuilderOptions::Check() const {
  if (const std::string problem = harris.Check(); !problem.empty()) return "harris." + problem;
  if (const std::string problem = zncc.Check(); !problem.empty()) return "zncc." + problem;
  if (!(search_radius > 0.0)) return "search_radius: expected a positive number of pixels";
  if (!(predicted_search_radius > 0.0))
    return "predicted_search_radius: expected a positive number of pixels";
  if (!(relocalisation_search_radius > 0.0))
    return "relocalisation_search_radius: expected a positive number of pixels";
  if (const std::string problem = map_search.Check(); !problem.empty())
    return "map_search." + problem;
  return {};
}

PixelPredictor ReprojectionPredictor(const Tracker& tracker, const Rig& rig) {
  Rigid3d predicted;
  if (!tracker.PredictPose(&predicted)) return {};
  const Rigid3d rig_from_world = predicted.Inverse();
  return [&tracker, &rig, rig_from_world](int camera, int track, Eigen::Vector2d* pixel) {
    Eigen::Vector3d position;
    if (!tracker.TrackPosition(track, &position)) return false;
    const Camera& model = rig.cameras[camera];
    return model.Project(model.cam_from_rig * (rig_from_world * position), pixel) &&
           model.IsInImage(*pixel);
  };
}

TrackBuilder::TrackBuilder(const Rig& rig, const TrackBuilderOptions& options)
    : rig_(rig),
      options_(CheckedOptions(options, "TrackBuilderOptions")),
      cameras_(rig.NumCameras()),
      map_search_(rig, options.map_search, options.harris.downscale) {}

TrackedFrame TrackBuilder::AddFrame(const std::vector<cv::Mat>& images,
                                    const PixelPredictor& predict) {
  if (images.size() != rig_.NumCameras()) {
    throw std::invalid_argument("TrackBuilder::AddFrame: " + std::to_string(images.size()) +
                                " images for a rig of " + std::to_string(rig_.NumCameras()) +
                                " cameras");
  }
  const int num_cameras = static_cast<int>(images.size());
  TrackedFrame frame;
  frame.relocalising = lost_ && !keyframe_cameras_.empty();
  const std::vector<CameraState>& sources = frame.relocalising ? keyframe_cameras_ : cameras_;
  // The previous frame's corners, with their final tracks (after the map-point search), are
  // the most recent observations of their tracks: their windows become the references.
  if (options_.map_search.enabled && frame_index_ >= 0) {
    const auto start = std::chrono::steady_clock::now();
    for (const CameraState& state : cameras_)
      map_search_.Remember(frame_index_, state.prepared, state.corners, state.tracks);
    // A reference lives max_reference_age frames, give or take a tenth of that.
    const int sweep = std::max(1, options_.map_search.max_reference_age / 10);
    if (frame_index_ % sweep == 0) map_search_.Forget(frame_index_);
    timings_.map_search +=
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  ++frame_index_;
  observation_corners_.clear();

  // Detection, in parallel over the cameras.
  auto start = std::chrono::steady_clock::now();
  std::vector<cv::Mat> prepared(num_cameras);
  std::vector<std::vector<Eigen::Vector2d>> corners(num_cameras);
  tbb::parallel_for(0, num_cameras, [&](int c) {
    prepared[c] = PrepareImage(images[c], options_.harris);
    for (const Corner& corner : DetectHarrisCorners(prepared[c], options_.harris))
      corners[c].push_back(corner.pixel);
  });
  auto now = std::chrono::steady_clock::now();
  timings_.detect += std::chrono::duration<double>(now - start).count();
  start = now;

  // Search regions (the predictor reads the tracker: called here, not in the parallel part).
  std::vector<std::vector<SearchRegion>> regions(num_cameras);
  std::vector<int> num_predicted(num_cameras, 0);
  for (int c = 0; c < num_cameras; ++c) {
    const CameraState& source = sources[c];
    for (size_t i = 0; i < source.corners.size(); ++i) {
      Eigen::Vector2d pixel;
      if (frame.relocalising) {
        regions[c].push_back({source.corners[i], options_.relocalisation_search_radius});
      } else if (predict && predict(c, source.tracks[i], &pixel)) {
        regions[c].push_back({InputToPreparedPixel(pixel, options_.harris.downscale),
                              options_.predicted_search_radius});
        ++num_predicted[c];
      } else {
        regions[c].push_back({source.corners[i] + source.flow, options_.search_radius});
      }
    }
  }
  // Matching, in parallel over the cameras.
  std::vector<std::vector<ZnccMatch>> matches(num_cameras);
  tbb::parallel_for(0, num_cameras, [&](int c) {
    const CameraState& source = sources[c];
    if (source.corners.empty() || corners[c].empty()) return;
    matches[c] = MatchZncc(source.prepared, source.corners, regions[c], prepared[c], corners[c],
                           options_.zncc);
  });

  for (int c = 0; c < num_cameras; ++c) {
    const CameraState& source = sources[c];
    std::vector<int> tracks(corners[c].size(), -1);
    std::vector<double> dx, dy;
    for (const ZnccMatch& match : matches[c]) {
      tracks[match.index2] = source.tracks[match.index1];
      // The subpixel ZNCC maximum of the previous window, not the detector's corner (Harris
      // corners sit up to half a pixel off): the track follows the same physical point.
      if (options_.follow_window) corners[c][match.index2] = match.pixel2;
      dx.push_back(corners[c][match.index2].x() - source.corners[match.index1].x());
      dy.push_back(corners[c][match.index2].y() - source.corners[match.index1].y());
    }
    frame.num_matched += static_cast<int>(matches[c].size());
    frame.num_predicted += num_predicted[c];
    CameraState& state = cameras_[c];
    if (!dx.empty() && !frame.relocalising) {
      std::nth_element(dx.begin(), dx.begin() + dx.size() / 2, dx.end());
      std::nth_element(dy.begin(), dy.begin() + dy.size() / 2, dy.end());
      state.flow = Eigen::Vector2d(dx[dx.size() / 2], dy[dy.size() / 2]);
    } else if (frame.relocalising) {
      state.flow = Eigen::Vector2d::Zero();
    }
    const Camera& camera = rig_.cameras[c];
    for (size_t i = 0; i < corners[c].size(); ++i) {
      if (tracks[i] < 0) tracks[i] = next_track_++;
      const Eigen::Vector2d pixel = PreparedToInputPixel(corners[c][i], options_.harris.downscale);
      Eigen::Vector3d bearing;
      if (!camera.Unproject(pixel, &bearing)) continue;
      frame.observations.push_back({tracks[i], c, bearing});
      frame.pixels.push_back(pixel);
      observation_corners_.emplace_back(c, static_cast<int>(i));
    }
    frame.num_corners += static_cast<int>(corners[c].size());
    state.prepared = prepared[c];
    state.corners = std::move(corners[c]);
    state.tracks = std::move(tracks);
  }
  timings_.match += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return frame;
}

MapPointSearchFn TrackBuilder::MapPointSearcher() {
  return
      [this](const std::vector<MapPointProjection>& candidates, const std::vector<char>& eligible) {
        return SearchMapPoints(candidates, eligible);
      };
}

std::vector<Reobservation> TrackBuilder::SearchMapPoints(
    const std::vector<MapPointProjection>& candidates, const std::vector<char>& eligible) {
  assert(eligible.size() == observation_corners_.size());
  if (!options_.map_search.enabled || candidates.empty()) return {};
  const auto start = std::chrono::steady_clock::now();
  const size_t num_cameras = cameras_.size();
  std::vector<cv::Mat> prepared(num_cameras);
  std::vector<std::vector<Eigen::Vector2d>> corners(num_cameras);
  std::vector<std::vector<char>> eligible_corners(num_cameras);
  std::vector<std::vector<int>> observation_of(num_cameras);
  for (size_t c = 0; c < num_cameras; ++c) {
    prepared[c] = cameras_[c].prepared;
    corners[c] = cameras_[c].corners;
    eligible_corners[c].assign(corners[c].size(), 0);
    observation_of[c].assign(corners[c].size(), -1);
  }
  for (size_t i = 0; i < observation_corners_.size(); ++i) {
    const auto [c, corner] = observation_corners_[i];
    eligible_corners[c][corner] = eligible[i];
    observation_of[c][corner] = static_cast<int>(i);
  }
  std::vector<Reobservation> result;
  for (const MapPointSearch::Match& match :
       map_search_.Search(candidates, prepared, corners, eligible_corners)) {
    const MapPointProjection& candidate = candidates[match.candidate];
    CameraState& state = cameras_[candidate.camera];
    Eigen::Vector3d bearing;
    const Eigen::Vector2d pixel = PreparedToInputPixel(match.pixel, options_.harris.downscale);
    if (!rig_.cameras[candidate.camera].Unproject(pixel, &bearing)) continue;
    if (match.corner >= 0) {
      // The corner takes the point's track, at the ZNCC maximum (the corner itself when only
      // corners are searched).
      state.tracks[match.corner] = candidate.track;
      state.corners[match.corner] = match.pixel;
      result.push_back({observation_of[candidate.camera][match.corner], candidate.track,
                        candidate.camera, bearing});
      continue;
    }
    // A new observation where no corner was detected: it becomes a corner of the frame, so
    // that the next frame continues the track from it.
    state.corners.push_back(match.pixel);
    state.tracks.push_back(candidate.track);
    observation_corners_.emplace_back(candidate.camera, static_cast<int>(state.corners.size()) - 1);
    result.push_back({-1, candidate.track, candidate.camera, bearing});
  }
  timings_.map_search +=
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return result;
}

void TrackBuilder::SetFrameResult(bool tracked, bool keyframe) {
  lost_ = !tracked;
  if (tracked && keyframe) keyframe_cameras_ = cameras_;
}

}  // namespace omni
