#include "sfm/loop_closure.h"

#include <spdlog/spdlog.h>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <ctime>
#include <limits>
#include <numeric>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <unordered_map>

#include "calib/error.h"
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
  ThrowIfInvalid(options.Check(), "LoopDetectionOptions");
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
  descriptor.cameras.resize(images.size());
  for (int camera : ring_) {  // only the ring is scored
    const cv::Mat& image = images[camera];
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
    descriptor.cameras[camera] = std::move(values);
  }
  return descriptor;
}

int LoopDetector::Add(PlaceDescriptor descriptor) {
  for (int camera : ring_)
    ring_rows_.insert(ring_rows_.end(), descriptor.cameras[camera].begin(),
                      descriptor.cameras[camera].end());
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
  const std::vector<LoopCandidate> best = QueryBest(query, before, 1);
  if (!best.empty()) return best.front();
  LoopCandidate none;
  // The best score even when under min_score, for the caller's information.
  const int end = std::min(size(), before - options_.min_keyframe_gap + 1);
  for (int k = 0; k < end; ++k)
    for (int shift = 0; shift < static_cast<int>(ring_.size()); ++shift)
      none.score = std::max(none.score, Score(query, descriptors_[k], shift));
  return none;
}

std::vector<LoopCandidate> LoopDetector::QueryBest(const PlaceDescriptor& query, int before,
                                                   int count) const {
  const int n = static_cast<int>(ring_.size());
  const int end = std::min(size(), before - options_.min_keyframe_gap + 1);
  std::vector<LoopCandidate> found;
  if (n == 0 || end <= 0 || count <= 0) return found;
  const int length = static_cast<int>(query.cameras[ring_[0]].size());
  // Every (stored ring thumbnail, query ring thumbnail) product in one matrix product; the
  // score of keyframe k and shift s sums the products of query camera i with stored i+s.
  using Matrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  const Eigen::Map<const Matrix> stored(ring_rows_.data(), static_cast<Eigen::Index>(end) * n,
                                        length);
  Matrix q(n, length);
  for (int i = 0; i < n; ++i)
    q.row(i) = Eigen::Map<const Eigen::RowVectorXf>(query.cameras[ring_[i]].data(), length);
  const Matrix products = stored * q.transpose();  // row k n + j, column i
  for (int k = 0; k < end; ++k) {
    LoopCandidate best{k, 0, -1.0};
    for (int shift = 0; shift < n; ++shift) {
      double sum = 0.0;
      for (int i = 0; i < n; ++i)
        sum += products(static_cast<Eigen::Index>(k) * n + (i + shift) % n, i);
      if (sum / n > best.score) best = {k, shift, sum / n};
    }
    if (best.score >= options_.min_score) found.push_back(best);
  }
  const size_t keep = std::min(found.size(), static_cast<size_t>(count));
  std::partial_sort(
      found.begin(), found.begin() + keep, found.end(),
      [](const LoopCandidate& a, const LoopCandidate& b) { return a.score > b.score; });
  found.resize(keep);
  return found;
}

int RingShiftOfRotation(const Rig& rig, const std::vector<int>& ring,
                        const Eigen::Quaterniond& then_from_now) {
  const int n = static_cast<int>(ring.size());
  if (n < 3) return -1;
  std::vector<Eigen::Vector3d> axes;
  for (int camera : ring)
    axes.push_back(rig.cameras[camera].cam_from_rig.rotation.conjugate() *
                   Eigen::Vector3d::UnitZ());
  std::vector<int> votes(n, 0);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d turned = then_from_now * axes[i];
    int best = 0;
    for (int j = 1; j < n; ++j)
      if (turned.dot(axes[j]) > turned.dot(axes[best])) best = j;
    ++votes[((best - i) % n + n) % n];
  }
  return static_cast<int>(std::max_element(votes.begin(), votes.end()) - votes.begin());
}

