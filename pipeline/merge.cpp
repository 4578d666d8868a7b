#include "pipeline/merge.h"

#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <deque>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <numeric>
#include <optional>
#include <unordered_map>

#include "calib/drive.h"
#include "calib/error.h"
#include "calib/input_file.h"
#include "pipeline/frame_prefetcher.h"
#include "sfm/harris.h"
#include "sfm/loop_closure.h"

namespace omni {
namespace fs = std::filesystem;

namespace {

constexpr double kDegree = M_PI / 180.0;

// The poses of a TUM file by frame: each timestamp is the drive's nearest frame time, within a
// quarter of the frames' spacing there (the file has 9 decimals; a clock of epoch seconds keeps
// fewer significant digits in a double, so the times are not compared exactly).
std::map<size_t, StampedPose> PosesByFrame(const std::vector<StampedPose>& poses,
                                           const std::vector<double>& frame_times,
                                           const fs::path& file) {
  std::map<size_t, StampedPose> by_frame;
  for (const StampedPose& pose : poses) {
    const auto after = std::lower_bound(frame_times.begin(), frame_times.end(), pose.timestamp);
    size_t best = frame_times.size();
    double tolerance = 0.0;
    for (auto it : {after, after == frame_times.begin() ? after : std::prev(after)}) {
      if (it == frame_times.end()) continue;
      const size_t i = static_cast<size_t>(it - frame_times.begin());
      if (best == frame_times.size() ||
          std::abs(*it - pose.timestamp) < std::abs(frame_times[best] - pose.timestamp))
        best = i;
    }
    if (best < frame_times.size()) {
      double spacing = 1.0;
      if (best + 1 < frame_times.size()) spacing = frame_times[best + 1] - frame_times[best];
      if (best > 0) spacing = std::min(spacing, frame_times[best] - frame_times[best - 1]);
      tolerance = 0.25 * spacing;
    }
    if (best == frame_times.size() || !(std::abs(frame_times[best] - pose.timestamp) <= tolerance))
      throw InputError(
          file, "",
          "timestamp " + std::to_string(pose.timestamp) + " is the time of no frame of the drive");
    by_frame[best] = pose;
  }
  return by_frame;
}

// The frame index of a sparse/ image name ("images/cam0/000123.png" -> frame "000123").
std::optional<size_t> FrameOfImage(const MergeSegment& segment, const std::string& name) {
  const auto it = segment.frame_of_name.find(fs::path(name).stem().string());
  if (it == segment.frame_of_name.end()) return std::nullopt;
  return it->second;
}

// How far a frame is from the ends of its segment's range: the larger, the better constrained
// its pose (a segment's first and last frames have the fewest observations).
long Centrality(const MergeSegment& segment, size_t frame) {
  return std::min(static_cast<long>(frame) - static_cast<long>(segment.first_frame),
                  static_cast<long>(segment.last_frame) - static_cast<long>(frame));
}

double RotationAngle(const Eigen::Quaterniond& q) {
  return 2.0 * std::atan2(q.vec().norm(), std::abs(q.w()));
}

// The similarity a_from_b from the poses of the frames both segments tracked (see
// MergeOverlap): the rotation is the mean of the frames' rotations a_from_b (chordal, on the
// inliers), then the scale and translation are the least-squares fit of the centres.
MergeOverlap AlignSharedFrames(const MergeSegment& a, const MergeSegment& b, int index_a,
                               int index_b, const MergeOptions& options) {
  MergeOverlap overlap;
  overlap.a = index_a;
  overlap.b = index_b;
  overlap.kind = "shared frames";
  std::vector<Rigid3d> pose_a, pose_b;
  for (const auto& [frame, stamped] : b.frame_poses) {
    const auto it = a.frame_poses.find(frame);
    if (it == a.frame_poses.end()) continue;
    pose_a.push_back(it->second.world_from_rig);
    pose_b.push_back(stamped.world_from_rig);
  }
  const size_t n = pose_a.size();
  overlap.shared_frames = static_cast<int>(n);
  if (n == 0) {
    overlap.refusal = "no frame tracked in both";
    return overlap;
  }
  std::vector<Eigen::Quaterniond> rotations(n);
  for (size_t i = 0; i < n; ++i)
    rotations[i] = (pose_a[i].rotation * pose_b[i].rotation.conjugate()).normalized();
  std::vector<Eigen::Vector3d> centre_a(n), centre_b(n);
  for (size_t i = 0; i < n; ++i) {
    centre_a[i] = pose_a[i].translation;  // world_from_rig: the translation is the centre
    centre_b[i] = pose_b[i].translation;
  }
  double path = 0.0;
  for (size_t i = 1; i < n; ++i) path += (centre_a[i] - centre_a[i - 1]).norm();
  const double max_centre_residual =
      options.max_centre_residual_share * path + options.min_centre_residual;

  std::vector<bool> inlier(n, true);
  Sim3d a_from_b;
  for (int round = 0; round < 3; ++round) {
    // Rotation: the normalised sum of the inliers' quaternions, signs aligned.
    Eigen::Vector4d sum = Eigen::Vector4d::Zero();
    const Eigen::Quaterniond reference = round == 0 ? rotations[n / 2] : a_from_b.rotation;
    for (size_t i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      const double sign = rotations[i].dot(reference) < 0.0 ? -1.0 : 1.0;
      sum += sign * rotations[i].coeffs();
    }
    if (sum.norm() == 0.0) break;
    a_from_b.rotation = Eigen::Quaterniond(sum.normalized());
    // Scale and translation given the rotation.
    Eigen::Vector3d mean_a = Eigen::Vector3d::Zero(), mean_b = Eigen::Vector3d::Zero();
    int count = 0;
    for (size_t i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      mean_a += centre_a[i];
      mean_b += centre_b[i];
      ++count;
    }
    mean_a /= count;
    mean_b /= count;
    double numerator = 0.0, denominator = 0.0;
    for (size_t i = 0; i < n; ++i) {
      if (!inlier[i]) continue;
      const Eigen::Vector3d rotated = a_from_b.rotation * (centre_b[i] - mean_b);
      numerator += (centre_a[i] - mean_a).dot(rotated);
      denominator += rotated.squaredNorm();
    }
    a_from_b.scale = denominator > 0.0 ? numerator / denominator : 0.0;
    a_from_b.translation = mean_a - a_from_b.scale * (a_from_b.rotation * mean_b);
    // Inliers of this estimate.
    for (size_t i = 0; i < n; ++i) {
      const double angle = RotationAngle(a_from_b.rotation.conjugate() * rotations[i]);
      const double residual = (centre_a[i] - a_from_b * centre_b[i]).norm();
      inlier[i] =
          angle <= options.max_rotation_residual_deg * kDegree && residual <= max_centre_residual;
    }
  }
  double rotation_sq = 0.0, centre_sq = 0.0;
  for (size_t i = 0; i < n; ++i) {
    if (!inlier[i]) continue;
    ++overlap.inliers;
    rotation_sq += std::pow(RotationAngle(a_from_b.rotation.conjugate() * rotations[i]), 2);
    centre_sq += (centre_a[i] - a_from_b * centre_b[i]).squaredNorm();
  }
  if (overlap.inliers > 0) {
    overlap.rms_rotation_deg = std::sqrt(rotation_sq / overlap.inliers) / kDegree;
    overlap.rms_centre = std::sqrt(centre_sq / overlap.inliers);
  }
  overlap.a_from_b = a_from_b;
  if (!(path > 0.0)) {
    overlap.refusal = "the shared frames do not move: the scale between the two is unknown";
  } else if (!(a_from_b.scale > 0.0) || !std::isfinite(a_from_b.scale)) {
    overlap.refusal = "no similarity fits the shared frames";
  } else if (overlap.inliers < options.min_shared_frames) {
    overlap.refusal = std::to_string(overlap.inliers) + " of " + std::to_string(n) +
                      " shared frames agree with one similarity (at least " +
                      std::to_string(options.min_shared_frames) + " needed)";
  } else {
    overlap.verified = true;
  }
  return overlap;
}

// cam_from_world of an image of a segment, in the city frame (city = S * segment).
Rigid3d CamFromCity(const Rigid3d& cam_from_segment, const Sim3d& city_from_segment) {
  const Eigen::Vector3d centre = city_from_segment * cam_from_segment.Center();
  const Eigen::Quaterniond rotation =
      (cam_from_segment.rotation * city_from_segment.rotation.conjugate()).normalized();
  return Rigid3d(rotation, -(rotation * centre));
}

struct UnionFind {
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  size_t Find(size_t i) {
    while (parent[i] != i) i = parent[i] = parent[parent[i]];
    return i;
  }
  void Join(size_t i, size_t j) { parent[Find(i)] = Find(j); }
  std::vector<size_t> parent;
};

// The keyframes of a segment: their frames in order and, per keyframe, its image of each rig
// camera (COLMAP camera id k is rig camera k-1; null when missing).
struct SegmentKeyframes {
  std::vector<size_t> frames;
  std::vector<std::vector<const ColmapImage*>> images;
};

SegmentKeyframes KeyframesOf(const MergeSegment& segment) {
  std::map<size_t, std::vector<const ColmapImage*>> by_frame;
  for (const ColmapImage& image : segment.model.images) {
    const std::optional<size_t> frame = FrameOfImage(segment, image.name);
    const int camera = static_cast<int>(image.camera_id) - 1;
    if (!frame || camera < 0 || camera >= static_cast<int>(segment.rig.NumCameras())) continue;
    auto& cameras = by_frame[*frame];
    cameras.resize(segment.rig.NumCameras(), nullptr);
    cameras[camera] = &image;
  }
  SegmentKeyframes keyframes;
  for (auto& [frame, cameras] : by_frame) {
    keyframes.frames.push_back(frame);
    keyframes.images.push_back(std::move(cameras));
  }
  return keyframes;
}

// The corners of an image that have a 3-D point, in pixels of the prepared image, and the points.
void CornersWithPoints(const ColmapImage& image, double downscale,
                       std::vector<Eigen::Vector2d>* corners, std::vector<uint32_t>* points) {
  corners->clear();
  points->clear();
  for (const ColmapPoint2D& point : image.points2d) {
    if (point.point3d_id < 0) continue;
    corners->push_back(InputToPreparedPixel(point.xy - Eigen::Vector2d(0.5, 0.5), downscale));
    points->push_back(static_cast<uint32_t>(point.point3d_id));
  }
}

// Revisits between every two segments (MergeRevisitOptions). `aligned`: the segments the shared
// frames already put in one frame (city_from_segment), for the drift bound; `drive_length`:
// the merged drive's length in city units.
std::vector<MergeOverlap> FindRevisits(const std::vector<MergeSegment>& segments,
                                       const std::vector<bool>& aligned,
                                       const std::vector<Sim3d>& city_from_segment,
                                       double drive_length, const MergeRevisitOptions& options) {
  const int count = static_cast<int>(segments.size());
  std::map<std::string, std::unique_ptr<Drive>> drives;
  for (const MergeSegment& segment : segments)
    if (!drives.count(segment.drive))
      drives[segment.drive] = std::make_unique<Drive>(Drive::Open(segment.drive));
  std::vector<SegmentKeyframes> keyframes;
  std::vector<std::unique_ptr<LoopDetector>> detectors;
  std::vector<std::vector<PlaceDescriptor>> descriptors(count);
  for (int s = 0; s < count; ++s) {
    keyframes.push_back(KeyframesOf(segments[s]));
    detectors.push_back(std::make_unique<LoopDetector>(segments[s].rig, options.loop.detection));
    const Drive& drive = *drives.at(segments[s].drive);
    for (size_t frame : keyframes[s].frames) {
      descriptors[s].push_back(detectors[s]->Describe(LoadGrayFrame(drive, frame)));
      detectors[s]->Add(descriptors[s].back());
    }
  }
  HarrisOptions prepare;
  prepare.downscale = options.loop.prepared_downscale;
  const auto prepared = [&](int s, size_t frame, int camera) {
    return PrepareImage(drives.at(segments[s].drive)->LoadGray(frame, camera), prepare);
  };
  std::vector<MergeOverlap> revisits;
  unsigned seed = options.seed;
  for (int a = 0; a < count; ++a) {
    for (int b = a + 1; b < count; ++b) {
      const MergeSegment& sa = segments[a];
      const MergeSegment& sb = segments[b];
      const std::vector<int>& ring = detectors[a]->ring();
      if (ring.size() != detectors[b]->ring().size() || ring.empty()) continue;
      const bool same_drive = sa.drive == sb.drive;
      std::unordered_map<uint32_t, Eigen::Vector3d> xyz_a, xyz_b;
      for (const ColmapPoint3D& p : sa.model.points) xyz_a.emplace(p.id, p.xyz);
      for (const ColmapPoint3D& p : sb.model.points) xyz_b.emplace(p.id, p.xyz);
      std::vector<MergeOverlap> found;
      int verified_candidates = 0, best_inliers = 0, best_matches = 0;
      for (size_t kb = 0; kb < keyframes[b].frames.size(); ++kb) {
        const size_t frame_b = keyframes[b].frames[kb];
        if (same_drive && frame_b >= sa.first_frame && frame_b <= sa.last_frame) continue;
        const std::vector<LoopCandidate> candidates = detectors[a]->QueryBest(
            descriptors[b][kb], detectors[a]->size() + options.loop.detection.min_keyframe_gap,
            options.candidates_per_keyframe);
        for (const LoopCandidate& candidate : candidates) {
          const size_t ka = static_cast<size_t>(candidate.keyframe);
          const size_t frame_a = keyframes[a].frames[ka];
          if (same_drive && ((frame_a >= sb.first_frame && frame_a <= sb.last_frame) ||
                             std::abs(static_cast<long>(frame_a) - static_cast<long>(frame_b)) <
                                 options.min_frame_gap))
            continue;
          // 3-D matches: b's ring camera i against a's ring camera i + shift.
          std::vector<Eigen::Vector3d> points_b, points_a;
          std::vector<std::pair<uint32_t, uint32_t>> pairs;  // (a, b)
          const int n = static_cast<int>(ring.size());
          for (int i = 0; i < n; ++i) {
            const int camera_b = ring[i], camera_a = ring[(i + candidate.shift) % n];
            const ColmapImage* image_b = keyframes[b].images[kb][camera_b];
            const ColmapImage* image_a = keyframes[a].images[ka][camera_a];
            if (!image_b || !image_a) continue;
            std::vector<Eigen::Vector2d> corners_b, corners_a;
            std::vector<uint32_t> ids_b, ids_a;
            CornersWithPoints(*image_b, prepare.downscale, &corners_b, &ids_b);
            CornersWithPoints(*image_a, prepare.downscale, &corners_a, &ids_a);
            for (const auto& [i_b, i_a] : MatchCornersAllPairs(
                     prepared(b, frame_b, camera_b), corners_b, prepared(a, frame_a, camera_a),
                     corners_a, options.loop.matching)) {
              const auto pb = xyz_b.find(ids_b[i_b]);
              const auto pa = xyz_a.find(ids_a[i_a]);
              if (pb == xyz_b.end() || pa == xyz_a.end()) continue;
              points_b.push_back(pb->second);
              points_a.push_back(pa->second);
              pairs.emplace_back(ids_a[i_a], ids_b[i_b]);
            }
          }
          MergeOverlap revisit;
          revisit.a = a;
          revisit.b = b;
          revisit.kind = "revisit";
          revisit.frame_a = frame_a;
          revisit.frame_b = frame_b;
          revisit.score = candidate.score;
          revisit.matches = static_cast<int>(points_a.size());
          ++verified_candidates;
          if (revisit.matches < options.loop.min_inliers) continue;
          const auto pose_a = sa.keyframe_poses.find(frame_a);
          const auto pose_b = sb.keyframe_poses.find(frame_b);
          if (pose_a == sa.keyframe_poses.end() || pose_b == sb.keyframe_poses.end()) continue;
          std::vector<double> depths;
          for (const Eigen::Vector3d& p : points_a)
            depths.push_back((p - pose_a->second.world_from_rig.translation).norm());
          std::nth_element(depths.begin(), depths.begin() + depths.size() / 2, depths.end());
          const double threshold = options.loop.inlier_depth_share * depths[depths.size() / 2];
          std::vector<int> inliers;
          revisit.a_from_b = EstimateSimilarityRansac(
              points_b, points_a, threshold, options.loop.ransac_iterations, seed++, &inliers);
          revisit.inliers = static_cast<int>(inliers.size());
          if (revisit.inliers > best_inliers) {
            best_inliers = revisit.inliers;
            best_matches = revisit.matches;
          }
          if (revisit.inliers < options.loop.min_inliers ||
              revisit.inliers < options.min_inlier_ratio * revisit.matches)
            continue;
          if (aligned[a] && aligned[b]) {
            const Sim3d graph = city_from_segment[a].Inverse() * city_from_segment[b];
            const Eigen::Vector3d centre = pose_b->second.world_from_rig.translation;
            const double moved =
                (revisit.a_from_b * centre - graph * centre).norm() * city_from_segment[a].scale;
            const double turned =
                RotationAngle(revisit.a_from_b.rotation * graph.rotation.conjugate());
            if (moved > options.max_drift_share * drive_length ||
                turned > options.max_rotation_deg * kDegree) {
              spdlog::info(
                  "merge: {} frame {} and {} frame {} look alike but would move by {:.2f} "
                  "(turn {:.1f} deg): not a revisit",
                  sb.folder.string(), frame_b, sa.folder.string(), frame_a, moved,
                  turned / kDegree);
              continue;
            }
          }
          double sq = 0.0;
          for (int i : inliers) {
            sq += (revisit.a_from_b * points_b[i] - points_a[i]).squaredNorm();
            revisit.point_pairs.push_back(pairs[i]);
          }
          revisit.rms_centre = std::sqrt(sq / inliers.size());
          revisit.verified = true;
          found.push_back(std::move(revisit));
          break;  // one candidate per keyframe
        }
      }
      if (found.empty()) {
        // Reported when nothing else joins the two (MergeSegments drops it otherwise).
        MergeOverlap none;
        none.a = a;
        none.b = b;
        none.kind = "revisit";
        none.inliers = best_inliers;
        none.matches = best_matches;
        none.refusal = verified_candidates == 0
                           ? "no place of one looks like a place of the other"
                           : std::to_string(verified_candidates) +
                                 " places looked alike; at best " + std::to_string(best_inliers) +
                                 " of " + std::to_string(best_matches) +
                                 " 3-D matches agreed with one similarity (at least " +
                                 std::to_string(options.loop.min_inliers) + " and half needed)";
        revisits.push_back(std::move(none));
        continue;
      }
      // The best revisits of different places (their frames min_frame_gap apart), so that a
      // pair meeting in several places is tied at each.
      std::sort(found.begin(), found.end(),
                [](const MergeOverlap& x, const MergeOverlap& y) { return x.inliers > y.inliers; });
      std::vector<MergeOverlap> kept;
      for (MergeOverlap& revisit : found) {
        if (kept.size() >= static_cast<size_t>(options.max_revisits_per_pair)) break;
        const bool new_place = std::none_of(kept.begin(), kept.end(), [&](const MergeOverlap& x) {
          return std::abs(static_cast<long>(x.frame_b) - static_cast<long>(revisit.frame_b)) <
                 options.min_frame_gap;
        });
        if (new_place) kept.push_back(std::move(revisit));
      }
      for (MergeOverlap& revisit : kept) {
        spdlog::info(
            "merge: revisit: {} frame {} is {} frame {} (appearance {:.2f}, {} of {} "
            "3-D matches agree)",
            sb.folder.string(), revisit.frame_b, sa.folder.string(), revisit.frame_a, revisit.score,
            revisit.inliers, revisit.matches);
        revisits.push_back(std::move(revisit));
      }
    }
  }
  return revisits;
}

// Whether two rigs are the same calibration (the global adjustment takes one rig).
bool SameRig(const Rig& a, const Rig& b) {
  if (a.cameras.size() != b.cameras.size()) return false;
  for (size_t c = 0; c < a.cameras.size(); ++c) {
    const Camera& x = a.cameras[c];
    const Camera& y = b.cameras[c];
    if (x.model != y.model || x.width != y.width || x.height != y.height || x.params != y.params ||
        !x.cam_from_rig.rotation.coeffs().isApprox(y.cam_from_rig.rotation.coeffs(), 1e-12) ||
        (x.cam_from_rig.translation - y.cam_from_rig.translation).norm() > 1e-12)
      return false;
  }
  return true;
}

// The global bundle adjustment of a merged map whose drives share one rig (MergeOptions):
// keyframes are the drives' merged keyframes, observations the points' tracks as bearings of
// the rig's cameras (COLMAP camera id k of a drive is its rig camera, renumbered by the merge
// in the drives' order: `camera_base` per drive). `frame_of_name` per drive.
void AdjustMergedMap(const Rig& rig,
                     const std::vector<std::map<std::string, size_t>>& frame_of_name,
                     const std::vector<uint32_t>& camera_base, bool several_drives,
                     BundleAdjustmentOptions::Mode mode, BundleAdjustmentOptions options,
                     MergeResult* result) {
  ColmapModel& model = result->model;
  std::vector<std::map<size_t, int>> keyframe_of_frame(result->drives.size());
  BundleAdjustmentProblem problem;
  std::vector<Rigid3d> old_poses;
  for (size_t d = 0; d < result->drives.size(); ++d) {
    const MergedDrive& drive = result->drives[d];
    for (size_t k = 0; k < drive.keyframes.size(); ++k) {
      keyframe_of_frame[d][drive.keyframe_frames[k]] = static_cast<int>(problem.keyframes.size());
      problem.keyframes.push_back(
          {drive.keyframes[k].world_from_rig, problem.keyframes.size() < 2});
      old_poses.push_back(drive.keyframes[k].world_from_rig);
    }
  }
  std::map<std::string, size_t> drive_of_label;
  for (size_t d = 0; d < result->drives.size(); ++d) drive_of_label[result->drives[d].label] = d;
  std::unordered_map<uint32_t, std::pair<int, int>> keyframe_camera_of;  // image id -> both
  for (const ColmapImage& image : model.images) {
    size_t d = 0;
    if (several_drives) {
      const auto label = drive_of_label.find(image.name.substr(0, image.name.find('/')));
      if (label == drive_of_label.end()) continue;
      d = label->second;
    }
    const auto frame = frame_of_name[d].find(fs::path(image.name).stem().string());
    if (frame == frame_of_name[d].end()) continue;
    const auto keyframe = keyframe_of_frame[d].find(frame->second);
    const int camera = static_cast<int>(image.camera_id) - static_cast<int>(camera_base[d]) - 1;
    if (keyframe == keyframe_of_frame[d].end() || camera < 0 ||
        camera >= static_cast<int>(rig.NumCameras()))
      continue;
    keyframe_camera_of[image.id] = {keyframe->second, camera};
  }
  std::unordered_map<uint32_t, size_t> image_index;
  for (size_t i = 0; i < model.images.size(); ++i) image_index[model.images[i].id] = i;
  struct Source {
    size_t point, element;
  };
  std::vector<Source> sources;
  for (size_t p = 0; p < model.points.size(); ++p) {
    problem.points_in_world.push_back(model.points[p].xyz);
    for (size_t e = 0; e < model.points[p].track.size(); ++e) {
      const ColmapTrackElement& element = model.points[p].track[e];
      const auto it = keyframe_camera_of.find(element.image_id);
      if (it == keyframe_camera_of.end()) continue;
      const ColmapImage& image = model.images[image_index.at(element.image_id)];
      BundleAdjustmentObservation observation;
      observation.keyframe = it->second.first;
      observation.camera = it->second.second;
      observation.point = static_cast<int>(p);
      const Eigen::Vector2d pixel =
          image.points2d.at(element.point2d_idx).xy - Eigen::Vector2d(0.5, 0.5);
      if (!rig.cameras[observation.camera].Unproject(pixel, &observation.bearing)) continue;
      problem.observations.push_back(observation);
      sources.push_back({p, e});
    }
  }
  if (problem.keyframes.size() < 3 || problem.observations.empty()) {
    result->adjustment_skipped = "too few keyframes or observations";
    return;
  }
  options.mode = mode;
  result->adjustment = LocalBundleAdjust(rig, options, &problem);
  if (!result->adjustment.success) {
    result->adjustment_skipped = "the solver failed: " + result->adjustment.BriefReport();
    return;
  }
  result->adjusted = true;
  // Outlier observations leave their tracks (and their 2-D points lose the point).
  std::vector<std::vector<bool>> removed(model.points.size());
  for (size_t p = 0; p < model.points.size(); ++p)
    removed[p].assign(model.points[p].track.size(), false);
  for (int index : result->adjustment.removed_observations) {
    const Source& source = sources.at(static_cast<size_t>(index));
    removed[source.point][source.element] = true;
  }
  for (size_t p = 0; p < model.points.size(); ++p) {
    ColmapPoint3D& point = model.points[p];
    point.xyz = problem.points_in_world[p];
    std::vector<ColmapTrackElement> kept;
    for (size_t e = 0; e < point.track.size(); ++e) {
      if (!removed[p][e]) {
        kept.push_back(point.track[e]);
        continue;
      }
      ColmapImage& image = model.images[image_index.at(point.track[e].image_id)];
      image.points2d.at(point.track[e].point2d_idx).point3d_id = -1;
    }
    point.track = std::move(kept);
  }
  // The keyframes' and images' new poses; every other frame follows the keyframe at or before
  // it.
  for (ColmapImage& image : model.images) {
    const auto it = keyframe_camera_of.find(image.id);
    if (it == keyframe_camera_of.end()) continue;
    image.cam_from_world = rig.cameras[it->second.second].cam_from_rig *
                           problem.keyframes[it->second.first].world_from_rig.Inverse();
  }
  for (size_t d = 0; d < result->drives.size(); ++d) {
    MergedDrive& drive = result->drives[d];
    for (size_t k = 0; k < drive.keyframes.size(); ++k)
      drive.keyframes[k].world_from_rig =
          problem.keyframes[keyframe_of_frame[d].at(drive.keyframe_frames[k])].world_from_rig;
    for (size_t f = 0; f < drive.frames.size(); ++f) {
      const auto next = keyframe_of_frame[d].upper_bound(drive.frame_frames[f]);
      if (keyframe_of_frame[d].empty()) break;
      const int k = next == keyframe_of_frame[d].begin() ? keyframe_of_frame[d].begin()->second
                                                         : std::prev(next)->second;
      const Rigid3d correction = problem.keyframes[k].world_from_rig * old_poses[k].Inverse();
      drive.frames[f].world_from_rig = correction * drive.frames[f].world_from_rig;
    }
  }
}

// The segments' frame rays (sparse/frame_rays.txt) in the merged model. Each frame's rays come
// from the segment that poses the frame in the merge (the one in which it is most central), so
// that two segments' rays of a shared frame are not both kept; a frame point is kept by the
// segment that poses the last frame that saw it, with all its rays. A ray's centre keeps its place
// in the rig of its frame: from the segment's pose of the frame to the frame's merged pose (the
// similarity, then the adjustment's correction); a frame point moves so with its last frame.
void MergeFrameRays(const std::vector<MergeSegment>& segments,
                    const std::function<std::string(int, const std::string&)>& merged_name,
                    const std::function<uint32_t(int, uint32_t)>& merged_point_id,
                    MergeResult* result) {
  const int count = static_cast<int>(segments.size());
  for (const MergedDrive& drive : result->drives) {
    // Frame -> its merged pose and the segment that pose comes from.
    std::map<size_t, Rigid3d> merged_pose;
    std::map<size_t, int> owner;
    for (size_t f = 0; f < drive.frames.size(); ++f) {
      merged_pose[drive.frame_frames[f]] = drive.frames[f].world_from_rig;
      owner[drive.frame_frames[f]] = drive.frame_segments[f];
    }
    for (int s = 0; s < count; ++s) {
      const MergeSegment& segment = segments[s];
      if (!result->merged[s] || segment.drive != drive.folder) continue;
      const double scale = result->city_from_segment[s].scale;
      // A point of the segment's world, seen from frame `frame`, in the city; nothing when the
      // frame is not posed by both.
      const auto to_city = [&](size_t frame,
                               const Eigen::Vector3d& point) -> std::optional<Eigen::Vector3d> {
        const auto pose = segment.frame_poses.find(frame);
        const auto merged = merged_pose.find(frame);
        if (pose == segment.frame_poses.end() || merged == merged_pose.end()) return std::nullopt;
        return merged->second * (scale * (pose->second.world_from_rig.Inverse() * point));
      };
      const auto owned = [&](size_t frame) {
        const auto it = owner.find(frame);
        return it != owner.end() && it->second == s;
      };
      for (const ColmapFrameRayPoint& line : segment.model.frame_rays) {
        ColmapFrameRayPoint merged;
        merged.color = line.color;
        if (line.point3d_id != 0) {
          merged.point3d_id = merged_point_id(s, line.point3d_id);
          if (merged.point3d_id == 0) continue;
          const ColmapPoint3D& point = result->model.points.at(merged.point3d_id - 1);
          assert(point.id == merged.point3d_id);
          merged.xyz = point.xyz;
        } else {
          std::optional<size_t> last;
          for (const ColmapFrameRay& ray : line.rays) {
            const std::optional<size_t> frame = FrameOfImage(segment, ray.image_name);
            if (frame && (!last || *frame > *last)) last = frame;
          }
          if (!last || !owned(*last)) continue;
          const std::optional<Eigen::Vector3d> xyz = to_city(*last, line.xyz);
          if (!xyz) continue;
          merged.xyz = *xyz;
        }
        for (const ColmapFrameRay& ray : line.rays) {
          const std::optional<size_t> frame = FrameOfImage(segment, ray.image_name);
          if (!frame || (line.point3d_id != 0 && !owned(*frame))) continue;
          const std::optional<Eigen::Vector3d> centre = to_city(*frame, ray.centre);
          if (centre) merged.rays.push_back({merged_name(s, ray.image_name), *centre});
        }
        if (!merged.rays.empty()) result->model.frame_rays.push_back(std::move(merged));
      }
    }
  }
}

}  // namespace

BundleAdjustmentOptions MergeOptions::DefaultGlobalAdjustment() {
  BundleAdjustmentOptions options;
  options.linear_solver = BundleAdjustmentOptions::LinearSolver::kSparseSchur;
  // One thread: with more, Ceres sums the reduced system in the order its threads reach it and
  // two merges of the same runs differ in their last bits (as the SfM's global adjustments).
  options.num_threads = 1;
  options.max_iterations = 30;
  return options;
}

std::string MergeRevisitOptions::Check() const {
  const std::string loop_check = loop.Check();
  if (!loop_check.empty()) return "loop." + loop_check;
  if (min_frame_gap < 0) return "min_frame_gap: expected 0 or more";
  if (candidates_per_keyframe < 1) return "candidates_per_keyframe: expected 1 or more";
  if (max_revisits_per_pair < 1) return "max_revisits_per_pair: expected 1 or more";
  if (!(min_inlier_ratio >= 0.0 && min_inlier_ratio <= 1.0))
    return "min_inlier_ratio: expected a share in [0, 1]";
  if (!(max_drift_share > 0.0)) return "max_drift_share: expected > 0";
  if (!(max_rotation_deg > 0.0)) return "max_rotation_deg: expected > 0";
  return {};
}

std::string MergeOptions::Check() const {
  if (min_shared_frames < 2) return "min_shared_frames: expected 2 or more";
  if (!(max_rotation_residual_deg > 0.0)) return "max_rotation_residual_deg: expected > 0";
  if (!(max_centre_residual_share >= 0.0)) return "max_centre_residual_share: expected >= 0";
  if (!(min_centre_residual >= 0.0)) return "min_centre_residual: expected >= 0";
  if (!(corner_tolerance_px > 0.0)) return "corner_tolerance_px: expected > 0";
  const std::string revisit = revisits.Check();
  if (!revisit.empty()) return "revisits." + revisit;
  const std::string graph = pose_graph.Check();
  if (!graph.empty()) return "pose_graph." + graph;
  const std::string adjustment = bundle_adjustment.Check();
  if (!adjustment.empty()) return "bundle_adjustment." + adjustment;
  return {};
}

std::optional<MergeSegment> LoadMergeSegment(const fs::path& folder, std::string* why) {
  fs::path incomplete = folder;
  incomplete += ".incomplete";
  if (!fs::is_directory(folder)) {
    *why = fs::exists(incomplete)
               ? "missing: only " + incomplete.string() + " exists (the run was interrupted)"
               : "missing: no such folder";
    return std::nullopt;
  }
  // A reconstruction (reconstruct.json) or an SfM run (sfm.json: the same map, no surface).
  fs::path summary_path = folder / "reconstruct.json";
  if (!fs::exists(summary_path)) summary_path = folder / "sfm.json";
  if (!fs::exists(summary_path)) {
    *why = "not a complete reconstruction (no reconstruct.json nor sfm.json)";
    return std::nullopt;
  }
  try {
    nlohmann::json summary;
    try {
      summary = nlohmann::json::parse(ReadInputFile(summary_path));
    } catch (const nlohmann::json::exception& error) {
      throw InputError(summary_path, "", std::string("not valid JSON: ") + error.what());
    }
    if (summary.value("status", "") != "usable") {
      *why = "not usable (" + summary.value("outcome", std::string("no outcome given")) + ")";
      return std::nullopt;
    }
    MergeSegment segment;
    segment.folder = folder;
    segment.drive = summary.value("drive_absolute", summary.value("drive", std::string()));
    segment.mode = summary.value("mode", std::string());
    const Drive drive = Drive::Open(segment.drive);
    segment.rig = drive.rig();
    for (size_t i = 0; i < drive.NumFrames(); ++i) segment.frame_of_name[drive.FrameName(i)] = i;
    segment.first_frame = 0;
    segment.last_frame = drive.NumFrames() - 1;
    if (summary.contains("frame_range") && summary["frame_range"].contains("first")) {
      segment.first_frame = summary["frame_range"]["first"].get<size_t>();
      segment.last_frame = summary["frame_range"]["last"].get<size_t>();
    }
    const double frame_rate = summary.value("frame_rate", 15.0);
    // The frames' times as the run wrote them (frames.csv's, else frame / frame_rate); they
    // increase (calib/drive.h).
    std::vector<double> frame_of_time;
    for (size_t i = 0; i < drive.NumFrames(); ++i)
      frame_of_time.push_back(drive.HasTimestamps() ? drive.FrameTimestamp(i) : i / frame_rate);
    segment.frame_poses = PosesByFrame(ReadTum(folder / "frame_poses.tum"), frame_of_time,
                                       folder / "frame_poses.tum");
    segment.keyframe_poses =
        PosesByFrame(ReadTum(folder / "poses.tum"), frame_of_time, folder / "poses.tum");
    segment.model = ReadColmapModel(folder / "sparse");
    return segment;
  } catch (const InputError& error) {
    *why = error.what();
  } catch (const nlohmann::json::exception& error) {
    *why = summary_path.string() + ": " + error.what();
  }
  return std::nullopt;
}

MergeResult MergeSegments(const std::vector<MergeSegment>& segments, const MergeOptions& options) {
  ThrowIfInvalid(options.Check(), "MergeOptions");
  const int count = static_cast<int>(segments.size());
  MergeResult result;
  result.merged.assign(count, false);
  result.city_from_segment.assign(count, Sim3d());
  result.not_merged_why.assign(count, "");
  if (count == 0) return result;

  // Overlaps: segments of one drive that tracked the same frames.
  for (int a = 0; a < count; ++a) {
    for (int b = a + 1; b < count; ++b) {
      if (segments[a].drive != segments[b].drive) continue;
      MergeOverlap overlap = AlignSharedFrames(segments[a], segments[b], a, b, options);
      if (overlap.shared_frames == 0) continue;
      spdlog::info(
          "merge: {} and {}: {} shared frames, {} agree (rotation {:.3f} deg, centre "
          "{:.4f} RMS), scale {:.4f}{}",
          segments[a].folder.filename().string(), segments[b].folder.filename().string(),
          overlap.shared_frames, overlap.inliers, overlap.rms_rotation_deg, overlap.rms_centre,
          overlap.a_from_b.scale, overlap.verified ? "" : ": not verified, " + overlap.refusal);
      result.overlaps.push_back(std::move(overlap));
    }
  }

  // The group of the segment with the most keyframes, through verified overlaps.
  int fixed = 0;
  for (int s = 1; s < count; ++s)
    if (segments[s].keyframe_poses.size() > segments[fixed].keyframe_poses.size()) fixed = s;
  result.fixed_segment = fixed;
  std::vector<bool> reached;
  const auto join = [&] {
    reached.assign(count, false);
    std::deque<int> queue{fixed};
    reached[fixed] = true;
    while (!queue.empty()) {
      const int s = queue.front();
      queue.pop_front();
      for (const MergeOverlap& overlap : result.overlaps) {
        if (!overlap.verified || (overlap.a != s && overlap.b != s)) continue;
        const int other = overlap.a == s ? overlap.b : overlap.a;
        if (reached[other]) continue;
        reached[other] = true;
        result.city_from_segment[other] =
            overlap.a == s ? result.city_from_segment[s] * overlap.a_from_b
                           : result.city_from_segment[s] * overlap.a_from_b.Inverse();
        queue.push_back(other);
      }
    }
  };
  join();
  // Revisits between segments that share no frame, then the groups again (a revisit may join
  // what no shared frame did).
  if (options.revisits.enabled && count > 1) {
    double drive_length = 0.0;  // of the aligned segments, in city units
    for (int s = 0; s < count; ++s) {
      if (!reached[s]) continue;
      const StampedPose* previous = nullptr;
      for (const auto& [frame, pose] : segments[s].keyframe_poses) {
        if (previous)
          drive_length +=
              result.city_from_segment[s].scale *
              (pose.world_from_rig.translation - previous->world_from_rig.translation).norm();
        previous = &pose;
      }
    }
    std::vector<MergeOverlap> revisits =
        FindRevisits(segments, reached, result.city_from_segment, drive_length, options.revisits);
    // A pair that found no revisit is reported only when no shared frame joins it either.
    const auto has_shared_frames = [&](int a, int b) {
      return std::any_of(result.overlaps.begin(), result.overlaps.end(),
                         [&](const MergeOverlap& x) { return x.a == a && x.b == b; });
    };
    for (MergeOverlap& revisit : revisits)
      if (revisit.verified || !has_shared_frames(revisit.a, revisit.b))
        result.overlaps.push_back(std::move(revisit));
    join();
  }
  for (int s = 0; s < count; ++s) {
    result.merged[s] = reached[s];
    if (reached[s]) continue;
    std::string why = "no verified overlap joins it to " + segments[fixed].folder.string();
    for (const MergeOverlap& overlap : result.overlaps)
      if ((overlap.a == s || overlap.b == s) && !overlap.verified)
        why += "; with " + segments[overlap.a == s ? overlap.b : overlap.a].folder.string() + ": " +
               overlap.refusal;
    result.not_merged_why[s] = why;
  }
  // One pose graph over the merged segments (cycles share their disagreement).
  std::vector<PoseGraphEdge> edges;
  for (const MergeOverlap& overlap : result.overlaps) {
    if (!overlap.verified || !reached[overlap.a]) continue;
    edges.push_back({overlap.a, overlap.b, overlap.a_from_b, std::sqrt(double(overlap.inliers))});
  }
  if (!edges.empty())
    result.pose_graph =
        OptimizePoseGraph(edges, {fixed}, options.pose_graph, &result.city_from_segment);

  // Drive labels for image names: the drive folder's name when there are several drives.
  std::vector<std::string> drives;
  for (int s = 0; s < count; ++s)
    if (result.merged[s] &&
        std::find(drives.begin(), drives.end(), segments[s].drive) == drives.end())
      drives.push_back(segments[s].drive);
  std::map<std::string, std::string> label_of;
  for (const std::string& drive : drives) {
    std::string label = fs::path(drive).filename().string();
    if (label.empty()) label = "drive";
    std::string unique = label;
    for (int k = 2;; ++k) {
      bool used = false;
      for (const auto& [other, other_label] : label_of) used = used || other_label == unique;
      if (!used) break;
      unique = label + "_" + std::to_string(k);
    }
    label_of[drive] = unique;
  }
  const auto merged_name = [&](const MergeSegment& segment, const std::string& name) {
    return drives.size() > 1 ? label_of[segment.drive] + "/" + name : name;
  };

  // Cameras: those of each drive's first merged segment, renumbered.
  std::map<std::pair<std::string, uint32_t>, uint32_t> camera_of;  // (drive, old id) -> new id
  for (int s = 0; s < count; ++s) {
    if (!result.merged[s]) continue;
    for (const ColmapCamera& camera : segments[s].model.cameras) {
      const auto key = std::make_pair(segments[s].drive, camera.id);
      if (camera_of.count(key)) continue;
      ColmapCamera renumbered = camera;
      renumbered.id = static_cast<uint32_t>(result.model.cameras.size() + 1);
      camera_of[key] = renumbered.id;
      result.model.cameras.push_back(renumbered);
    }
  }

  // Images: one per name, posed by the segment in which its frame is most central.
  struct ImageSlot {
    int owner = -1;
    long centrality = -1;
    size_t frame = 0;
    const ColmapImage* source = nullptr;
    int segments = 0;
  };
  std::map<std::string, ImageSlot> slots;
  for (int s = 0; s < count; ++s) {
    if (!result.merged[s]) continue;
    for (const ColmapImage& image : segments[s].model.images) {
      ImageSlot& slot = slots[merged_name(segments[s], image.name)];
      const std::optional<size_t> frame = FrameOfImage(segments[s], image.name);
      const long centrality = frame ? Centrality(segments[s], *frame) : -1;
      ++slot.segments;
      if (slot.owner < 0 || centrality > slot.centrality) {
        slot.owner = s;
        slot.centrality = centrality;
        slot.frame = frame.value_or(0);
        slot.source = &image;
      }
    }
  }
  // In drive, frame and camera order.
  std::vector<std::pair<std::string, ImageSlot*>> ordered;
  for (auto& [name, slot] : slots) ordered.push_back({name, &slot});
  std::sort(ordered.begin(), ordered.end(), [&](const auto& x, const auto& y) {
    const MergeSegment& sx = segments[x.second->owner];
    const MergeSegment& sy = segments[y.second->owner];
    return std::make_tuple(label_of[sx.drive], x.second->frame, x.second->source->camera_id) <
           std::make_tuple(label_of[sy.drive], y.second->frame, y.second->source->camera_id);
  });
  std::map<std::string, size_t> image_index;  // merged name -> index in result.model.images
  for (const auto& [name, slot] : ordered) {
    const MergeSegment& owner = segments[slot->owner];
    ColmapImage image;
    image.id = static_cast<uint32_t>(result.model.images.size() + 1);
    image.name = name;
    image.camera_id = camera_of.at({owner.drive, slot->source->camera_id});
    image.cam_from_world =
        CamFromCity(slot->source->cam_from_world, result.city_from_segment[slot->owner]);
    image_index[name] = result.model.images.size();
    if (slot->segments > 1) ++result.shared_images;
    result.model.images.push_back(std::move(image));
  }

  // Points: one node per segment point; the segment points observed at one corner are one.
  std::vector<size_t> point_offset(count + 1, 0);
  for (int s = 0; s < count; ++s)
    point_offset[s + 1] =
        point_offset[s] + (result.merged[s] ? segments[s].model.points.size() : 0);
  const size_t num_nodes = point_offset[count];
  result.input_points = num_nodes;
  UnionFind classes(num_nodes);
  // Per merged image, its corners: pixel and the nodes seen there.
  struct Corner {
    Eigen::Vector2d xy;
    std::vector<size_t> nodes;
  };
  std::vector<std::vector<Corner>> corners(result.model.images.size());
  // (segment, image id, 2D index) -> (merged image, corner index), for the tracks.
  std::vector<std::unordered_map<uint64_t, std::pair<size_t, size_t>>> corner_of(count);
  const double tolerance_sq = options.corner_tolerance_px * options.corner_tolerance_px;
  std::vector<std::unordered_map<uint32_t, size_t>> nodes_of(count);  // point3d id -> node
  for (int s = 0; s < count; ++s) {
    if (!result.merged[s]) continue;
    for (size_t p = 0; p < segments[s].model.points.size(); ++p)
      nodes_of[s][segments[s].model.points[p].id] = point_offset[s] + p;
  }
  // The points a revisit matched are one.
  for (const MergeOverlap& overlap : result.overlaps) {
    if (!overlap.verified || !result.merged[overlap.a] || !result.merged[overlap.b]) continue;
    for (const auto& [point_a, point_b] : overlap.point_pairs) {
      const auto node_a = nodes_of[overlap.a].find(point_a);
      const auto node_b = nodes_of[overlap.b].find(point_b);
      if (node_a != nodes_of[overlap.a].end() && node_b != nodes_of[overlap.b].end())
        classes.Join(node_a->second, node_b->second);
    }
  }
  for (int s = 0; s < count; ++s) {
    if (!result.merged[s]) continue;
    const std::unordered_map<uint32_t, size_t>& node_of = nodes_of[s];
    for (const ColmapImage& image : segments[s].model.images) {
      const size_t merged = image_index.at(merged_name(segments[s], image.name));
      std::vector<Corner>& image_corners = corners[merged];
      for (size_t k = 0; k < image.points2d.size(); ++k) {
        const ColmapPoint2D& point = image.points2d[k];
        if (point.point3d_id < 0) continue;
        const auto node = node_of.find(static_cast<uint32_t>(point.point3d_id));
        if (node == node_of.end()) continue;
        size_t c = 0;
        while (c < image_corners.size() &&
               (image_corners[c].xy - point.xy).squaredNorm() > tolerance_sq)
          ++c;
        if (c == image_corners.size()) image_corners.push_back({point.xy, {}});
        for (size_t other : image_corners[c].nodes) classes.Join(other, node->second);
        image_corners[c].nodes.push_back(node->second);
        corner_of[s][(uint64_t{image.id} << 32) | k] = {merged, c};
      }
    }
  }
  // The merged points: the mean of their segment points in the city frame.
  std::unordered_map<size_t, size_t> merged_point_of;  // class root -> index in model.points
  std::vector<int> members;
  std::vector<Eigen::Vector3d> color_sum;
  for (int s = 0; s < count; ++s) {
    if (!result.merged[s]) continue;
    for (size_t p = 0; p < segments[s].model.points.size(); ++p) {
      const ColmapPoint3D& point = segments[s].model.points[p];
      const size_t root = classes.Find(point_offset[s] + p);
      auto [it, added] = merged_point_of.emplace(root, result.model.points.size());
      if (added) {
        ColmapPoint3D merged;
        merged.id = static_cast<uint32_t>(result.model.points.size() + 1);
        merged.xyz = Eigen::Vector3d::Zero();
        merged.error = 0.0;
        result.model.points.push_back(merged);
        members.push_back(0);
        color_sum.push_back(Eigen::Vector3d::Zero());
      }
      ColmapPoint3D& merged = result.model.points[it->second];
      merged.xyz += result.city_from_segment[s] * point.xyz;
      merged.error += point.error;
      color_sum[it->second] += point.color.cast<double>();
      ++members[it->second];
      for (const ColmapTrackElement& element : point.track) {
        const auto corner =
            corner_of[s].find((uint64_t{element.image_id} << 32) | element.point2d_idx);
        if (corner == corner_of[s].end()) continue;
        const ColmapTrackElement observation{result.model.images[corner->second.first].id,
                                             static_cast<uint32_t>(corner->second.second)};
        const bool seen = std::any_of(merged.track.begin(), merged.track.end(), [&](const auto& e) {
          return e.image_id == observation.image_id && e.point2d_idx == observation.point2d_idx;
        });
        if (!seen) merged.track.push_back(observation);
      }
    }
  }
  for (size_t i = 0; i < result.model.points.size(); ++i) {
    ColmapPoint3D& merged = result.model.points[i];
    merged.xyz /= members[i];
    merged.error /= members[i];
    merged.color = (color_sum[i] / members[i]).array().round().cast<uint8_t>();
    if (members[i] > 1) ++result.fused_points;
  }
  // The images' 2-D points: their corners, each with its merged point.
  for (size_t i = 0; i < result.model.images.size(); ++i) {
    for (const Corner& corner : corners[i]) {
      ColmapPoint2D point;
      point.xy = corner.xy;
      point.point3d_id = result.model.points[merged_point_of.at(classes.Find(corner.nodes[0]))].id;
      result.model.images[i].points2d.push_back(point);
    }
  }

  // The poses per drive: each frame from the segment in which it is most central.
  for (const std::string& drive : drives) {
    MergedDrive merged;
    merged.folder = drive;
    merged.label = label_of[drive];
    const auto collect = [&](std::map<size_t, StampedPose> MergeSegment::*poses,
                             std::vector<StampedPose>* out, std::vector<size_t>* frames,
                             std::vector<int>* owners) {
      struct Best {
        long centrality;
        int segment;
        StampedPose pose;
      };
      std::map<size_t, Best> best;
      for (int s = 0; s < count; ++s) {
        if (!result.merged[s] || segments[s].drive != drive) continue;
        for (const auto& [frame, pose] : segments[s].*poses) {
          const long centrality = Centrality(segments[s], frame);
          const auto it = best.find(frame);
          if (it != best.end() && it->second.centrality >= centrality) continue;
          StampedPose city = pose;
          city.world_from_rig = TransformPose(result.city_from_segment[s], pose.world_from_rig);
          best[frame] = {centrality, s, city};
        }
      }
      for (const auto& [frame, entry] : best) {
        out->push_back(entry.pose);
        frames->push_back(frame);
        if (owners) owners->push_back(entry.segment);
      }
    };
    collect(&MergeSegment::keyframe_poses, &merged.keyframes, &merged.keyframe_frames, nullptr);
    collect(&MergeSegment::frame_poses, &merged.frames, &merged.frame_frames,
            &merged.frame_segments);
    result.drives.push_back(std::move(merged));
  }

  // One rig for the adjustment: every merged drive's must be the same calibration.
  std::vector<int> drive_segment;  // a merged segment of each drive
  for (const MergedDrive& drive : result.drives)
    for (int s = 0; s < count; ++s)
      if (result.merged[s] && segments[s].drive == drive.folder) {
        drive_segment.push_back(s);
        break;
      }
  bool one_rig = true;
  for (int s : drive_segment) one_rig = one_rig && SameRig(segments[s].rig, segments[fixed].rig);
  size_t observations = 0;
  for (const ColmapPoint3D& point : result.model.points) observations += point.track.size();
  if (!options.global_bundle_adjustment) {
    result.adjustment_skipped = "off";
  } else if (!one_rig) {
    result.adjustment_skipped = "the drives have different rigs";
  } else if (observations > options.max_adjusted_observations) {
    result.adjustment_skipped = std::to_string(observations) + " observations, above " +
                                std::to_string(options.max_adjusted_observations);
  } else {
    const auto start = std::chrono::steady_clock::now();
    std::vector<std::map<std::string, size_t>> frame_of_name;
    std::vector<uint32_t> camera_base;
    for (int s : drive_segment) {
      frame_of_name.push_back(segments[s].frame_of_name);
      camera_base.push_back(
          camera_of.at({segments[s].drive, segments[s].model.cameras.front().id}) - 1);
    }
    AdjustMergedMap(segments[fixed].rig, frame_of_name, camera_base, result.drives.size() > 1,
                    segments[fixed].mode == "central" ? BundleAdjustmentOptions::Mode::kCentral
                                                      : BundleAdjustmentOptions::Mode::kNonCentral,
                    options.bundle_adjustment, &result);
    result.adjustment_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  }
  MergeFrameRays(
      segments, [&](int s, const std::string& name) { return merged_name(segments[s], name); },
      [&](int s, uint32_t id) -> uint32_t {
        const auto node = nodes_of[s].find(id);
        if (node == nodes_of[s].end()) return 0;
        return result.model.points[merged_point_of.at(classes.Find(node->second))].id;
      },
      &result);
  return result;
}

}  // namespace omni
