#pragma once
// The image front end of the tracker: Harris corners in every camera of every frame, matched by
// ZNCC against the previous frame of the same camera inside a search region predicted by a
// constant image-motion model (the median displacement of the camera's last matches), chained
// into tracks; matched and new corners become bearings through the camera model. Works on any
// rig (1 to N cameras). Not yet: matching across overlapping neighbour cameras, and search
// regions predicted by reprojection once the pose is known (issue 8).

#include <Eigen/Core>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/rig.h"
#include "sfm/harris.h"
#include "sfm/tracker.h"
#include "sfm/zncc_matching.h"

namespace omni {

struct TrackBuilderOptions {
  HarrisOptions harris;
  ZnccOptions zncc;
  // Radius of the search region around the predicted position (pixels of the prepared image).
  double search_radius = 30.0;

  std::string Check() const;
};

struct TrackedFrame {
  std::vector<TrackObservation> observations;
  std::vector<Eigen::Vector2d> pixels;  // one per observation, input-image pixels
  int num_corners = 0;
  int num_matched = 0;  // corners continuing a track of the previous frame
};

class TrackBuilder {
 public:
  TrackBuilder(const Rig& rig, const TrackBuilderOptions& options);

  // images[c] is camera c's image of the frame (8-bit grey or colour, the size rig.json gives).
  TrackedFrame AddFrame(const std::vector<cv::Mat>& images);

 private:
  struct CameraState {
    cv::Mat prepared;
    std::vector<Eigen::Vector2d> corners;  // prepared pixels
    std::vector<int> tracks;
    Eigen::Vector2d flow = Eigen::Vector2d::Zero();  // predicted displacement per frame
  };
  Rig rig_;
  TrackBuilderOptions options_;
  std::vector<CameraState> cameras_;
  int next_track_ = 0;
};

}  // namespace omni
