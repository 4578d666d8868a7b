#include "sfm/loop_closure.h"

#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <unordered_map>

#include "sfm/harris.h"
#include "sfm/zncc_matching.h"

namespace omni {

std::string LoopDetectionOptions::Check() const {
  if (thumbnail_width < 2 || thumbnail_height < 2) return "thumbnail size: at least 2x2";
  if (!(ring_max_elevation > 0.0)) return "ring_max_elevation: expected a positive angle";
  if (min_keyframe_gap < 1) return "min_keyframe_gap: expected at least 1";
  if (!(min_score > -1.0 && min_score <= 1.0)) return "min_score: expected in (-1, 1]";
  return {};
}

LoopDetector::LoopDetector(const Rig& rig, const LoopDetectionOptions& options)
    : options_(options) {
  assert(options.Check().empty());
  const size_t n = rig.cameras.size();
  std::vector<Eigen::Vector3d> axes;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Camera& camera : rig.cameras) {
    axes.push_back(camera.cam_from_rig.rotation.conjugate() * Eigen::Vector3d::UnitZ());
    scatter += axes.back() * axes.back().transpose();
  }
  if (n < 3) {
    ring_.resize(n);
    std::iota(ring_.begin(), ring_.end(), 0);
    return;
  }
  // The ring's axis: the direction the optical axes spread least along.
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(scatter);
  const Eigen::Vector3d normal = solver.eigenvectors().col(0);
  const Eigen::Vector3d x = normal.unitOrthogonal(), y = normal.cross(x);
  std::vector<std::pair<double, int>> by_azimuth;
  for (size_t c = 0; c < n; ++c)
    if (std::abs(std::asin(std::clamp(axes[c].dot(normal), -1.0, 1.0))) <
        options.ring_max_elevation)
      by_azimuth.emplace_back(std::atan2(axes[c].dot(y), axes[c].dot(x)), static_cast<int>(c));
  std::sort(by_azimuth.begin(), by_azimuth.end());
  for (const auto& [azimuth, camera] : by_azimuth) ring_.push_back(camera);
}

PlaceDescriptor LoopDetector::Describe(const std::vector<cv::Mat>& images) const {
  PlaceDescriptor descriptor;
  for (const cv::Mat& image : images) {
    cv::Mat grey = image, small;
    if (image.channels() == 3) cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
    cv::resize(grey, small, cv::Size(options_.thumbnail_width, options_.thumbnail_height), 0, 0,
               cv::INTER_AREA);
    small.convertTo(small, CV_32F);
    std::vector<float> values(small.begin<float>(), small.end<float>());
    const double mean = std::accumulate(values.begin(), values.end(), 0.0) / values.size();
    double norm = 0.0;
    for (float& v : values) {
      v = static_cast<float>(v - mean);
      norm += static_cast<double>(v) * v;
    }
    norm = std::sqrt(norm);
    for (float& v : values) v = norm > 0.0 ? static_cast<float>(v / norm) : 0.0f;
    descriptor.cameras.push_back(std::move(values));
  }
  return descriptor;
}

int LoopDetector::Add(PlaceDescriptor descriptor) {
  descriptors_.push_back(std::move(descriptor));
  return size() - 1;
}

double LoopDetector::Score(const PlaceDescriptor& query, const PlaceDescriptor& candidate,
                           int shift) const {
  const int n = static_cast<int>(ring_.size());
  if (n == 0) return -1.0;
  double sum = 0.0;
  for (int i = 0; i < n; ++i) {
    const std::vector<float>& a = query.cameras[ring_[i]];
    const std::vector<float>& b = candidate.cameras[ring_[((i + shift) % n + n) % n]];
    sum += std::inner_product(a.begin(), a.end(), b.begin(), 0.0);
  }
  return sum / n;
}

LoopCandidate LoopDetector::Query(const PlaceDescriptor& query, int before) const {
  LoopCandidate best;
  const int end = std::min(size(), before - options_.min_keyframe_gap + 1);
  for (int k = 0; k < end; ++k)
    for (int shift = 0; shift < static_cast<int>(ring_.size()); ++shift) {
      const double score = Score(query, descriptors_[k], shift);
      if (score > best.score) best = {k, shift, score};
    }
  if (best.score < options_.min_score) best.keyframe = -1;
  return best;
}