std::string LoopClosureOptions::Check() const {
  for (const auto& [name, check] :
       {std::pair<const char*, std::string>{"detection", detection.Check()},
        {"matching", matching.Check()},
        {"central_relative_pose", central_relative_pose.Check()},
        {"generalized_relative_pose", generalized_relative_pose.Check()},
        {"pose_graph", pose_graph.Check()}})
    if (!check.empty()) return std::string(name) + "." + check;
  if (!(global_bundle_adjustment_function_tolerance > 0.0 &&
        global_bundle_adjustment_function_tolerance < 1.0))
    return "global_bundle_adjustment_function_tolerance: expected a value in (0, 1)";
  if (!(prepared_downscale >= 1.0)) return "prepared_downscale: expected at least 1";
  if (ransac_iterations < 1) return "ransac_iterations: expected at least 1";
  if (!(inlier_depth_share > 0.0)) return "inlier_depth_share: expected a positive share";
  if (min_inliers < 3) return "min_inliers: expected at least 3";
  if (max_candidates < 1) return "max_candidates: expected at least 1";
  if (min_relative_inliers < 8) return "min_relative_inliers: expected at least 8";
  if (!(min_relative_inlier_ratio >= 0.0 && min_relative_inlier_ratio <= 1.0))
    return "min_relative_inlier_ratio: expected a share in [0, 1]";
  if (!(max_rotation_disagreement > 0.0 && max_rotation_disagreement < M_PI))
    return "max_rotation_disagreement: expected an angle in (0, pi) radians";
  if (!(max_drift_share > 0)) return "max_drift_share: expected more than 0";
  if (!(revisit_reach_keyframes >= 0.0))
    return "revisit_reach_keyframes: expected 0 or more keyframe steps";
  if (cooldown_keyframes < 0) return "cooldown_keyframes: expected 0 or more";
  if (!(loop_edge_weight > 0.0)) return "loop_edge_weight: expected a positive weight";
  return {};
}

CentralRelativePoseOptions LoopClosureOptions::DefaultCentralRelativePose() {
  CentralRelativePoseOptions options;
  // Matched corners are full-resolution detections (≈1 px ≈ 4 mrad at the Ladybug's 229 px
  // focal length), and the central approximation adds offset / depth (4 cm at 10 m: 4 mrad).
  options.ransac.max_angle_error = 0.008;
  // Enough to draw an all-inlier sample of five with 99.9 % certainty at the least inlier
  // ratio accepted (min_relative_inlier_ratio, 0.7): 1 − (1 − 0.7⁵)^200 > 0.999 (also at 0.55).
  options.ransac.max_iterations = 200;
  return options;
}

NoncentralRelativePoseOptions LoopClosureOptions::DefaultGeneralizedRelativePose() {
  NoncentralRelativePoseOptions options;
  options.ransac.max_angle_error = 0.006;
  options.ransac.max_iterations = 2000;
  return options;
}

std::string LoopClosureEvent::Summary() const {
  std::ostringstream o;
  o << "loop closed at keyframe " << keyframe << " (frame " << frame << ") with keyframe "
    << candidate_keyframe << " (frame " << candidate_frame << "), ring shift " << shift
    << ", appearance " << score << "; relative pose: " << relative_inliers << " of "
    << relative_matches << " matched bearings agree; similarity: " << inliers << " of " << matches
    << " matched points agree, rotations " << rotation_disagreement * 180.0 / M_PI
    << " deg apart; the revisit moved by " << correction_translation << " (scale x"
    << correction_scale << ") in " << ms << " ms";
  return o.str();
}

std::string LoopClosureTimings::Summary() const {
  std::ostringstream o;
  o << keyframes << " keyframes, " << queries << " queries, " << candidates
    << " candidates verified, " << closures << " closures; seconds: prepare " << prepare
    << ", query " << query << ", match " << match << ", verify " << verify << ", correct "
    << correct << ", global adjustment " << global_bundle_adjustment;
  return o.str();
}

