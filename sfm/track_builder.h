#pragma once
// The image front end of the tracker: Harris corners in every camera of every frame, matched by
// ZNCC against the previous frame of the same camera inside a search region predicted by a
// constant image-motion model (the median displacement of the camera's last matches), chained
// into tracks; matched and new corners become bearings through the camera model. Works on any
// rig (1 to N cameras); detection and matching run in parallel over the cameras (TBB).
// Once the tracker predicts the pose (constant velocity), corners whose track has a map point
// are searched in a small region around its reprojection (a PixelPredictor), and the corners
// still unmatched along their epipolar segment (a RigMotion): near structure moves far more
// than the median flow. After a frame the
// tracker could not track (a black frame, a jump), the next frames are matched against the
// last keyframe's images in a wider region (re-localisation), so that tracks resume with the
// keyframe's track ids. Once the tracker has resected the frame, it asks for its map points
// to be searched among the corners whose track has no point (MapPointSearcher, matching of
// sfm/map_point_search.h): a corner found to be a map point takes the point's track, in any
// camera, which continues tracks across overlapping neighbour cameras.
// When the image-motion model fails (wide baselines, low frame rates, the first frames, after a
// gap), the frame just added can be matched again without any prior (RematchByDescriptors:
// binary descriptors at the corners, all cameras against all, sfm/descriptor_matching.h)
// against one of the last keyframes, newest first; its corners take the keyframe's tracks.
// For a rig whose cameras overlap, MatchOverlappingCameras gives the corners that two cameras
// of the frame see alike one track, checked against the rig's own epipolar geometry.

#include <Eigen/Core>
#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <string>
#include <vector>

#include "calib/rig.h"
#include "sfm/descriptor_matching.h"
#include "sfm/harris.h"
#include "sfm/map_point_search.h"
#include "sfm/tracker.h"
#include "sfm/zncc_matching.h"

namespace omni {

struct TrackBuilderOptions {
  HarrisOptions harris;
  ZnccOptions zncc;
  // Radius of the search region around the predicted position (pixels of the prepared image).
  double search_radius = 30.0;
  // Radius around the reprojection of a track's map point by the predicted pose (pixels of the
  // prepared image): the constant-velocity model's error, mostly the change of turn rate.
  double predicted_search_radius = 15.0;
  // Radius when re-localising against the last keyframe (no motion model after a failure).
  double relocalisation_search_radius = 80.0;
  // A continued track takes the subpixel ZNCC maximum of the previous frame's window
  // (ZnccMatch::pixel2) rather than the detected corner's position.
  bool follow_window = true;
  // Re-observation of the map points once the frame is resected (MapPointSearcher).
  MapPointSearchOptions map_search;
  // Matching without a motion prior (RematchByDescriptors, MatchOverlappingCameras).
  DescriptorMatchingOptions descriptors;
  // Keyframes kept for RematchByDescriptors (the newest first).
  int rematch_keyframes = 3;
  // MatchOverlappingCameras: a match is kept when each ray passes within this angle of the
  // other camera's epipolar plane (radians) and the two rays meet in front of both cameras.
  double stereo_max_epipolar_angle = 0.004;
  // The tracks of the frame before are continued among this many times harris.max_corners
  // corners of each image (a pool: HarrisOptions::pool_corners), and the frame keeps every
  // corner that continues a track plus the strongest of the others up to max_corners: a track
  // no longer ends because its corner fell just below the max_corners strongest of the next
  // frame, while the corners per image stay max_corners. 1: no pool (each frame's
  // max_corners strongest only).
  double continuation_pool = 2.0;
  // The corners of the frame before that the image-motion model left unmatched (those of
  // tracks without a map point: a map point's reprojection is searched around instead) are
  // searched again along their epipolar segment in the new frame, when the rig's motion is
  // predicted (AddFrame's `motion`): from where the corner would be at infinite depth to where it
  // would be at epipolar_min_depth times the camera's predicted step, within
  // epipolar_search_radius of that segment. Near structure (a parked car beside the road, a pole,
  // a kerb) moves many times the camera's median flow between two frames and is otherwise never
  // tracked, so never mapped. 0: off.
  double epipolar_min_depth = 1.5;
  // The half width of the band around the epipolar segment (pixels of the prepared image) is
  // epipolar_search_radius plus the motion model's error across the segment as it was on the
  // frame before (RigMotion): its rotation error and, at the segment's near end, its
  // translation error across the step, both in the camera's pixels; at most
  // epipolar_max_search_radius. A wider band holds more corners that look alike: a rig's
  // prediction is a few hundredths of a degree and about a percent of the step off at a drive's
  // frame rate (a pixel or two), a single camera's translation often several times that. A camera
  // whose rotation error alone moves an image point by more than half of epipolar_max_search_radius
  // is not searched along (in turns at a low frame rate the model is degrees off).
  double epipolar_search_radius = 6.0;
  double epipolar_max_search_radius = 15.0;