std::string LoopClosureOptions::Check() const {
  for (const auto& [name, check] :
       {std::pair<const char*, std::string>{"detection", detection.Check()},
        {"matching", matching.Check()},
        {"pose_graph", pose_graph.Check()}})
    if (!check.empty()) return std::string(name) + "." + check;
  if (!(prepared_downscale >= 1.0)) return "prepared_downscale: expected at least 1";
  if (ransac_iterations < 1) return "ransac_iterations: expected at least 1";
  if (!(inlier_depth_share > 0.0)) return "inlier_depth_share: expected a positive share";
  if (min_inliers < 3) return "min_inliers: expected at least 3";
  if (!(max_drift_share > 0)) return "max_drift_share: expected more than 0";
  if (cooldown_keyframes < 0) return "cooldown_keyframes: expected 0 or more";
  if (!(loop_edge_weight > 0.0)) return "loop_edge_weight: expected a positive weight";
  return {};
}

std::string LoopClosureEvent::Summary() const {
  std::ostringstream o;
  o << "loop closed at keyframe " << keyframe << " (frame " << frame << ") with keyframe "
    << candidate_keyframe << " (frame " << candidate_frame << "), ring shift " << shift
    << ", appearance " << score << ", " << inliers << " of " << matches
    << " matched points agree; the revisit moved by " << correction_translation << " (scale x"
    << correction_scale << ") in " << ms << " ms";
  return o.str();
}

LoopCloser::LoopCloser(const Rig& rig, const LoopClosureOptions& options)
    : rig_(rig), options_(options), detector_(rig, options.detection) {
  assert(options.Check().empty());
}

double LoopDriftShare(const std::vector<Rigid3d>& world_from_rig, int then, int now,
                      const Sim3d& then_from_now) {
  double path = 0.0;
  for (int i = then; i < now; ++i)
    path += (world_from_rig[i + 1].translation - world_from_rig[i].translation).norm();
  const Eigen::Vector3d& centre = world_from_rig[now].translation;
  const double move = (then_from_now * centre - centre).norm();
  return path > 0.0 ? move / path : std::numeric_limits<double>::infinity();
}