LoopCloser::LoopCloser(const Rig& rig, const LoopClosureOptions& options)
    : rig_(rig),
      options_(CheckedOptions(options, "LoopClosureOptions")),
      detector_(rig, options.detection) {}

LoopCloser::~LoopCloser() {
  if (timings_.keyframes > 0) spdlog::debug("loop closure: {}", timings_.Summary());
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

bool LoopWithinReach(const std::vector<Rigid3d>& world_from_rig, int then, int now,
                     const LoopClosureOptions& options) {
  if (now <= then) return false;
  double path = 0.0;
  for (int i = then; i < now; ++i)
    path += (world_from_rig[i + 1].translation - world_from_rig[i].translation).norm();
  const double step = path / (now - then);
  const double distance =
      (world_from_rig[now].translation - world_from_rig[then].translation).norm();
  return distance <= options.max_drift_share * path + options.revisit_reach_keyframes * step;
}

Sim3d EstimateSimilarityRansac(const std::vector<Eigen::Vector3d>& src,
                               const std::vector<Eigen::Vector3d>& dst, double threshold,
                               int iterations, unsigned seed, std::vector<int>* inliers_out) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<size_t> pick(0, src.size() - 1);
  auto inliers_of = [&](const Sim3d& s) {
    std::vector<int> inliers;
    for (size_t i = 0; i < src.size(); ++i)
      if ((s * src[i] - dst[i]).norm() < threshold) inliers.push_back(static_cast<int>(i));
    return inliers;
  };
  std::vector<int> best_inliers;
  for (int iteration = 0; iteration < iterations; ++iteration) {
    const size_t i0 = pick(rng), i1 = pick(rng), i2 = pick(rng);
    if (i0 == i1 || i1 == i2 || i0 == i2) continue;
    const Eigen::Vector3d e1 = src[i1] - src[i0], e2 = src[i2] - src[i0];
    if (e1.cross(e2).norm() < 1e-6 * e1.squaredNorm()) continue;
    const Sim3d s = EstimateSim3Umeyama({src[i0], src[i1], src[i2]}, {dst[i0], dst[i1], dst[i2]});
    std::vector<int> inliers = inliers_of(s);
    if (inliers.size() > best_inliers.size()) best_inliers = std::move(inliers);
  }
  inliers_out->clear();
  if (best_inliers.size() < 3) return Sim3d();
  std::vector<Eigen::Vector3d> in_src, in_dst;
  for (int i : best_inliers) {
    in_src.push_back(src[i]);
    in_dst.push_back(dst[i]);
  }
  const Sim3d refit = EstimateSim3Umeyama(in_src, in_dst);
  *inliers_out = inliers_of(refit);
  return refit;
}

