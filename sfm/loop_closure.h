#pragma once
// Place recognition for loop closure (DESIGN.md §6, issue 9), first part: a compact appearance
// descriptor per keyframe (a small zero-mean, unit-norm thumbnail per camera) and a search
// among keyframes far enough back in time. For a ring of side cameras a rotation of the
// vehicle is a cyclic shift of the cameras, so every shift of the ring is scored. Not yet here:
// the geometric verification (relative pose in RANSAC on matched bearings) and the correction
// (sfm/pose_graph.h, then global adjustment).

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/pose_graph.h"
#include "sfm/track_builder.h"
#include "sfm/tracker.h"

namespace omni {

struct LoopDetectionOptions {
  int thumbnail_width = 16;  // pixels of each camera's thumbnail
  int thumbnail_height = 12;
  // A camera belongs to the ring when its optical axis is within this angle of the plane the
  // rig's axes spread in most (radians; the up camera of a Ladybug is ~90° off).
  double ring_max_elevation = 0.5;
  int min_keyframe_gap = 30;  // candidates are at least this many keyframes older
  double min_score = 0.7;     // mean ZNCC of the ring cameras' thumbnails

  std::string Check() const;
};

struct PlaceDescriptor {
  std::vector<std::vector<float>> cameras;  // one unit-norm, zero-mean thumbnail per camera
};

struct LoopCandidate {
  int keyframe = -1;  // index in the order the descriptors were added
  int shift = 0;      // the query's ring camera i looks like the candidate's ring camera i+shift
  double score = -1.0;
};

class LoopDetector {
 public:
  LoopDetector(const Rig& rig, const LoopDetectionOptions& options);

  // The ring cameras in azimuth order around the ring's axis (all cameras when fewer than 3).
  const std::vector<int>& ring() const { return ring_; }
  PlaceDescriptor Describe(const std::vector<cv::Mat>& images) const;
  // Adds the keyframe's descriptor; returns its index.
  int Add(PlaceDescriptor descriptor);
  // The best keyframe at least min_keyframe_gap before `before` (exclusive) over every ring
  // shift, or keyframe −1 when none scores min_score.
  LoopCandidate Query(const PlaceDescriptor& query, int before) const;
  double Score(const PlaceDescriptor& query, const PlaceDescriptor& candidate, int shift) const;
  int size() const { return static_cast<int>(descriptors_.size()); }

 private:
  LoopDetectionOptions options_;
  std::vector<int> ring_;
  std::vector<PlaceDescriptor> descriptors_;
};

struct LoopClosureOptions {
  LoopDetectionOptions detection;
  ZnccOptions matching;             // between the revisit's and the candidate's images
  double prepared_downscale = 2.0;  // images kept per keyframe for matching, shrunk by this
  int ransac_iterations = 300;
  // Inlier of the similarity: ‖S p_new − p_old‖ below this share of the median depth of the
  // candidate's points.
  double inlier_depth_share = 0.03;
  int min_inliers = 20;
  // A verified similarity must move the revisiting keyframe by at most this share of the path
  // driven (keyframe centre to centre) since the place seen before: drift beyond it is not
  // drift but a wrong place that looks alike (a repetitive street).
  double max_drift_share = 0.1;
  int cooldown_keyframes = 20;  // keyframes after a closure before the next one is tried
  double loop_edge_weight = 10.0;
  PoseGraphOptions pose_graph;
  bool global_bundle_adjustment = true;
  unsigned seed = 1;

  std::string Check() const;
};

// What a closure did: where, and how much it moved the revisiting keyframe.
struct LoopClosureEvent {
  int keyframe = -1, frame = -1;                      // the revisit
  int candidate_keyframe = -1, candidate_frame = -1;  // the place seen before
  int shift = 0;
  double score = 0.0;
  int matches = 0, inliers = 0;
  double correction_translation = 0.0;  // how far the revisiting keyframe moved (map units)
  double correction_scale = 1.0;        // its scale correction
  double ms = 0.0;
  std::string Summary() const;
};

// How far then_from_now moves keyframe `now` (world_from_rig poses of the map), as a share of
// the path from keyframe `then` to `now` through the keyframe centres; infinity for no path.
double LoopDriftShare(const std::vector<Rigid3d>& world_from_rig, int then, int now,
                      const Sim3d& then_from_now);

class LoopCloser {
 public:
  LoopCloser(const Rig& rig, const LoopClosureOptions& options);
  // Call after each new keyframe of the tracker (its newest one), with the frame's images and
  // tracked observations (pixels of the input images). Returns true and fills *event when a
  // loop was closed and the tracker's map corrected.
  bool AddKeyframe(const std::vector<cv::Mat>& images, const TrackedFrame& frame, Tracker* tracker,
                   LoopClosureEvent* event);

 private:
  struct KeyframeData {
    int frame = -1;
    std::vector<cv::Mat> prepared;                      // per camera
    std::vector<std::vector<Eigen::Vector2d>> corners;  // per camera, prepared pixels
    std::vector<std::vector<int>> tracks;               // per camera, track of each corner
  };
  Rig rig_;
  LoopClosureOptions options_;
  LoopDetector detector_;
  std::vector<KeyframeData> keyframes_;
  int last_closure_ = -1000000;
};

}  // namespace omni
