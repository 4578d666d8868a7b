#include "sfm/track_builder.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_set>

#include "calib/error.h"
#include "calib/rig_report.h"
#include "sfm/internal/corner_cells.h"

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
  if (const std::string problem = descriptors.Check(); !problem.empty())
    return "descriptors." + problem;
  if (rematch_keyframes < 0) return "rematch_keyframes: expected 0 or more";
  if (!(continuation_pool >= 1.0 && continuation_pool <= 10.0))
    return "continuation_pool: expected a factor in [1, 10]";
  if (!(epipolar_min_depth >= 0.0) || !std::isfinite(epipolar_min_depth))
    return "epipolar_min_depth: expected 0 (off) or a positive number of steps";
  if (!(epipolar_search_radius > 0.0) || !std::isfinite(epipolar_search_radius))
    return "epipolar_search_radius: expected a positive number of pixels";
  if (!(epipolar_max_search_radius >= epipolar_search_radius) ||
      !std::isfinite(epipolar_max_search_radius))
    return "epipolar_max_search_radius: expected a number of pixels at least "
           "epipolar_search_radius";
  if (!(stereo_max_epipolar_angle > 0.0))
    return "stereo_max_epipolar_angle: expected a positive angle (radians)";
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

std::optional<RigMotion> PredictedMotion(const Tracker& tracker) {
  RigMotion motion;
  if (!tracker.PredictMotion(&motion.previous_world_from_rig, &motion.world_from_rig,
                             &motion.rotation_error, &motion.translation_error))
    return std::nullopt;
  return motion;
}

bool EpipolarSearchRegion(const Camera& camera, const RigMotion& motion,
                          const Eigen::Vector2d& pixel, double min_depth, double radius,
                          double downscale, SearchRegion* region) {
  Eigen::Vector3d bearing;
  if (!camera.Unproject(pixel, &bearing)) return false;
  // The new camera from the camera of the frame before.
  const Rigid3d new_from_previous = camera.cam_from_rig * motion.world_from_rig.Inverse() *
                                    motion.previous_world_from_rig * camera.cam_from_rig.Inverse();
  const double step = new_from_previous.translation.norm();
  Eigen::Vector2d far, near, middle;
  if (!camera.Project(new_from_previous.rotation * bearing, &far)) return false;
  // The near end: the corner's ray at `depth`; brought farther (up to 2^6 times) while it cannot
  // be imaged or the curve between the ends (the projection at twice that depth, halfway in
  // inverse depth) leaves the band around the segment.
  double depth = min_depth * step;
  constexpr int kTries = 7;
  int tries = 0;
  for (; tries < kTries; ++tries, depth *= 2.0) {
    if (!(depth > 0.0)) {
      near = far;
      break;
    }
    if (!camera.Project(new_from_previous * (depth * bearing), &near) ||
        !camera.Project(new_from_previous * (2.0 * depth * bearing), &middle))
      continue;
    if (std::sqrt(internal::SquaredDistanceToSegment(middle, far, near - far)) <=
        0.5 * radius * downscale)
      break;
  }
  if (tries == kTries) return false;
  region->center = InputToPreparedPixel(far, downscale);
  region->along = InputToPreparedPixel(near, downscale) - region->center;
  region->radius = radius;
  return true;
}

TrackBuilder::TrackBuilder(const Rig& rig, const TrackBuilderOptions& options)
    : rig_(rig),
      options_(CheckedOptions(options, "TrackBuilderOptions")),
      cameras_(rig.NumCameras()),
      map_search_(rig, options.map_search, options.harris.downscale) {
  // The camera pairs that see common directions (a property of the rig).
  const int num_cameras = static_cast<int>(rig.NumCameras());
  for (int a = 0; a < num_cameras; ++a)
    for (int b = a + 1; b < num_cameras; ++b) {
      if (ComputeViewOverlap(rig, a, b, 16) < 0.05 && ComputeViewOverlap(rig, b, a, 16) < 0.05)
        continue;
      overlapping_pairs_.emplace_back(a, b);
    }
}

HarrisOptions FrontEndHarrisOptions(const TrackBuilderOptions& options) {
  HarrisOptions harris = options.harris;
  harris.pool_corners =
      options.continuation_pool > 1.0
          ? static_cast<int>(std::lround(options.continuation_pool * harris.max_corners))
          : 0;
  return harris;
}