bool LoopCloser::AddKeyframe(const std::vector<cv::Mat>& images, const TrackedFrame& frame,
                             Tracker* tracker, LoopClosureEvent* event) {
  const auto start = std::chrono::steady_clock::now();
  const int k = tracker->NumKeyframes() - 1;
  if (k != static_cast<int>(keyframes_.size())) return false;  // a keyframe was missed
  KeyframeData data;
  data.frame = tracker->KeyframeFrames().back();
  HarrisOptions prepare;
  prepare.downscale = options_.prepared_downscale;
  data.corners.resize(images.size());
  data.tracks.resize(images.size());
  for (const cv::Mat& image : images) data.prepared.push_back(PrepareImage(image, prepare));
  for (size_t i = 0; i < frame.observations.size(); ++i) {
    const TrackObservation& o = frame.observations[i];
    data.corners[o.camera].push_back(InputToPreparedPixel(frame.pixels[i], prepare.downscale));
    data.tracks[o.camera].push_back(o.track);
  }
  const PlaceDescriptor descriptor = detector_.Describe(images);
  detector_.Add(descriptor);
  keyframes_.push_back(std::move(data));
  if (k - last_closure_ < options_.cooldown_keyframes) return false;
  const LoopCandidate candidate = detector_.Query(descriptor, k);
  if (candidate.keyframe < 0) return false;

  // Matches between the ring cameras of the revisit and the shifted ones of the candidate.
  const KeyframeData& now = keyframes_[k];
  const KeyframeData& then = keyframes_[candidate.keyframe];
  std::unordered_map<int, Eigen::Vector3d> now_points, then_points;
  for (const auto& [track, position] : tracker->KeyframeTrackPoints(k))
    now_points.emplace(track, position);
  for (const auto& [track, position] : tracker->KeyframeTrackPoints(candidate.keyframe))
    then_points.emplace(track, position);
  std::vector<Eigen::Vector3d> src, dst;    // now (drifted) -> then
  std::vector<std::pair<int, int>> tracks;  // (now, then) of each pair
  const std::vector<int>& ring = detector_.ring();
  const int n = static_cast<int>(ring.size());
  for (int i = 0; i < n; ++i) {
    const int a = ring[i], b = ring[(i + candidate.shift) % n];
    const double radius =
        std::hypot(then.prepared[b].cols, then.prepared[b].rows);  // anywhere in the image
    std::vector<SearchRegion> regions;
    for (const Eigen::Vector2d& corner : now.corners[a]) regions.push_back({corner, radius});
    for (const ZnccMatch& match : MatchZncc(now.prepared[a], now.corners[a], regions,
                                            then.prepared[b], then.corners[b], options_.matching)) {
      const auto p = now_points.find(now.tracks[a][match.index1]);
      const auto q = then_points.find(then.tracks[b][match.index2]);
      if (p == now_points.end() || q == then_points.end()) continue;
      src.push_back(p->second);
      dst.push_back(q->second);
      tracks.emplace_back(p->first, q->first);
    }
  }
  LoopClosureEvent result;
  result.keyframe = k;
  result.frame = now.frame;
  result.candidate_keyframe = candidate.keyframe;
  result.candidate_frame = then.frame;
  result.shift = candidate.shift;
  result.score = candidate.score;
  result.matches = static_cast<int>(src.size());
  if (result.matches < options_.min_inliers) return false;

  // Similarity then_from_now in RANSAC (three-point Umeyama samples).
  const std::vector<Rigid3d> poses = tracker->KeyframePoses();
  std::vector<double> depths;
  for (const Eigen::Vector3d& q : dst)
    depths.push_back((q - poses[candidate.keyframe].translation).norm());
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
  const double threshold = options_.inlier_depth_share * depths[depths.size() / 2];
  std::mt19937 rng(options_.seed + static_cast<unsigned>(k));
  std::uniform_int_distribution<size_t> pick(0, src.size() - 1);
  std::vector<int> best_inliers;
  auto inliers_of = [&](const Sim3d& s) {
    std::vector<int> inliers;
    for (size_t i = 0; i < src.size(); ++i)
      if ((s * src[i] - dst[i]).norm() < threshold) inliers.push_back(static_cast<int>(i));
    return inliers;
  };
  for (int iteration = 0; iteration < options_.ransac_iterations; ++iteration) {
    const size_t i0 = pick(rng), i1 = pick(rng), i2 = pick(rng);
    if (i0 == i1 || i1 == i2 || i0 == i2) continue;
    const Eigen::Vector3d e1 = src[i1] - src[i0], e2 = src[i2] - src[i0];
    if (e1.cross(e2).norm() < 1e-6 * e1.squaredNorm()) continue;
    const Sim3d s = EstimateSim3Umeyama({src[i0], src[i1], src[i2]}, {dst[i0], dst[i1], dst[i2]});
    std::vector<int> inliers = inliers_of(s);
    if (inliers.size() > best_inliers.size()) best_inliers = std::move(inliers);
  }
  if (static_cast<int>(best_inliers.size()) < options_.min_inliers) return false;
  std::vector<Eigen::Vector3d> in_src, in_dst;
  std::vector<std::pair<int, int>> in_tracks;
  for (int i : best_inliers) {
    in_src.push_back(src[i]);
    in_dst.push_back(dst[i]);
    in_tracks.push_back(tracks[i]);
  }
  Sim3d then_from_now = EstimateSim3Umeyama(in_src, in_dst);
  result.inliers = static_cast<int>(inliers_of(then_from_now).size());
  if (result.inliers < options_.min_inliers) return false;
  const double drift_share = LoopDriftShare(poses, candidate.keyframe, k, then_from_now);
  if (!(drift_share <= options_.max_drift_share)) {
    spdlog::info(
        "loop closure: keyframe {} with keyframe {} rejected: the correction would move "
        "it by {:.1f} % of the path between them",
        k, candidate.keyframe, 100.0 * drift_share);
    return false;
  }

  // Pose graph over every keyframe: odometry edges (neighbours one and two apart) as the map
  // is now, and the loop edge where the revisit should be.
  std::vector<Sim3d> nodes;
  for (const Rigid3d& pose : poses) nodes.emplace_back(1.0, pose.rotation, pose.translation);
  const std::vector<Sim3d> before = nodes;
  std::vector<PoseGraphEdge> edges;
  for (int i = 0; i < static_cast<int>(nodes.size()); ++i)
    for (int d = 1; d <= 2 && i + d < static_cast<int>(nodes.size()); ++d)
      edges.push_back({i, i + d, RelativeSim3(nodes[i], nodes[i + d])});
  const Sim3d corrected_now = then_from_now * nodes[k];
  edges.push_back({candidate.keyframe, k, RelativeSim3(nodes[candidate.keyframe], corrected_now),
                   options_.loop_edge_weight});
  const PoseGraphSummary summary = OptimizePoseGraph(edges, {0}, options_.pose_graph, &nodes);
  if (!summary.success) return false;
  std::vector<Sim3d> new_from_old;
  for (size_t i = 0; i < nodes.size(); ++i) new_from_old.push_back(nodes[i] * before[i].Inverse());
  tracker->ApplyCorrection(new_from_old);
  // The matched points become one (the loop's constraint in the adjustment), then all is adjusted.
  tracker->MergeTracks(in_tracks);
  if (options_.global_bundle_adjustment) tracker->GlobalBundleAdjust();
  result.correction_translation =
      (tracker->KeyframePoses()[k].translation - poses[k].translation).norm();
  result.correction_scale = nodes[k].scale;
  result.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
  last_closure_ = k;
  *event = result;
  return true;
}

}  // namespace omni