LoopVerification VerifyLoop(const Rig& rig, const std::vector<int>& ring, int shift,
                            const LoopMatches& matches,
                            const std::vector<Rigid3d>& world_from_keyframe, int then, int now,
                            const LoopClosureOptions& options, unsigned seed) {
  ThrowIfInvalid(options.Check(), "LoopClosureOptions");
  assert(matches.bearings_now.size() == matches.bearings_then.size());
  assert(matches.points_now.size() == matches.points_then.size());
  LoopVerification v;
  v.matches = static_cast<int>(matches.bearings_now.size());
  v.points = static_cast<int>(matches.points_now.size());
  auto refuse = [&](std::string why) {
    v.accepted = false;
    v.refusal = std::move(why);
    return v;
  };

  // 1. Similarity of the map points in RANSAC, and the drift bound: cheap, first.
  if (v.points < options.min_inliers) return refuse("too few 3-D matches");
  std::vector<double> depths;
  for (const Eigen::Vector3d& q : matches.points_then)
    depths.push_back((q - world_from_keyframe[then].translation).norm());
  std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
  const double threshold = options.inlier_depth_share * depths[depths.size() / 2];
  std::vector<int> inliers;
  v.similarity = EstimateSimilarityRansac(matches.points_now, matches.points_then, threshold,
                                          options.ransac_iterations, seed, &inliers);
  v.similarity_inliers = static_cast<int>(inliers.size());
  if (v.similarity_inliers < options.min_inliers) return refuse("similarity: too few inliers");
  v.drift_share = LoopDriftShare(world_from_keyframe, then, now, v.similarity);
  if (!(v.drift_share <= options.max_drift_share))
    return refuse("the correction would move the revisit too far for drift");

  // 2. Relative pose of the rig from the bearings (view 1: then, view 2: now).
  if (v.matches < options.min_relative_inliers) return refuse("relative pose: too few matches");
  const bool central =
      options.relative_pose_model == LoopClosureOptions::RelativePoseModel::kCentral ||
      (options.relative_pose_model == LoopClosureOptions::RelativePoseModel::kFollowRig &&
       rig.central);
  RansacResult relative;
  if (central) {
    std::vector<Eigen::Vector3d> in_rig_then, in_rig_now;
    for (int i = 0; i < v.matches; ++i) {
      in_rig_then.push_back(rig.cameras[matches.cameras_then[i]].cam_from_rig.rotation.conjugate() *
                            matches.bearings_then[i]);
      in_rig_now.push_back(rig.cameras[matches.cameras_now[i]].cam_from_rig.rotation.conjugate() *
                           matches.bearings_now[i]);
    }
    CentralRelativePoseOptions relative_options = options.central_relative_pose;
    relative_options.ransac.seed = seed;
    relative =
        EstimateCentralRelativePose(in_rig_then, in_rig_now, relative_options, &v.then_from_now);
  } else {
    NoncentralRelativePoseOptions relative_options = options.generalized_relative_pose;
    relative_options.ransac.seed = seed;
    relative = EstimateNoncentralRelativePose(rig, matches.bearings_then, matches.cameras_then,
                                              matches.bearings_now, matches.cameras_now,
                                              relative_options, &v.then_from_now);
  }
  v.relative_inliers = relative.success ? relative.num_inliers : 0;
  if (v.relative_inliers < options.min_relative_inliers)
    return refuse("relative pose: too few inliers");
  if (v.relative_inliers < options.min_relative_inlier_ratio * v.matches)
    return refuse("relative pose: too low an inlier ratio");
  v.ring_shift = RingShiftOfRotation(rig, ring, v.then_from_now.rotation);
  if (options.check_ring_shift && v.ring_shift >= 0 && v.ring_shift != shift)
    return refuse("relative pose: its rotation is not the appearance's ring shift");

  // 3. The two are independent evidence of one motion: the similarity's corrected revisit seen
  // from the place, against the relative pose.
  const Rigid3d predicted =
      world_from_keyframe[then].Inverse() * TransformPose(v.similarity, world_from_keyframe[now]);
  v.rotation_disagreement = predicted.rotation.angularDistance(v.then_from_now.rotation);
  if (!(v.rotation_disagreement <= options.max_rotation_disagreement))
    return refuse("the relative pose and the similarity disagree on the rotation");
  const bool both = matches.match_of_point.size() == matches.points_now.size();
  for (int i : inliers)
    if (!both || relative.inlier_mask[matches.match_of_point[i]])
      v.inlier_tracks.push_back(matches.tracks[i]);
  v.accepted = true;
  return v;
}

