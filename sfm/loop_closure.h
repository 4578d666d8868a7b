#pragma once
// Place recognition for loop closure (docs/design.md §9), first part: a compact appearance
// descriptor per keyframe (a small zero-mean, unit-norm thumbnail per camera) and a search
// among keyframes far enough back in time. For a ring of side cameras a rotation of the
// vehicle is a cyclic shift of the cameras, so every shift of the ring is scored. Then the
// geometric verification of a candidate (VerifyLoop: a relative pose of the rig in RANSAC on the
// matched bearings, and a 3-D similarity of the matched map points, which must agree) and the
// correction (sfm/pose_graph.h, then a global bundle adjustment).

#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/pose.h"
#include "calib/rig.h"
#include "sfm/pose_graph.h"
#include "sfm/relative_pose_central.h"
#include "sfm/relative_pose_noncentral.h"
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
  // One unit-norm, zero-mean thumbnail per camera of the ring (empty for the others).
  std::vector<std::vector<float>> cameras;
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
  // The best `count` keyframes (each with its best shift) scoring at least min_score, best
  // first. One matrix product over all stored thumbnails: linear in the keyframes.
  std::vector<LoopCandidate> QueryBest(const PlaceDescriptor& query, int before, int count) const;
  double Score(const PlaceDescriptor& query, const PlaceDescriptor& candidate, int shift) const;
  int size() const { return static_cast<int>(descriptors_.size()); }

 private:
  LoopDetectionOptions options_;
  std::vector<int> ring_;
  std::vector<PlaceDescriptor> descriptors_;
  // The ring thumbnails of every keyframe, one row per (keyframe, ring position).
  std::vector<float> ring_rows_;
};

// The ring shift a rotation of the rig implies: for each ring camera i of the revisit, the ring
// camera of the place seen before whose optical axis its axis comes closest to once rotated by
// then_from_now; the most frequent i+shift. −1 without a ring of at least 3 cameras.
int RingShiftOfRotation(const Rig& rig, const std::vector<int>& ring,
                        const Eigen::Quaterniond& then_from_now);