FrameCorners DetectFrameCorners(const std::vector<cv::Mat>& images, const HarrisOptions& options,
                                int zncc_half_window) {
  const auto start = std::chrono::steady_clock::now();
  const int num_cameras = static_cast<int>(images.size());
  FrameCorners detected;
  detected.prepared.resize(num_cameras);
  detected.corners.resize(num_cameras);
  detected.pool_begin.resize(num_cameras, 0);
  if (zncc_half_window > 0) detected.windows.resize(num_cameras);
  tbb::parallel_for(0, num_cameras, [&](int c) {
    detected.prepared[c] = PrepareImage(images[c], options);
    for (const Corner& corner :
         DetectHarrisCorners(detected.prepared[c], options, &detected.pool_begin[c]))
      detected.corners[c].push_back(corner.pixel);
    if (zncc_half_window > 0)
      detected.windows[c] =
          ComputeCornerWindows(detected.prepared[c], detected.corners[c], zncc_half_window);
  });
  detected.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return detected;
}

TrackedFrame TrackBuilder::AddFrame(const std::vector<cv::Mat>& images,
                                    const PixelPredictor& predict,
                                    const std::optional<RigMotion>& motion) {
  if (images.size() != rig_.NumCameras()) {
    throw std::invalid_argument("TrackBuilder::AddFrame: " + std::to_string(images.size()) +
                                " images for a rig of " + std::to_string(rig_.NumCameras()) +
                                " cameras");
  }
  FrameCorners detected =
      DetectFrameCorners(images, FrontEndHarrisOptions(options_), options_.zncc.half_window);
  timings_.detect += detected.seconds;
  return AddCorners(std::move(detected), predict, motion);
}

TrackedFrame TrackBuilder::AddDetectedFrame(FrameCorners detected, const PixelPredictor& predict,
                                            const std::optional<RigMotion>& motion) {
  if (detected.prepared.size() != rig_.NumCameras() ||
      detected.corners.size() != rig_.NumCameras()) {
    throw std::invalid_argument(
        "TrackBuilder::AddDetectedFrame: corners of " + std::to_string(detected.prepared.size()) +
        " cameras for a rig of " + std::to_string(rig_.NumCameras()) + " cameras");
  }
  if (!detected.windows.empty() && detected.windows.size() != rig_.NumCameras())
    throw std::invalid_argument("TrackBuilder::AddDetectedFrame: windows of " +
                                std::to_string(detected.windows.size()) + " cameras for a rig of " +
                                std::to_string(rig_.NumCameras()) + " cameras");
  timings_.detect_ahead += detected.seconds;
  return AddCorners(std::move(detected), predict, motion);
}