  std::string Check() const;
};

// The rig's motion from the frame before to the new frame, as the tracker predicts it: where a
// corner of the frame before may lie in the new frame, whatever its depth.
struct RigMotion {
  Rigid3d previous_world_from_rig;  // the frame before (tracked)
  Rigid3d world_from_rig;           // the new frame (predicted)
  // How far the prediction's rotation may be off (radians): the model's error on the frame
  // before; negative when unknown. A camera searches along epipolar segments only where this
  // moves an image point by less than half the widest band (epipolar_max_search_radius; in
  // turns at a low frame rate the model is degrees off, and a band in the wrong place offers
  // only look-alikes).
  double rotation_error = -1.0;
  // The model's translation error on the frame before across the step, over the step's length
  // (Tracker::PredictMotion); negative when unknown (then only the rotation widens the band).
  double translation_error = -1.0;
};

// The tracker's constant-velocity motion (Tracker::PredictMotion); nullopt before the
// initialisation or after a frame that was not tracked.
std::optional<RigMotion> PredictedMotion(const Tracker& tracker);

// Where a corner of the frame before (`pixel`, input-image pixels of `camera`) lies in the same
// camera of the new frame at any depth from min_depth times the camera's step to infinity: a
// segment of the prepared image (its two ends project points of the corner's ray; where the
// lens bends the epipolar curve more than radius / 2 away from the segment, the near end is
// brought farther), `radius` wide. False when the ray cannot be imaged there.
bool EpipolarSearchRegion(const Camera& camera, const RigMotion& motion,
                          const Eigen::Vector2d& pixel, double min_depth, double radius,
                          double downscale, SearchRegion* region);

// The Harris options of the front end's detection: options.harris with its pool
// (continuation_pool). DetectFrameCorners for TrackBuilder::AddDetectedFrame takes these.
HarrisOptions FrontEndHarrisOptions(const TrackBuilderOptions& options);

struct TrackedFrame {
  std::vector<TrackObservation> observations;
  std::vector<Eigen::Vector2d> pixels;  // one per observation, input-image pixels
  int num_corners = 0;
  int num_matched = 0;        // corners continuing a track of the previous frame (or keyframe)
  int num_predicted = 0;      // searched around a reprojection
  int num_epipolar = 0;       // of num_matched, found along their epipolar segment
  bool relocalising = false;  // matched against the last keyframe
};

// The detection step of TrackBuilder::AddFrame for one frame: each camera's prepared image
// (PrepareImage) and its Harris corners (prepared pixels, strongest first; with a pool, the pool
// after them). It needs nothing
// of the tracker, so a caller may compute it ahead, on another thread (the SfM loop does it on
// its prefetch thread while the frame before is tracked).
struct FrameCorners {
  std::vector<cv::Mat> prepared;                      // one per camera
  std::vector<std::vector<Eigen::Vector2d>> corners;  // one list per camera
  // Per camera: where the pool begins in its list (its size without a pool).
  std::vector<size_t> pool_begin;
  // Per camera: the corners' ZNCC windows (ComputeCornerWindows), when DetectFrameCorners was
  // given the matching's half window; empty otherwise (the matching computes them).
  std::vector<CornerWindows> windows;
  double seconds = 0.0;  // wall time of the detection
};

// The cameras detected in parallel (TBB). zncc_half_window > 0: the corners' ZNCC windows too
// (TrackBuilderOptions::zncc.half_window), so that the matching does not compute them: done on
// the thread that detects ahead, they leave the tracking thread.
FrameCorners DetectFrameCorners(const std::vector<cv::Mat>& images, const HarrisOptions& options,
                                int zncc_half_window = 0);

// Input-image pixel where `track` should appear in camera `camera` of the new frame (its map
// point projected by the predicted pose); false when there is no prediction.
using PixelPredictor = std::function<bool(int camera, int track, Eigen::Vector2d* pixel)>;

// The PixelPredictor of the tracker's constant-velocity pose: a track's map point projected
// into the camera; empty (no prediction) before the initialisation or after a lost frame.
PixelPredictor ReprojectionPredictor(const Tracker& tracker, const Rig& rig);

class TrackBuilder {
 public:
  TrackBuilder(const Rig& rig, const TrackBuilderOptions& options);

