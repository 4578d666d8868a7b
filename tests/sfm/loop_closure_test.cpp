// Place recognition of loop closure on the short synthetic drive (fixture
// short_drive): the end of the drive, which passes the start again, is recognised among frames
// far back in time, also when the ring of cameras is rotated.

#include "sfm/loop_closure.h"

#include <gtest/gtest.h>

#include <limits>

#include "calib/drive.h"
#include "calib/tum.h"
#include "sfm/synthetic.h"
#include "tests/calib/options_error_check.h"

namespace omni {
namespace {

std::vector<cv::Mat> LoadFrame(const Drive& drive, size_t frame) {
  std::vector<cv::Mat> images;
  for (size_t c = 0; c < drive.rig().NumCameras(); ++c) images.push_back(drive.LoadGray(frame, c));
  return images;
}

// The plausibility of a verified loop: the move of the revisit against the path driven.
TEST(LoopDriftShare, IsTheMoveOfTheRevisitOverThePathBetweenTheKeyframes) {
  // Keyframes 1 m apart along x, then back along y: a path of 6 m from keyframe 1 to 7.
  std::vector<Rigid3d> world_from_rig;
  for (int i = 0; i <= 4; ++i)
    world_from_rig.emplace_back(Eigen::Quaterniond::Identity(), Eigen::Vector3d(i, 0, 0));
  for (int i = 1; i <= 3; ++i)
    world_from_rig.emplace_back(Eigen::Quaterniond::Identity(), Eigen::Vector3d(4, i, 0));
  const Sim3d shift(1.0, Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.3, -0.4, 0.0));
  EXPECT_NEAR(LoopDriftShare(world_from_rig, 1, 7, shift), 0.5 / 6.0, 1e-12);
  // A scaled rotation about the revisit's own centre does not move it.
  const Eigen::Vector3d centre = world_from_rig[7].translation;
  const Eigen::Quaterniond turn(Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()));
  const Sim3d about_centre(1.2, turn, centre - 1.2 * (turn * centre));
  EXPECT_NEAR(LoopDriftShare(world_from_rig, 1, 7, about_centre), 0.0, 1e-12);
  // No path: infinitely implausible.
  EXPECT_EQ(LoopDriftShare(world_from_rig, 7, 7, shift), std::numeric_limits<double>::infinity());
}

TEST(LoopDetectorShortDrive, FindsTheRingOfTheDefaultRig) {
  const Drive drive = Drive::Open(OMNI_SHORT_DRIVE_DIR);
  LoopDetector detector(drive.rig(), LoopDetectionOptions());
  // The Ladybug-like rig: five side cameras in the ring, the up camera out of it.
  EXPECT_EQ(detector.ring().size(), drive.rig().NumCameras() - 1);
}

TEST(LoopDetectorShortDrive, RecognisesTheStartAtTheEndEvenWithTheRingRotated) {
  const Drive drive = Drive::Open(OMNI_SHORT_DRIVE_DIR);
  const std::vector<StampedPose> truth = ReadTum(drive.GroundTruthPosesPath());
  ASSERT_EQ(truth.size(), drive.NumFrames());
  LoopDetectionOptions options;
  options.min_keyframe_gap = 30;
  LoopDetector detector(drive.rig(), options);
  const int step = 3;  // every third frame is a "keyframe"
  const int last = static_cast<int>(drive.NumFrames()) - 1;
  std::vector<int> frame_of;
  for (int f = 0; f < last - 40; f += step) {
    detector.Add(detector.Describe(LoadFrame(drive, f)));
    frame_of.push_back(f);
  }
  // The last frame is ~12 m past the start: its place was seen in the first frames.
  const std::vector<cv::Mat> images = LoadFrame(drive, last);
  const LoopCandidate found = detector.Query(detector.Describe(images), detector.size() + 30);
  ASSERT_GE(found.keyframe, 0) << found.score;
  EXPECT_EQ(found.shift, 0);
  const Eigen::Vector3d here = truth[last].world_from_rig.translation;
  double nearest = 1e9;
  for (int f : frame_of)
    nearest = std::min(nearest, (truth[f].world_from_rig.translation - here).norm());
  const double distance =
      (truth[frame_of[found.keyframe]].world_from_rig.translation - here).norm();
  EXPECT_LT(nearest, 3.0);   // the drive does revisit
  EXPECT_LT(distance, 4.0);  // and the detector found the revisit
  // A frame from the middle of the drive, far from every earlier "keyframe", is no loop.
  const int middle = 60;
  const LoopCandidate none = detector.Query(detector.Describe(LoadFrame(drive, middle)), 0);
  EXPECT_EQ(none.keyframe, -1);

  // The same frame with the ring turned by one camera: the same place, found with shift 1.
  const std::vector<int>& ring = detector.ring();
  std::vector<cv::Mat> rotated = images;
  for (size_t i = 0; i < ring.size(); ++i) rotated[ring[i]] = images[ring[(i + 1) % ring.size()]];
  const LoopCandidate turned = detector.Query(detector.Describe(rotated), detector.size() + 30);
  EXPECT_EQ(turned.keyframe, found.keyframe);
  EXPECT_EQ(turned.shift, 1);
  EXPECT_NEAR(turned.score, found.score, 1e-6);
}

TEST(LoopCloser, BadOptionsThrowNamingTheField) {
  const Rig rig = MakeSyntheticRingRig(4, false, 0.1);
  LoopClosureOptions options;
  options.detection.min_score = 2.0;
  EXPECT_THROW((LoopCloser{rig, options}), OptionsError);
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { LoopCloser closer(rig, options); },
                                          "LoopClosureOptions.detection.min_score: expected"));
  options = LoopClosureOptions();
  options.central_relative_pose.ransac.max_iterations = 0;
  EXPECT_TRUE(testing::ThrowsOptionsError(
      [&] { LoopCloser closer(rig, options); },
      "LoopClosureOptions.central_relative_pose.ransac.max_iterations"));
  for (const double bad : {0.0, -1e-4, 1.0, std::nan("")}) {
    options = LoopClosureOptions();
    options.global_bundle_adjustment_function_tolerance = bad;
    EXPECT_TRUE(testing::ThrowsOptionsError(
        [&] { LoopCloser closer(rig, options); },
        "LoopClosureOptions.global_bundle_adjustment_function_tolerance"))
        << bad;
  }
  LoopDetectionOptions detection;
  detection.min_keyframe_gap = 0;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { LoopDetector detector(rig, detection); },
                                          "LoopDetectionOptions.min_keyframe_gap"));
}

}  // namespace
}  // namespace omni