TrackedFrame TrackBuilder::AddCorners(FrameCorners detected, const PixelPredictor& predict,
                                      const std::optional<RigMotion>& motion) {
  const int num_cameras = static_cast<int>(rig_.NumCameras());
  TrackedFrame frame;
  frame.relocalising = lost_ && !keyframe_history_.empty();
  const std::vector<CameraState>& sources =
      frame.relocalising ? keyframe_history_.front().second : cameras_;
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

  std::vector<cv::Mat>& prepared = detected.prepared;
  std::vector<std::vector<Eigen::Vector2d>>& corners = detected.corners;
  // Corners given without their pool's place (FrameCorners made by hand) have no pool.
  std::vector<size_t>& pool_begin = detected.pool_begin;
  pool_begin.resize(num_cameras, std::numeric_limits<size_t>::max());
  const auto start = std::chrono::steady_clock::now();

  // Search regions (the predictor reads the tracker: called here, not in the parallel part).
  std::vector<std::vector<SearchRegion>> regions(num_cameras);
  std::vector<int> num_predicted(num_cameras, 0);
  // Per camera, the corners searched around their map point's reprojection: their depth is
  // known, so they are not searched along the whole epipolar segment.
  std::vector<std::vector<char>> reprojected(num_cameras);
  for (int c = 0; c < num_cameras; ++c) {
    const CameraState& source = sources[c];
    reprojected[c].assign(source.corners.size(), 0);
    for (size_t i = 0; i < source.corners.size(); ++i) {
      Eigen::Vector2d pixel;
      if (frame.relocalising) {
        regions[c].push_back({source.corners[i], options_.relocalisation_search_radius});
      } else if (predict && predict(c, source.tracks[i], &pixel)) {
        regions[c].push_back({InputToPreparedPixel(pixel, options_.harris.downscale),
                              options_.predicted_search_radius});
        reprojected[c][i] = 1;
        ++num_predicted[c];
      } else {
        regions[c].push_back({source.corners[i] + source.flow, options_.search_radius});
      }
    }
  }
  // Matching, in parallel over the cameras; then the corners left unmatched that have no map
  // point along their epipolar segments, against the corners left unmatched.
  const bool epipolar =
      motion.has_value() && !frame.relocalising && options_.epipolar_min_depth > 0.0;
  std::vector<std::vector<ZnccMatch>> matches(num_cameras);
  std::vector<int> num_epipolar(num_cameras, 0);
  tbb::parallel_for(0, num_cameras, [&](int c) {
    const CameraState& source = sources[c];
    if (source.corners.empty() || corners[c].empty()) return;
    const CornerWindows* windows = detected.windows.empty() ? nullptr : &detected.windows[c];
    matches[c] = MatchZncc(source.prepared, source.corners, regions[c], prepared[c], corners[c],
                           options_.zncc, pool_begin[c], windows);
    // The prediction's errors on the frame before, in pixels of this camera's prepared image:
    // the rotation's, and the translation's across the step seen at the segment's near end.
    if (!epipolar || !(motion->rotation_error >= 0.0)) return;
    const double focal = rig_.cameras[c].fx() / options_.harris.downscale;
    const double rotation_pixels = motion->rotation_error * focal;
    if (rotation_pixels > 0.5 * options_.epipolar_max_search_radius) return;
    const double translation_pixels =
        motion->translation_error > 0.0
            ? motion->translation_error * focal / options_.epipolar_min_depth
            : 0.0;
    const double band_radius =
        std::min(options_.epipolar_max_search_radius,
                 options_.epipolar_search_radius + rotation_pixels + translation_pixels);
    std::vector<char> matched1(source.corners.size(), 0), matched2(corners[c].size(), 0);
    for (const ZnccMatch& match : matches[c]) matched1[match.index1] = matched2[match.index2] = 1;
    std::vector<SearchRegion> segments(source.corners.size(), {Eigen::Vector2d::Zero(), -1.0});
    for (size_t i = 0; i < source.corners.size(); ++i) {
      if (matched1[i] || reprojected[c][i]) continue;
      if (!EpipolarSearchRegion(rig_.cameras[c], *motion,
                                PreparedToInputPixel(source.corners[i], options_.harris.downscale),
                                options_.epipolar_min_depth, band_radius, options_.harris.downscale,
                                &segments[i]))
        segments[i].radius = -1.0;
    }
    for (const ZnccMatch& match : MatchZncc(source.prepared, source.corners, segments, prepared[c],
                                            corners[c], options_.zncc, pool_begin[c], windows)) {
      if (matched2[match.index2]) continue;  // taken by the first search
      matches[c].push_back(match);
      ++num_epipolar[c];
    }
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
    frame.num_epipolar += num_epipolar[c];
    CameraState& state = cameras_[c];
    if (!dx.empty() && !frame.relocalising) {
      std::nth_element(dx.begin(), dx.begin() + dx.size() / 2, dx.end());
      std::nth_element(dy.begin(), dy.begin() + dy.size() / 2, dy.end());
      state.flow = Eigen::Vector2d(dx[dx.size() / 2], dy[dy.size() / 2]);
    } else if (frame.relocalising) {
      state.flow = Eigen::Vector2d::Zero();
    }
    // With a pool (FrontEndHarrisOptions): the corners that continue a track, then the others
    // in the detector's order (those before the pool first) up to max_corners.
    const int budget = options_.harris.max_corners;
    if (pool_begin[c] < corners[c].size() && static_cast<int>(corners[c].size()) > budget) {
      int kept = 0;
      std::vector<char> keep(corners[c].size(), 0);
      for (size_t i = 0; i < tracks.size(); ++i)
        if (tracks[i] >= 0) keep[i] = 1, ++kept;
      for (size_t i = 0; i < keep.size() && kept < budget; ++i)
        if (!keep[i]) keep[i] = 1, ++kept;
      size_t out = 0;
      for (size_t i = 0; i < keep.size(); ++i) {
        if (!keep[i]) continue;
        corners[c][out] = corners[c][i];
        tracks[out] = tracks[i];
        ++out;
      }
      corners[c].resize(out);
      tracks.resize(out);
    }
    for (int& track : tracks)
      if (track < 0) track = next_track_++;
    frame.num_corners += static_cast<int>(corners[c].size());
    state.prepared = prepared[c];
    state.corners = std::move(corners[c]);
    state.tracks = std::move(tracks);
    state.descriptors.release();
  }
  BuildObservations(&frame);
  timings_.match += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return frame;
}

void TrackBuilder::BuildObservations(TrackedFrame* frame) {
  frame->observations.clear();
  frame->pixels.clear();
  observation_corners_.clear();
  for (size_t c = 0; c < cameras_.size(); ++c) {
    const Camera& camera = rig_.cameras[c];
    const CameraState& state = cameras_[c];
    for (size_t i = 0; i < state.corners.size(); ++i) {
      const Eigen::Vector2d pixel =
          PreparedToInputPixel(state.corners[i], options_.harris.downscale);
      Eigen::Vector3d bearing;
      if (!camera.Unproject(pixel, &bearing)) continue;
      frame->observations.push_back({state.tracks[i], static_cast<int>(c), bearing});
      frame->pixels.push_back(pixel);
      observation_corners_.emplace_back(static_cast<int>(c), static_cast<int>(i));
    }
  }
}

const cv::Mat& TrackBuilder::Describe(CameraState* state) const {
  if (state->descriptors.empty() ||
      state->descriptors.rows !=
          static_cast<int>(state->corners.size()) * options_.descriptors.levels)
    state->descriptors = DescribeCorners(state->prepared, state->corners, options_.descriptors);
  return state->descriptors;
}

bool TrackBuilder::LastTrackedIsOwnReference() const {
  return last_tracked_.first >= 0 &&
         (keyframe_history_.empty() || keyframe_history_[0].first != last_tracked_.first);
}

int TrackBuilder::NumRematchReferences() const {
  if (options_.rematch_keyframes == 0) return 0;
  return static_cast<int>(keyframe_history_.size()) + (LastTrackedIsOwnReference() ? 1 : 0);
}

std::vector<TrackBuilder::CameraState>* TrackBuilder::RematchReference(int reference) {
  if (reference < 0 || reference >= NumRematchReferences()) return nullptr;
  const bool own_entry = LastTrackedIsOwnReference();
  if (own_entry && reference == 0) return &last_tracked_.second;
  return &keyframe_history_[reference - (own_entry ? 1 : 0)].second;
}

bool TrackBuilder::RematchByDescriptors(int reference, TrackedFrame* frame,
                                        const std::function<bool(int track)>& has_map_point) {
  std::vector<CameraState>* reference_state = RematchReference(reference);
  if (!reference_state) return false;
  const auto start = std::chrono::steady_clock::now();
  std::vector<CameraState>& keyframe = *reference_state;
  const int num_cameras = static_cast<int>(cameras_.size());
  // All cameras against all: a rig that turned sees a point in another camera.
  std::vector<std::pair<int, int>> rows_now, rows_then;  // (camera, corner) of each row
  // The descriptors of both frames' cameras, in parallel (each state is described once).
  tbb::parallel_for(0, 2 * num_cameras, [&](int task) {
    Describe(task < num_cameras ? &cameras_[task] : &keyframe[task - num_cameras]);
  });
  cv::Mat now, then, then_points;
  std::vector<int> point_rows;  // the rows of `then` whose track has a map point
  for (int c = 0; c < num_cameras; ++c) {
    now.push_back(cameras_[c].descriptors);
    then.push_back(keyframe[c].descriptors);
    for (size_t i = 0; i < cameras_[c].corners.size(); ++i) rows_now.emplace_back(c, i);
    for (size_t i = 0; i < keyframe[c].corners.size(); ++i) {
      if (has_map_point && has_map_point(keyframe[c].tracks[i])) {
        point_rows.push_back(static_cast<int>(rows_then.size()));
        const int levels = options_.descriptors.levels;
        then_points.push_back(keyframe[c].descriptors.rowRange(static_cast<int>(i) * levels,
                                                               static_cast<int>(i + 1) * levels));
      }
      rows_then.emplace_back(c, i);
    }
  }
  // First the reference's corners that are map points (the ratio test among them alone: a
  // map point is one of a few hundred, not of every corner, so more of them pass it), then
  // every corner for the corners left (tracks to triangulate later).
  std::vector<DescriptorMatch> matches;
  std::vector<char> used_now(rows_now.size(), 0), used_then(rows_then.size(), 0);
  if (!point_rows.empty())
    for (DescriptorMatch match : MatchDescriptors(now, then_points, options_.descriptors)) {
      match.index2 = point_rows[match.index2];
      used_now[match.index1] = used_then[match.index2] = 1;
      matches.push_back(match);
    }
  for (const DescriptorMatch& match : MatchDescriptors(now, then, options_.descriptors))
    if (!used_now[match.index1] && !used_then[match.index2]) matches.push_back(match);
  // The keyframe's track for each matched corner; a track is given to one corner per camera
  // (the first match: the map points' come first).
  std::vector<std::vector<int>> assigned(num_cameras);
  std::vector<std::unordered_set<int>> assigned_tracks(num_cameras);
  for (int c = 0; c < num_cameras; ++c) assigned[c].assign(cameras_[c].corners.size(), -1);
  for (const DescriptorMatch& match : matches) {
    const auto [c, i] = rows_now[match.index1];
    const auto [kc, ki] = rows_then[match.index2];
    const int track = keyframe[kc].tracks[ki];
    if (!assigned_tracks[c].insert(track).second) continue;
    assigned[c][i] = track;
  }
  // The association replaces the motion model's: a corner no descriptor matched starts a
  // new track.
  int matched = 0;
  for (int c = 0; c < num_cameras; ++c) {
    std::vector<int>& tracks = cameras_[c].tracks;
    for (size_t i = 0; i < tracks.size(); ++i) {
      tracks[i] = assigned[c][i] >= 0 ? assigned[c][i] : next_track_++;
      matched += assigned[c][i] >= 0;
    }
    cameras_[c].flow = Eigen::Vector2d::Zero();
  }
  frame->num_matched = matched;
  frame->relocalising = true;
  BuildObservations(frame);
  timings_.match += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return true;
}

int TrackBuilder::MatchOverlappingCameras(TrackedFrame* frame) {
  const auto start = std::chrono::steady_clock::now();
  int total = 0;
  for (const auto& [a, b] : overlapping_pairs_) {
    const Camera& camera_a = rig_.cameras[a];
    const Camera& camera_b = rig_.cameras[b];
    // b_from_a, and the baseline: without one the pair sees no depth.
    const Rigid3d b_from_a = camera_b.cam_from_rig * camera_a.cam_from_rig.Inverse();
    const Eigen::Vector3d baseline = b_from_a.translation;  // centre of a, in b's frame
    if (baseline.norm() < 1e-6) continue;
    CameraState& state_a = cameras_[a];
    CameraState& state_b = cameras_[b];
    // One instant, a baseline of centimetres: no change of scale between the two views, and
    // one scale keeps the ratio test as sharp as it can be.
    DescriptorMatchingOptions one_scale = options_.descriptors;
    one_scale.levels = 1;
    const std::vector<DescriptorMatch> matches =
        MatchDescriptors(DescribeCorners(state_a.prepared, state_a.corners, one_scale),
                         DescribeCorners(state_b.prepared, state_b.corners, one_scale), one_scale);
    std::unordered_set<int> tracks_b(state_b.tracks.begin(), state_b.tracks.end());
    for (const DescriptorMatch& match : matches) {
      Eigen::Vector3d bearing_a, bearing_b;
      if (!camera_a.Unproject(
              PreparedToInputPixel(state_a.corners[match.index1], options_.harris.downscale),
              &bearing_a) ||
          !camera_b.Unproject(
              PreparedToInputPixel(state_b.corners[match.index2], options_.harris.downscale),
              &bearing_b))
        continue;
      // In b's frame: ray a from the centre of a, ray b from the origin.
      const Eigen::Vector3d direction_a = b_from_a.rotation * bearing_a;
      const Eigen::Vector3d normal = baseline.cross(direction_a);
      if (normal.norm() < 1e-9) continue;
      const double epipolar =
          std::asin(std::min(1.0, std::abs(normal.normalized().dot(bearing_b.normalized()))));
      if (epipolar > options_.stereo_max_epipolar_angle) continue;
      // Depths along both rays (closest points of the two lines) must be positive.
      const Eigen::Vector3d w = baseline;  // from the origin of b to the centre of a
      const double aa = direction_a.dot(direction_a), bb = bearing_b.dot(bearing_b),
                   ab = direction_a.dot(bearing_b);
      const double denominator = aa * bb - ab * ab;
      if (denominator < 1e-12) continue;
      const double depth_a = (ab * bearing_b.dot(w) - bb * direction_a.dot(w)) / denominator;
      const double depth_b = (aa * bearing_b.dot(w) - ab * direction_a.dot(w)) / denominator;
      if (!(depth_a > 0.0 && depth_b > 0.0)) continue;
      const int track = state_a.tracks[match.index1];
      if (tracks_b.count(track)) continue;  // b sees that track already
      tracks_b.erase(state_b.tracks[match.index2]);
      state_b.tracks[match.index2] = track;
      tracks_b.insert(track);
      ++total;
    }
  }
  BuildObservations(frame);
  timings_.match += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return total;
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
  if (tracked && options_.rematch_keyframes > 0) last_tracked_ = {frame_index_, cameras_};
  if (!keyframe) return;
  // The last keyframe is always kept (the re-localisation's reference).
  keyframe_history_.insert(keyframe_history_.begin(), {frame_index_, cameras_});
  if (static_cast<int>(keyframe_history_.size()) > std::max(1, options_.rematch_keyframes))
    keyframe_history_.pop_back();
}

}  // namespace omni