namespace {

using WindowMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// One zero-mean, unit-norm window (bilinear, around the subpixel corner) per row; zero rows for
// the corners whose window leaves the image or is flat (they match nothing).
WindowMatrix NormalisedWindows(const cv::Mat& image, const std::vector<Eigen::Vector2d>& corners,
                               int half_window) {
  const int side = 2 * half_window + 1;
  WindowMatrix windows = WindowMatrix::Zero(static_cast<Eigen::Index>(corners.size()), side * side);
  cv::Mat patch;
  for (size_t i = 0; i < corners.size(); ++i) {
    const Eigen::Vector2d& c = corners[i];
    if (c.x() < half_window || c.y() < half_window || c.x() > image.cols - 1 - half_window ||
        c.y() > image.rows - 1 - half_window)
      continue;
    cv::getRectSubPix(image, cv::Size(side, side), cv::Point2f(c.x(), c.y()), patch, CV_32F);
    const Eigen::Map<const Eigen::RowVectorXf> values(patch.ptr<float>(), side * side);
    const Eigen::RowVectorXf centred = values.array() - values.mean();
    const float norm = centred.norm();
    if (norm > 1e-3f * side) windows.row(static_cast<Eigen::Index>(i)) = centred / norm;
  }
  return windows;
}

// All-against-all ZNCC of two corner sets as one matrix product of their windows, with the
// checks of ZnccOptions (minimum score, distinctiveness ratio, mutual best); (index1, index2).
std::vector<std::pair<int, int>> MatchWindows(const WindowMatrix& windows1,
                                              const WindowMatrix& windows2,
                                              const ZnccOptions& options) {
  std::vector<std::pair<int, int>> matches;
  if (windows1.rows() == 0 || windows2.rows() == 0) return matches;
  const WindowMatrix scores = windows1 * windows2.transpose();
  Eigen::VectorXi best_of_column(scores.cols());
  for (Eigen::Index j = 0; j < scores.cols(); ++j) scores.col(j).maxCoeff(&best_of_column[j]);
  for (Eigen::Index i = 0; i < scores.rows(); ++i) {
    BestTwoZncc two;
    for (Eigen::Index j = 0; j < scores.cols(); ++j) two.Offer(scores(i, j), static_cast<int>(j));
    const Eigen::Index best_j = two.index;
    if (best_j < 0 || two.best < options.min_zncc) continue;
    if (!IsDistinctZncc(two.best, two.second, options.max_distance_ratio)) continue;
    if (options.mutual && best_of_column[best_j] != i) continue;
    matches.emplace_back(static_cast<int>(i), static_cast<int>(best_j));
  }
  return matches;
}

}  // namespace

std::vector<std::pair<int, int>> MatchCornersAllPairs(const cv::Mat& image1,
                                                      const std::vector<Eigen::Vector2d>& corners1,
                                                      const cv::Mat& image2,
                                                      const std::vector<Eigen::Vector2d>& corners2,
                                                      const ZnccOptions& options) {
  return MatchWindows(NormalisedWindows(image1, corners1, options.half_window),
                      NormalisedWindows(image2, corners2, options.half_window), options);
}

LoopMatches LoopCloser::Match(const KeyframeData& now, const KeyframeData& then, int shift,
                              const Tracker& tracker, int now_keyframe, int then_keyframe) const {
  LoopMatches matches;
  const std::vector<int>& ring = detector_.ring();
  const int n = static_cast<int>(ring.size());
  std::vector<std::pair<int, int>> track_pairs;  // (now, then) of each 2-D match
  for (int i = 0; i < n; ++i) {
    const int a = ring[i], b = ring[(i + shift) % n];
    if (now.prepared[a].empty() || then.prepared[b].empty()) continue;
    for (const auto& [i_now, i_then] :
         MatchCornersAllPairs(now.prepared[a], now.corners[a], then.prepared[b], then.corners[b],
                              options_.matching)) {
      matches.bearings_now.push_back(now.bearings[a][i_now]);
      matches.bearings_then.push_back(then.bearings[b][i_then]);
      matches.cameras_now.push_back(a);
      matches.cameras_then.push_back(b);
      track_pairs.emplace_back(now.tracks[a][i_now], then.tracks[b][i_then]);
    }
  }
  if (static_cast<int>(track_pairs.size()) < options_.min_inliers) return matches;
  std::unordered_map<int, Eigen::Vector3d> now_points, then_points;
  for (const auto& [track, position] : tracker.KeyframeTrackPoints(now_keyframe))
    now_points.emplace(track, position);
  for (const auto& [track, position] : tracker.KeyframeTrackPoints(then_keyframe))
    then_points.emplace(track, position);
  for (const std::pair<int, int>& pair : track_pairs) {
    const auto& [track_now, track_then] = pair;
    const auto p = now_points.find(track_now);
    const auto q = then_points.find(track_then);
    if (p == now_points.end() || q == then_points.end()) continue;
    matches.points_now.push_back(p->second);
    matches.points_then.push_back(q->second);
    matches.tracks.emplace_back(track_now, track_then);
    matches.match_of_point.push_back(static_cast<int>(&pair - track_pairs.data()));
  }
  return matches;
}