struct LoopClosureOptions {
  LoopDetectionOptions detection;
  // Between the revisit's and the candidate's corners, all against all (one matrix product of
  // their normalised windows per camera pair): half_window, min_zncc, max_distance_ratio and
  // mutual apply; the matches keep the detected corners (no subpixel refinement).
  ZnccOptions matching;
  double prepared_downscale = 2.0;  // images kept per keyframe for matching, shrunk by this
  int ransac_iterations = 300;
  // Inlier of the similarity: ‖S p_new − p_old‖ below this share of the median depth of the
  // candidate's points.
  double inlier_depth_share = 0.03;
  int min_inliers = 20;
  int max_candidates = 2;  // verified per keyframe, best appearance first
  // Geometric verification by the relative pose of the rig from the matched bearings (all the
  // 2-D matches, with or without a map point). kFollowRig: central when Rig::central. Central:
  // the ring's bearings rotated into the rig frame, one camera at the rig centre (the tracker's
  // central approximation), five-point solver; the generalised solvers are degenerate for a
  // rig whose camera offsets are small against the depths (Ladybug: 4 cm). Generalised: the
  // rig's cam_from_rig offsets (sfm/relative_pose_noncentral.h).
  enum class RelativePoseModel { kFollowRig, kCentral, kGeneralized };
  RelativePoseModel relative_pose_model = RelativePoseModel::kFollowRig;
  CentralRelativePoseOptions central_relative_pose = DefaultCentralRelativePose();
  NoncentralRelativePoseOptions generalized_relative_pose = DefaultGeneralizedRelativePose();
  int min_relative_inliers = 20;  // inliers of the relative pose
  // Inliers over the 2-D matches. The paper drive's true loop: 0.78 to 0.98 over the runs; its
  // look-alike places (repetitive streets): at most 0.45, once 0.56 (frame 1475 with frame 88,
  // which then also passed the similarity and a 2.9 degree rotation bound and wrecked the map).
  double min_relative_inlier_ratio = 0.7;
  // The relative pose and the rotation the similarity gives the revisit must agree (radians):
  // two independent estimates of one motion. True loops of the demo and paper drives: 0.08 to
  // 0.15 degrees apart; the look-alike above: 1.9 degrees. 1 degree.
  double max_rotation_disagreement = 0.0175;
  // The ring shift of the relative rotation must be the one the appearance found.
  bool check_ring_shift = true;
  // A verified similarity must move the revisiting keyframe by at most this share of the path
  // driven (keyframe centre to centre) since the place seen before: drift beyond it is not
  // drift but a wrong place that looks alike (a repetitive street).
  double max_drift_share = 0.1;
  // Before any matching, a candidate must be within reach of the drift bound: its keyframe no
  // farther from the revisit in the map than max_drift_share of the path between them plus
  // this many mean keyframe steps (how far from a place a revisit may pass and look alike).
  double revisit_reach_keyframes = 10.0;
  int cooldown_keyframes = 20;  // keyframes after a closure before the next one is tried
  double loop_edge_weight = 10.0;
  PoseGraphOptions pose_graph;
  bool global_bundle_adjustment = true;
  // The adjustment after a closure stops when an iteration lowers the cost by less than this
  // share (Ceres's function_tolerance). After the pose graph's correction its first few
  // iterations take the cost down by a quarter; then it creeps, a few 1e-4 per iteration for
  // twenty more (the keyframes before the closure: over ten loop drives and modes, the
  // error at 1e-4 is 1.003 times that at 1e-6 in geometric mean, from 0.78 to 1.11 times,
  // for 0.58 of the time; docs/figures.md F72). The final adjustment keeps the tracker's
  // TrackerOptions::global_bundle_adjustment_function_tolerance.
  double global_bundle_adjustment_function_tolerance = 1e-4;
  unsigned seed = 1;

  std::string Check() const;
  static CentralRelativePoseOptions DefaultCentralRelativePose();
  static NoncentralRelativePoseOptions DefaultGeneralizedRelativePose();
};

// The matches between a revisiting keyframe ("now") and a candidate ("then"). 2-D: unit
// bearings in the cameras of each keyframe; 3-D: the map points (world) of the matches whose
// corners both belong to a track with a point, and those tracks (now, then).
struct LoopMatches {
  std::vector<Eigen::Vector3d> bearings_now, bearings_then;
  std::vector<int> cameras_now, cameras_then;
  std::vector<Eigen::Vector3d> points_now, points_then;
  std::vector<std::pair<int, int>> tracks;
  std::vector<int> match_of_point;  // the 2-D match of each 3-D match (empty: not known)
};

struct LoopVerification {
  bool accepted = false;
  std::string refusal;  // why it was refused (empty when accepted)
  // Relative pose: rig_then_from_rig_now (central: unit translation), its inliers among the
  // 2-D matches.
  int matches = 0, relative_inliers = 0;
  Rigid3d then_from_now;
  int ring_shift = -1;  // of the relative rotation (RingShiftOfRotation)
  // 3-D similarity then_from_now of the world (the drifted revisit onto the place), its inliers
  // among the 3-D matches, and the tracks of those inliers that are also inliers of the
  // relative pose (when match_of_point is given): the pairs the closure merges.
  int points = 0, similarity_inliers = 0;
  Sim3d similarity;
  std::vector<std::pair<int, int>> inlier_tracks;
  double rotation_disagreement = 0.0;  // radians, relative pose vs similarity
  double drift_share = 0.0;            // LoopDriftShare of the similarity
};

// The similarity dst ≈ S src of matched 3-D points: three-point Umeyama samples in RANSAC
// (`iterations`, seeded), refit on the inliers (closer than `threshold`), whose indices go to
// *inliers (fewer than 3: identity, no inliers).
Sim3d EstimateSimilarityRansac(const std::vector<Eigen::Vector3d>& src,
                               const std::vector<Eigen::Vector3d>& dst, double threshold,
                               int iterations, unsigned seed, std::vector<int>* inliers);

