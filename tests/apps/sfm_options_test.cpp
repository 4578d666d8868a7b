// The SfM option group's profiles (apps/sfm_options.h): what each sets on the built-in six-camera
// rig and on one camera, that --corners and --min-tracked-share win over them, and the errors.

#include "apps/sfm_options.h"

#include <gtest/gtest.h>

#include <string>

#include "apps/default_rig.h"
#include "calib/error.h"

namespace omni {
namespace {

// ApplySfmOptions on `rig` with the given command-line values; *options holds the result.
void Apply(const Rig& rig, const std::string& profile, int corners, double min_tracked_share,
           SfmCommandLine* options) {
  options->profile = profile;
  options->corners = corners;
  options->min_tracked_share = min_tracked_share;
  options->downscale = 1.0;
  ApplySfmOptions(rig, "sfm", options);
}

TEST(SfmProfiles, EachSetsTheCornersAndTheKeyframeShareOfItsName) {
  const Rig rig = DefaultRig();
  ASSERT_EQ(rig.NumCameras(), 6u);
  struct Expected {
    std::string profile;
    int corners;
    double share;
  };
  for (const Expected& expected :
       {Expected{"realtime", 350, 0.3}, {"accurate", 700, 0.3}, {"offline", 700, 0.5}}) {
    SfmCommandLine options;
    Apply(rig, expected.profile, 0, 0.0, &options);
    EXPECT_EQ(options.sfm.tracks.harris.max_corners, expected.corners) << expected.profile;
    EXPECT_DOUBLE_EQ(options.sfm.tracker.keyframes.min_tracked_share, expected.share)
        << expected.profile;
  }
  // One camera: the cap of 2000 per image, whatever the profile.
  Rig one = rig;
  one.cameras.resize(1);
  SfmCommandLine single;
  Apply(one, "accurate", 0, 0.0, &single);
  EXPECT_EQ(single.sfm.tracks.harris.max_corners, 2000);
  EXPECT_EQ(CornersPerImage(1), 2000);
  EXPECT_EQ(CornersPerImage(2), 1050);
  EXPECT_EQ(CornersPerImage(2, 2), 2000);
  EXPECT_EQ(CornersPerImage(5, 2), 840);
}

TEST(SfmProfiles, GivenCornersAndKeyframeShareWinOverTheProfile) {
  const Rig rig = DefaultRig();
  SfmCommandLine options;
  Apply(rig, "offline", 500, 0.4, &options);
  EXPECT_EQ(options.sfm.tracks.harris.max_corners, 500);
  EXPECT_DOUBLE_EQ(options.sfm.tracker.keyframes.min_tracked_share, 0.4);
}

TEST(SfmProfiles, AnUnknownNameOrAShareOutOfRangeIsAnInputErrorNamingTheOption) {
  const Rig rig = DefaultRig();
  SfmCommandLine unknown;
  try {
    Apply(rig, "fast", 0, 0.0, &unknown);
    FAIL() << "no error for --profile fast";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what()).find("--profile"), std::string::npos) << error.what();
  }
  for (const double share : {-0.1, 1.0}) {
    SfmCommandLine options;
    try {
      Apply(rig, "realtime", 0, share, &options);
      FAIL() << "no error for --min-tracked-share " << share;
    } catch (const InputError& error) {
      EXPECT_NE(std::string(error.what()).find("--min-tracked-share"), std::string::npos)
          << error.what();
    }
  }
}

}  // namespace
}  // namespace omni