bool LoopCloser::AddKeyframe(const std::vector<cv::Mat>& images, const TrackedFrame& frame,
                             Tracker* tracker, LoopClosureEvent* event) {
  // Stage timings in CPU seconds of this thread (what the stage costs, whatever the load);
  // the event's ms in wall time.
  auto cpu_now = [] {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
  };
  auto seconds_since = [&](double t) { return cpu_now() - t; };
  const auto wall_start = std::chrono::steady_clock::now();
  const double start = cpu_now();
  const int k = tracker->NumKeyframes() - 1;
  if (k != static_cast<int>(keyframes_.size())) return false;  // a keyframe was missed
  ++timings_.keyframes;
  KeyframeData data;
  data.frame = tracker->KeyframeFrames().back();
  HarrisOptions prepare;
  prepare.downscale = options_.prepared_downscale;
  data.prepared.resize(images.size());
  data.corners.resize(images.size());
  data.bearings.resize(images.size());
  data.tracks.resize(images.size());
  for (int camera : detector_.ring())  // only the ring is matched
    data.prepared[camera] = PrepareImage(images[camera], prepare);
  for (size_t i = 0; i < frame.observations.size(); ++i) {
    const TrackObservation& o = frame.observations[i];
    Eigen::Vector3d bearing;
    if (!rig_.cameras[o.camera].Unproject(frame.pixels[i], &bearing)) continue;
    data.corners[o.camera].push_back(InputToPreparedPixel(frame.pixels[i], prepare.downscale));
    data.bearings[o.camera].push_back(bearing.normalized());
    data.tracks[o.camera].push_back(o.track);
  }
  const PlaceDescriptor descriptor = detector_.Describe(images);
  detector_.Add(descriptor);
  keyframes_.push_back(std::move(data));
  timings_.prepare += seconds_since(start);
  if (k - last_closure_ < options_.cooldown_keyframes) return false;
  double lap = cpu_now();
  // Every candidate scoring min_score, best first; only those within reach of the drift bound
  // are matched, at most max_candidates of them.
  const std::vector<Rigid3d> poses = tracker->KeyframePoses();
  std::vector<LoopCandidate> candidates;
  for (const LoopCandidate& candidate : detector_.QueryBest(descriptor, k, k + 1)) {
    if (static_cast<int>(candidates.size()) == options_.max_candidates) break;
    if (LoopWithinReach(poses, candidate.keyframe, k, options_)) candidates.push_back(candidate);
  }
  ++timings_.queries;
  timings_.query += seconds_since(lap);
  if (candidates.empty()) return false;

  const KeyframeData& now = keyframes_[k];
  LoopClosureEvent result;
  LoopVerification verified;
  for (const LoopCandidate& candidate : candidates) {
    ++timings_.candidates;
    lap = cpu_now();
    const KeyframeData& then = keyframes_[candidate.keyframe];
    const LoopMatches matches = Match(now, then, candidate.shift, *tracker, k, candidate.keyframe);
    timings_.match += seconds_since(lap);
    lap = cpu_now();
    const LoopVerification v =
        VerifyLoop(rig_, detector_.ring(), candidate.shift, matches, poses, candidate.keyframe, k,
                   options_, options_.seed + static_cast<unsigned>(k));
    timings_.verify += seconds_since(lap);
    spdlog::debug(
        "loop closure: keyframe {} with keyframe {} (shift {}, appearance {:.3f}): relative "
        "pose {} of {} (shift {}), similarity {} of {}, rotations {:.2f} deg apart, drift "
        "{:.1f} %: {}",
        k, candidate.keyframe, candidate.shift, candidate.score, v.relative_inliers, v.matches,
        v.ring_shift, v.similarity_inliers, v.points, v.rotation_disagreement * 180.0 / M_PI,
        100.0 * v.drift_share, v.accepted ? "accepted" : v.refusal);
    if (!v.accepted) {
      if (v.similarity_inliers >= options_.min_inliers)  // refused late: worth telling
        spdlog::info("loop closure: keyframe {} with keyframe {} refused: {}", k,
                     candidate.keyframe, v.refusal);
      continue;
    }
    verified = v;
    result.candidate_keyframe = candidate.keyframe;
    result.candidate_frame = then.frame;
    result.shift = candidate.shift;
    result.score = candidate.score;
    break;
  }
  if (!verified.accepted) return false;
  result.keyframe = k;
  result.frame = now.frame;
  result.matches = verified.points;
  result.inliers = verified.similarity_inliers;
  result.relative_matches = verified.matches;
  result.relative_inliers = verified.relative_inliers;
  result.rotation_disagreement = verified.rotation_disagreement;
  const Sim3d& then_from_now = verified.similarity;

  // Pose graph over every keyframe: odometry edges (neighbours one and two apart) as the map
  // is now, and the loop edge where the revisit should be.
  lap = cpu_now();
  std::vector<Sim3d> nodes;
  for (const Rigid3d& pose : poses) nodes.emplace_back(1.0, pose.rotation, pose.translation);
  const std::vector<Sim3d> before = nodes;
  std::vector<PoseGraphEdge> edges;
  for (int i = 0; i < static_cast<int>(nodes.size()); ++i)
    for (int d = 1; d <= 2 && i + d < static_cast<int>(nodes.size()); ++d)
      edges.push_back({i, i + d, RelativeSim3(nodes[i], nodes[i + d])});
  const Sim3d corrected_now = then_from_now * nodes[k];
  edges.push_back({result.candidate_keyframe, k,
                   RelativeSim3(nodes[result.candidate_keyframe], corrected_now),
                   options_.loop_edge_weight});
  const PoseGraphSummary summary = OptimizePoseGraph(edges, {0}, options_.pose_graph, &nodes);
  if (!summary.success) {
    timings_.correct += seconds_since(lap);
    return false;
  }
  std::vector<Sim3d> new_from_old;
  for (size_t i = 0; i < nodes.size(); ++i) new_from_old.push_back(nodes[i] * before[i].Inverse());
  tracker->ApplyCorrection(new_from_old);
  // The matched points become one (the loop's constraint in the adjustment), then all is adjusted.
  tracker->MergeTracks(verified.inlier_tracks);
  timings_.correct += seconds_since(lap);
  lap = cpu_now();
  if (options_.global_bundle_adjustment) {
    tracker->GlobalBundleAdjust(false, 0.0, nullptr, 0,
                                options_.global_bundle_adjustment_function_tolerance);
  }
  timings_.global_bundle_adjustment += seconds_since(lap);
  result.correction_translation =
      (tracker->KeyframePoses()[k].translation - poses[k].translation).norm();
  result.correction_scale = nodes[k].scale;
  result.ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - wall_start)
          .count();
  ++timings_.closures;
  last_closure_ = k;
  *event = result;
  spdlog::info("loop closure: {}", timings_.Summary());
  return true;
}

}  // namespace omni