  // images[c] is camera c's image of the frame (8-bit grey or colour, the size rig.json gives).
  // motion: the rig's predicted motion since the frame before, for the epipolar search
  // (TrackBuilderOptions::epipolar_min_depth).
  TrackedFrame AddFrame(const std::vector<cv::Mat>& images, const PixelPredictor& predict = {},
                        const std::optional<RigMotion>& motion = std::nullopt);
  // The same with the frame's corners detected beforehand (DetectFrameCorners with
  // FrontEndHarrisOptions(options)); the result is the same. Their detection time counts as
  // detect_ahead.
  TrackedFrame AddDetectedFrame(FrameCorners detected, const PixelPredictor& predict = {},
                                const std::optional<RigMotion>& motion = std::nullopt);
  // What the tracker made of the frame just added: a keyframe becomes the reference of a later
  // re-localisation; after a frame not tracked, the next frames are matched against it.
  void SetFrameResult(bool tracked, bool keyframe);
  // Matches the frame just added again, by descriptors, against reference frame `reference`:
  // 0 is the last tracked frame, then the last keyframes, newest first (a frame is listed
  // once): every corner a descriptor matches takes the reference corner's track; the others
  // start new tracks. False (and *frame untouched) when there is no such reference. The
  // map-point search then works on the new tracks. With has_map_point, the reference's corners
  // whose track has a map point are matched first, among themselves (sfm/descriptor_matching.h
  // ratio test over them alone), then every corner for the corners left.
  bool RematchByDescriptors(int reference, TrackedFrame* frame,
                            const std::function<bool(int track)>& has_map_point = {});
  int NumRematchReferences() const;
  // Matches the corners of every pair of cameras of the frame just added whose fields of view
  // overlap, by descriptors, keeping the matches that the rig's epipolar geometry accepts;
  // the second corner of a match takes the first's track. Returns the number of matches.
  int MatchOverlappingCameras(TrackedFrame* frame);
  // The search of map points among the corners of the frame just added, for
  // Tracker::AddFrame: a corner matched to a map point takes the point's track (also for the
  // frame-to-frame chaining that follows). Valid while the builder lives.
  MapPointSearchFn MapPointSearcher();
  std::vector<Reobservation> SearchMapPoints(const std::vector<MapPointProjection>& candidates,
                                             const std::vector<char>& eligible);

  struct Timings {
    double detect = 0.0;        // seconds (wall) since the start: preparation and Harris
    double detect_ahead = 0.0;  // the same for the frames detected beforehand (FrameCorners)
    double match = 0.0;         // ZNCC matching and the bearings
    double map_search = 0.0;    // map-point re-observation (reference patches and search)
  };
  Timings StageTimings() const { return timings_; }

 private:
  struct CameraState {
    cv::Mat prepared;
    std::vector<Eigen::Vector2d> corners;  // prepared pixels
    std::vector<int> tracks;
    Eigen::Vector2d flow = Eigen::Vector2d::Zero();  // predicted displacement per frame
    cv::Mat descriptors;  // of the corners, computed when first needed (Describe)
  };
  // AddFrame after the detection.
  TrackedFrame AddCorners(FrameCorners detected, const PixelPredictor& predict,
                          const std::optional<RigMotion>& motion);
  // The descriptors of a camera state's corners (computed once; again after corners were
  // added by the map-point search).
  const cv::Mat& Describe(CameraState* state) const;
  // The frame's observations (bearings of every corner) from cameras_, and which corner each
  // one is.
  void BuildObservations(TrackedFrame* frame);
  Rig rig_;
  TrackBuilderOptions options_;
  std::vector<CameraState> cameras_;
  // The last keyframes' states, newest first (at least the last one: the re-localisation's
  // reference; rematch_keyframes of them), and the last tracked frame's, with their frame
  // indices.
  std::vector<std::pair<int, std::vector<CameraState>>> keyframe_history_;
  std::pair<int, std::vector<CameraState>> last_tracked_{-1, {}};
  std::vector<CameraState>* RematchReference(int reference);
  // Whether the last tracked frame is a reference of its own (not the last keyframe).
  bool LastTrackedIsOwnReference() const;
  // Camera pairs (a < b) whose views overlap (MatchOverlappingCameras).
  std::vector<std::pair<int, int>> overlapping_pairs_;
  bool lost_ = false;
  int next_track_ = 0;
  int frame_index_ = -1;  // of the frame just added
  MapPointSearch map_search_;
  // The frame just added: camera and corner index of each observation.
  std::vector<std::pair<int, int>> observation_corners_;
  Timings timings_;
};

}  // namespace omni