// All-against-all ZNCC matches (index1, index2) between the corners of two prepared images
// (pixels of those images), with the checks of ZnccOptions (minimum score, distinctiveness
// ratio, mutual best): one matrix product of their normalised windows. What the loop closer
// matches a revisit with, and `merge` two segments' keyframes.
std::vector<std::pair<int, int>> MatchCornersAllPairs(const cv::Mat& image1,
                                                      const std::vector<Eigen::Vector2d>& corners1,
                                                      const cv::Mat& image2,
                                                      const std::vector<Eigen::Vector2d>& corners2,
                                                      const ZnccOptions& options);

// The geometric verification of a candidate, cheapest first: the 3-D similarity in RANSAC and
// the drift bound (max_drift_share), the relative pose of the rig (inliers and ratio) and the
// ring shift it implies against the appearance's `shift`, and their rotations' agreement.
// `world_from_keyframe` are the map's keyframe poses, `ring` the detector's.
LoopVerification VerifyLoop(const Rig& rig, const std::vector<int>& ring, int shift,
                            const LoopMatches& matches,
                            const std::vector<Rigid3d>& world_from_keyframe, int then, int now,
                            const LoopClosureOptions& options, unsigned seed);

// Where the loop closer's time goes (CPU seconds of the calling thread, summed over the
// keyframes; the global adjustment runs on that thread when its num_threads is 1).
struct LoopClosureTimings {
  double prepare = 0.0;  // thumbnails, prepared images, bearings of each keyframe
  double query = 0.0;    // appearance search
  double match = 0.0;    // ZNCC matching of the candidates
  double verify = 0.0;   // relative pose, similarity
  double correct = 0.0;  // pose graph and map correction
  double global_bundle_adjustment = 0.0;
  int keyframes = 0, queries = 0, candidates = 0, closures = 0;
  std::string Summary() const;
};

// What a closure did: where, and how much it moved the revisiting keyframe.
struct LoopClosureEvent {
  int keyframe = -1, frame = -1;                      // the revisit
  int candidate_keyframe = -1, candidate_frame = -1;  // the place seen before
  int shift = 0;
  double score = 0.0;
  int matches = 0, inliers = 0;  // 3-D matches and the similarity's inliers
  // The relative pose: 2-D matches, inliers, and its disagreement with the similarity (radians).
  int relative_matches = 0, relative_inliers = 0;
  double rotation_disagreement = 0.0;
  double correction_translation = 0.0;  // how far the revisiting keyframe moved (map units)
  double correction_scale = 1.0;        // its scale correction
  double ms = 0.0;
  std::string Summary() const;
};

// Whether a candidate can pass the drift bound at all (max_drift_share, revisit_reach_keyframes)
// given the map's keyframe poses, before any matching.
bool LoopWithinReach(const std::vector<Rigid3d>& world_from_rig, int then, int now,
                     const LoopClosureOptions& options);

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
  const LoopClosureTimings& timings() const { return timings_; }
  ~LoopCloser();

 private:
  struct KeyframeData {
    int frame = -1;
    std::vector<cv::Mat> prepared;                       // per camera (ring cameras only)
    std::vector<std::vector<Eigen::Vector2d>> corners;   // per camera, prepared pixels
    std::vector<std::vector<Eigen::Vector3d>> bearings;  // per camera, unit, of each corner
    std::vector<std::vector<int>> tracks;                // per camera, track of each corner
  };
  LoopMatches Match(const KeyframeData& now, const KeyframeData& then, int shift,
                    const Tracker& tracker, int now_keyframe, int then_keyframe) const;
  Rig rig_;
  LoopClosureOptions options_;
  LoopDetector detector_;
  std::vector<KeyframeData> keyframes_;
  int last_closure_ = -1000000;
  LoopClosureTimings timings_;
};

}  // namespace omni
