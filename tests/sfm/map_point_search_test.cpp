#include "sfm/map_point_search.h"

#include <gtest/gtest.h>

#include <map>
#include <set>

#include "sfm/harris.h"
#include "sfm/synthetic.h"
#include "sfm/track_builder.h"
#include "tests/calib/options_error_check.h"
#include "tests/sfm/test_util.h"

namespace omni {
namespace {

using test::TwoCameraRig;

// The texture camera 0 saw in frame 0 appears in camera 1 of frame 1 moved by `shift` (a
// point that left camera A for camera B); camera 0 of frame 1 sees an unrelated texture. The
// candidates are the frame-0 corners predicted in camera 1 with an error of up to 1.5 pixels
// (and, as a trap, in camera 0 where they are not).
class MapPointSearchTest : public ::testing::TestWithParam<bool> {};

TEST_P(MapPointSearchTest, FindsPointsThatMovedToAnotherCamera) {
  const Rig rig = TwoCameraRig();
  const Eigen::Vector2d shift(7.3, -2.6);
  HarrisOptions harris;
  const cv::Mat frame0 = MakeSyntheticTexture(400, 300, {0, 0}, 250, 30);
  std::vector<Eigen::Vector2d> corners0;
  for (const Corner& corner : DetectHarrisCorners(frame0, harris)) corners0.push_back(corner.pixel);
  ASSERT_GT(corners0.size(), 200u);
  std::vector<int> tracks0;
  for (size_t i = 0; i < corners0.size(); ++i) tracks0.push_back(1000 + static_cast<int>(i));

  MapPointSearchOptions options;
  options.search_every_pixel = GetParam();
  MapPointSearch search(rig, options, 1.0);
  search.Remember(0, frame0, corners0, tracks0);
  EXPECT_EQ(search.NumReferences(), corners0.size());

  const std::vector<cv::Mat> frame1 = {MakeSyntheticTexture(400, 300, {0, 0}, 250, 31),
                                       MakeSyntheticTexture(400, 300, shift, 250, 30)};
  std::vector<std::vector<Eigen::Vector2d>> corners1(2);
  for (int c = 0; c < 2; ++c)
    for (const Corner& corner : DetectHarrisCorners(frame1[c], harris))
      corners1[c].push_back(corner.pixel);
  // Every corner of camera 1 may become a map point's; in camera 0, none but the first half.
  std::vector<std::vector<char>> eligible = {std::vector<char>(corners1[0].size(), 1),
                                             std::vector<char>(corners1[1].size(), 1)};

  std::vector<MapPointProjection> candidates;
  std::vector<Eigen::Vector2d> truth;  // per candidate, where the point is in camera 1
  for (size_t i = 0; i < corners0.size(); ++i) {
    const Eigen::Vector2d moved = corners0[i] + shift;
    if (moved.x() < 12 || moved.y() < 12 || moved.x() > 388 || moved.y() > 288) continue;
    const Eigen::Vector2d error(1.5 * std::cos(0.7 * i), 1.5 * std::sin(0.7 * i));
    for (int c = 0; c < 2; ++c) {
      MapPointProjection candidate;
      candidate.track = tracks0[i];
      candidate.camera = c;
      ASSERT_TRUE(rig.cameras[c].Unproject(moved + error, &candidate.bearing));
      candidates.push_back(candidate);
      truth.push_back(moved);
    }
  }
  const std::vector<MapPointSearch::Match> matches =
      search.Search(candidates, frame1, corners1, eligible);
  int right = 0, in_camera0 = 0, in_camera1 = 0;
  std::set<std::pair<int, int>> used_corners;
  std::set<int> used_candidates;
  for (const MapPointSearch::Match& match : matches) {
    const MapPointProjection& candidate = candidates[match.candidate];
    EXPECT_TRUE(used_candidates.insert(match.candidate).second);
    if (match.corner >= 0) {
      EXPECT_TRUE(used_corners.insert({candidate.camera, match.corner}).second);
      if (!GetParam()) {
        EXPECT_EQ(match.pixel, corners1[candidate.camera][match.corner]);
      }
    }
    EXPECT_GE(match.zncc, options.min_zncc);
    if (candidate.camera == 0) {
      ++in_camera0;
      continue;
    }
    ++in_camera1;
    // Every pixel: the subpixel ZNCC maximum; corners only: a Harris corner, which sits up to
    // a pixel off the true place.
    right += (match.pixel - truth[match.candidate]).norm() < (GetParam() ? 0.5 : 1.0) ? 1 : 0;
  }
  const int num_in_camera1 = static_cast<int>(candidates.size() / 2);
  // Most points are found in camera 1, at their true place; few in camera 0 (ZNCC >= 0.8 on
  // another texture of the same kind: the tracker's angle check and the bundle adjustment's
  // robust loss deal with those).
  EXPECT_GT(in_camera1, (GetParam() ? 0.8 : 0.5) * num_in_camera1);
  EXPECT_GE(right, 0.97 * in_camera1);
  EXPECT_LT(in_camera0, 0.1 * num_in_camera1);

  // Corners of other map points are never taken: with none eligible, no corner match, and in
  // every-pixel mode no new observation on top of them.
  for (auto& flags : eligible) std::fill(flags.begin(), flags.end(), 0);
  for (const MapPointSearch::Match& match : search.Search(candidates, frame1, corners1, eligible)) {
    EXPECT_LT(match.corner, 0);
    for (const Eigen::Vector2d& corner : corners1[candidates[match.candidate].camera])
      EXPECT_GE((corner - match.pixel).norm(), options.snap_radius - 1e-9);
  }
  // References are forgotten after max_reference_age frames.
  search.Forget(options.max_reference_age + 1);
  EXPECT_EQ(search.NumReferences(), 0u);
}

INSTANTIATE_TEST_SUITE_P(EveryPixelOrCorners, MapPointSearchTest, ::testing::Values(true, false));

// Through the front end: a point tracked in camera 0 moves to camera 1; the search re-labels
// (or adds) its observation in camera 1 with the point's track, and the next frame continues
// that track in camera 1 by the frame-to-frame chaining. One track, two cameras; never a
// track twice in one camera of a frame.
TEST(MapPointSearchFrontEnd, PointLeavingCameraAForCameraBKeepsOneTrack) {
  const Rig rig = TwoCameraRig();
  const Eigen::Vector2d shift(5.2, 1.7);
  TrackBuilderOptions options;
  options.search_radius = 12.0;
  TrackBuilder builder(rig, options);
  const TrackedFrame frame0 = builder.AddFrame({MakeSyntheticTexture(400, 300, {0, 0}, 250, 30),
                                                MakeSyntheticTexture(400, 300, {0, 0}, 250, 31)});
  std::map<int, Eigen::Vector2d> camera0_pixel;  // frame 0, camera 0: track -> pixel
  for (size_t i = 0; i < frame0.observations.size(); ++i)
    if (frame0.observations[i].camera == 0)
      camera0_pixel[frame0.observations[i].track] = frame0.pixels[i];
  ASSERT_GT(camera0_pixel.size(), 150u);

  // Frame 1: camera 1 sees camera 0's old texture moved by `shift`.
  const TrackedFrame frame1 = builder.AddFrame({MakeSyntheticTexture(400, 300, {0, 0}, 250, 32),
                                                MakeSyntheticTexture(400, 300, shift, 250, 30)});
  for (const TrackObservation& o : frame1.observations)
    if (o.camera == 1) {
      ASSERT_EQ(camera0_pixel.count(o.track), 0u) << "no chaining across cameras by itself";
    }
  std::vector<MapPointProjection> candidates;
  for (const auto& [track, pixel] : camera0_pixel) {
    MapPointProjection candidate;
    candidate.track = track;
    candidate.camera = 1;
    if (!rig.cameras[1].Unproject(pixel + shift + Eigen::Vector2d(0.8, -0.6), &candidate.bearing))
      continue;
    candidates.push_back(candidate);
  }
  const std::vector<Reobservation> found =
      builder.SearchMapPoints(candidates, std::vector<char>(frame1.observations.size(), 1));
  ASSERT_GT(found.size(), 0.6 * candidates.size());
  std::set<int> found_tracks;
  int placed = 0;
  for (const Reobservation& r : found) {
    EXPECT_TRUE(found_tracks.insert(r.track).second);
    EXPECT_TRUE(camera0_pixel.count(r.track));
    EXPECT_EQ(r.camera, 1);
    if (r.observation >= 0) {
      EXPECT_EQ(frame1.observations[r.observation].camera, 1);
    }
    // The bearing is where the frame-0 window went.
    Eigen::Vector2d pixel;
    ASSERT_TRUE(rig.cameras[1].Project(r.bearing, &pixel));
    // Within a pixel: by default the observation is a Harris corner of frame 1, which sits up
    // to a pixel off the place of the frame-0 corner's window.
    placed += (pixel - (camera0_pixel[r.track] + shift)).norm() < 1.0 ? 1 : 0;
  }
  EXPECT_GE(placed, 0.9 * found.size());

  // Frame 2: the texture moves on in camera 1; its corners continue the frame-0 tracks.
  const TrackedFrame frame2 =
      builder.AddFrame({MakeSyntheticTexture(400, 300, {0, 0}, 250, 33),
                        MakeSyntheticTexture(400, 300, 2.0 * shift, 250, 30)});
  int continued = 0, right = 0;
  std::set<std::pair<int, int>> track_camera;
  for (size_t i = 0; i < frame2.observations.size(); ++i) {
    const TrackObservation& o = frame2.observations[i];
    EXPECT_TRUE(track_camera.insert({o.track, o.camera}).second) << "track twice in a camera";
    const auto it = camera0_pixel.find(o.track);
    if (it == camera0_pixel.end()) continue;
    EXPECT_EQ(o.camera, 1);
    ++continued;
    right += (frame2.pixels[i] - (it->second + 2.0 * shift)).norm() < 1.0 ? 1 : 0;
  }
  EXPECT_GT(continued, 0.5 * found.size());
  EXPECT_GE(right, 0.9 * continued);
}

TEST(MapPointSearchOptions, ChecksItsFields) {
  EXPECT_EQ(MapPointSearchOptions().Check(), "");
  MapPointSearchOptions options;
  options.search_radius = 0.0;
  EXPECT_NE(options.Check(), "");
  options = MapPointSearchOptions();
  options.min_zncc = 1.0;
  EXPECT_NE(options.Check(), "");
  options = MapPointSearchOptions();
  options.max_reference_age = 0;
  EXPECT_NE(options.Check(), "");
  TrackBuilderOptions builder;
  builder.map_search.half_window = 0;
  EXPECT_EQ(builder.Check().rfind("map_search.", 0), 0u);
}

TEST(MapPointSearch, BadOptionsThrowNamingTheField) {
  const Rig rig = TwoCameraRig();
  MapPointSearchOptions options;
  options.half_window = 0;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { MapPointSearch search(rig, options, 1.0); },
                                          "MapPointSearchOptions.half_window"));
  EXPECT_TRUE(
      testing::ThrowsOptionsError([&] { MapPointSearch search(rig, MapPointSearchOptions(), 0.0); },
                                  "MapPointSearch.downscale"));
}

}  // namespace
}  // namespace omni
