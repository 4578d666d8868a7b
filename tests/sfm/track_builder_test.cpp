#include "sfm/track_builder.h"

#include <gtest/gtest.h>

#include <map>
#include <set>

#include "sfm/synthetic.h"

namespace omni {
namespace {

TEST(TrackBuilder, ChainsTracksAlongAShiftedSequence) {
  // Two cameras; each sees the texture moving by its own constant shift per frame.
  Rig rig = MakeSyntheticRingRig(2, false, 0.0);
  for (Camera& camera : rig.cameras) {
    camera.width = 400;
    camera.height = 300;
    camera.params = {200.0, 200.0, 199.5, 149.5};
  }
  const Eigen::Vector2d shifts[2] = {Eigen::Vector2d(6.0, 1.5), Eigen::Vector2d(-4.5, -3.0)};
  TrackBuilderOptions options;
  options.search_radius = 12.0;  // the first frame has no flow yet: the shift must fit
  TrackBuilder builder(rig, options);

  std::vector<std::map<int, Eigen::Vector2d>> first_pixel(2);
  std::vector<TrackedFrame> frames;
  for (int f = 0; f < 5; ++f) {
    std::vector<cv::Mat> images;
    for (int c = 0; c < 2; ++c)
      images.push_back(MakeSyntheticTexture(400, 300, f * shifts[c], 250, 30 + c));
    frames.push_back(builder.AddFrame(images));
  }
  for (int f = 0; f < 5; ++f) {
    const TrackedFrame& frame = frames[f];
    ASSERT_EQ(frame.observations.size(), frame.pixels.size());
    ASSERT_GT(frame.observations.size(), 300u);
    std::set<int> ids;
    for (size_t i = 0; i < frame.observations.size(); ++i) {
      const TrackObservation& observation = frame.observations[i];
      EXPECT_TRUE(ids.insert(observation.track).second) << "track twice in frame " << f;
      // The bearing is the camera model's bearing of the pixel.
      Eigen::Vector3d expected;
      ASSERT_TRUE(rig.cameras[observation.camera].Unproject(frame.pixels[i], &expected));
      EXPECT_LT((expected - observation.bearing).norm(), 1e-9);
      if (f == 0) first_pixel[observation.camera][observation.track] = frame.pixels[i];
    }
    if (f > 0) {
      EXPECT_GT(frame.num_matched, 0.6 * frames[f - 1].num_corners);
    }
  }
  // Tracks that live from frame 0 to frame 4 moved by 4 shifts of their camera.
  int long_tracks = 0, right = 0;
  const TrackedFrame& last = frames.back();
  for (size_t i = 0; i < last.observations.size(); ++i) {
    const TrackObservation& observation = last.observations[i];
    const auto it = first_pixel[observation.camera].find(observation.track);
    if (it == first_pixel[observation.camera].end()) continue;
    ++long_tracks;
    const Eigen::Vector2d moved = last.pixels[i] - it->second;
    right += (moved - 4.0 * shifts[observation.camera]).norm() < 0.5 ? 1 : 0;
  }
  EXPECT_GT(long_tracks, 200);
  EXPECT_GE(right, 0.95 * long_tracks);
}

}  // namespace
}  // namespace omni
