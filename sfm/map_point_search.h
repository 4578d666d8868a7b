#pragma once
// Map-point re-observation ("track the local map": Mouragnon et al. 2007, ORB-SLAM):
// once a frame's pose is resected, the live map points of the recent keyframes that the frame
// does not observe in a camera are projected into that camera (every camera of the rig, not
// only the one that saw the point last: a point leaving camera A for camera B, or seen by two
// neighbouring cameras at once, stays one track), and the frame's Harris corners whose track
// has no map point are searched within a small radius for a ZNCC match against the point's
// reference patch (the window of its most recent observation). A match makes the corner an
// observation of the map point: the corner's track becomes the point's track, so the frame to
// frame chaining of sfm/track_builder.h carries the point on from there. Harris corners repeat
// poorly from frame to frame (about half of a frame's corners continue a track), so the search
// can also look at every pixel of the radius (search_every_pixel): the subpixel ZNCC maximum
// is the observation, snapped to a corner of no map point when one is that close, and a new
// observation otherwise. Not the default: on the demo drive its observations are too loose for
// the resection's 0.002 rad threshold and the tracking was lost on the demo drive.
//
// The split of the work: the tracker (sfm/tracker.h, it has the map and the pose) lists the
// candidates as MapPointProjections and applies the Reobservations; the front end
// (sfm/track_builder.h, it has the images and the corners) answers through a MapPointSearchFn,
// with the matching of MapPointSearch below.

#include <Eigen/Core>
#include <functional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/rig.h"

namespace omni {

struct MapPointSearchOptions {
  bool enabled = true;
  // Radius around the projection of the point by the resected pose (input-image pixels): the
  // error of the pose and of the point, a few tenths of a degree.
  double search_radius = 4.0;
  // ZNCC windows of (2 half_window + 1)² pixels of the prepared image (as ZnccOptions).
  int half_window = 5;
  double min_zncc = 0.8;
  // Distinctiveness against the second-best corner in the radius, with d = sqrt(1 − zncc):
  // d_best < max_distance_ratio · d_second (as ZnccOptions).
  double max_distance_ratio = 0.8;
  // Search every pixel of the radius (true) or only the frame's Harris corners (false).
  bool search_every_pixel = false;
  // A maximum this close to a corner is that corner (input-image pixels); if the corner
  // belongs to another map point, the match is dropped. Two new observations in one camera are
  // at least this far apart.
  double snap_radius = 1.5;
  // A track's reference patch is forgotten this many frames after its last observation.
  int max_reference_age = 60;

  std::string Check() const;
};

// A map point predicted in one camera of the current frame, by the frame's pose.
struct MapPointProjection {
  int track = -1;                                      // the map point's track
  int camera = 0;                                      // index into Rig::cameras
  Eigen::Vector3d bearing = Eigen::Vector3d::UnitZ();  // towards the point, camera frame
  double radius_scale = 1.0;  // times MapPointSearchOptions::search_radius (a coarse pose: > 1)
};

// Observation `observation` of the current frame (index into the observations the tracker
// was given) is the map point of track `track`, seen along `bearing` (camera frame; the
// search may refine the corner's); or, with observation = -1, a new observation of that point
// in camera `camera` along `bearing`.
struct Reobservation {
  int observation = -1;
  int track = -1;
  int camera = -1;
  Eigen::Vector3d bearing = Eigen::Vector3d::UnitZ();
};

// The front end's answer to the tracker. eligible[i] tells whether observation i of the frame
// may be re-assigned (its track has no map point). Each candidate (track, camera) is a camera
// where the frame does not observe that track yet; the answer gives each observation and each
// (track, camera) at most once, so that no point gets two observations in one camera of one
// frame.
using MapPointSearchFn = std::function<std::vector<Reobservation>(
    const std::vector<MapPointProjection>& candidates, const std::vector<char>& eligible)>;

// The image side: the reference patches of the tracks, and the search.
class MapPointSearch {
 public:
  // downscale: the prepared images' shrink factor (HarrisOptions::downscale).
  MapPointSearch(const Rig& rig, const MapPointSearchOptions& options, double downscale);

  // Keeps the window around each corner of a camera's prepared image of frame `frame`
  // (prepared pixels) as the reference patch of its track (the most recent observation wins).
  void Remember(int frame, const cv::Mat& prepared, const std::vector<Eigen::Vector2d>& corners,
                const std::vector<int>& tracks);
  // Forgets the references older than max_reference_age frames before `frame`.
  void Forget(int frame);
  size_t NumReferences() const { return slot_frame_.size() - free_slots_.size(); }

  struct Match {
    int candidate = -1;  // index into the candidates
    int corner = -1;     // index into the camera's corners; -1: a new observation at `pixel`
    // Prepared image: the ZNCC maximum (subpixel) when every pixel is searched, else the
    // corner's.
    Eigen::Vector2d pixel = Eigen::Vector2d::Zero();
    double zncc = 0.0;
  };
  // prepared[c], corners[c] (prepared pixels) and eligible[c] (one flag per corner: may become
  // a map point's) of each camera of the current frame. Each corner and each candidate appears
  // in at most one match; so does each (track, camera) when the candidates are distinct.
  std::vector<Match> Search(const std::vector<MapPointProjection>& candidates,
                            const std::vector<cv::Mat>& prepared,
                            const std::vector<std::vector<Eigen::Vector2d>>& corners,
                            const std::vector<std::vector<char>>& eligible) const;

 private:
  // The 8-bit reference patch of slot `slot` (the corner at its centre pixel).
  cv::Mat Patch(int slot) const;

  Rig rig_;
  MapPointSearchOptions options_;
  double downscale_ = 1.0;
  // The references in slots of one pool (no allocation per track): each slot's patch, the frame
  // it was taken in (−1: a free slot) and its track; the free slots; the slot of each track, by
  // track id (the front end numbers tracks densely), −1 for none.
  int patch_side_ = 0;
  std::vector<uint8_t> patches_;
  std::vector<int> slot_frame_, slot_track_, free_slots_, slot_of_track_;
};

}  // namespace omni
