// `omnisculpt synth` on the command line: one-line errors for a bad preset or output; the rig
// presets, the frame step and the exposure options.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>

#include "calib/rig_io.h"
#include "calib/tum.h"
#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

fs::path TempFolder(const std::string& name) {
  const fs::path path =
      fs::temp_directory_path() / ("omni_synth_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(path);
  return path;
}

using testing::CommandResult;
using testing::RunOmnisculpt;

int CountLines(const std::string& text) {
  return static_cast<int>(std::count(text.begin(), text.end(), '\n'));
}

TEST(SynthCommandTest, BadPresetAndUnwritableOutputAreOneLineErrors) {
  const fs::path folder = TempFolder("cli");
  fs::create_directories(folder);
  CommandResult result =
      RunOmnisculpt({"synth", "--preset", "nope", "--out", (folder / "d").string()}, folder);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(CountLines(result.err), 1) << result.err;
  EXPECT_NE(result.err.find("tiny, demo, paper"), std::string::npos) << result.err;
  EXPECT_FALSE(fs::exists(folder / "d"));

  std::ofstream(folder / "file") << "a file, not a folder";
  result = RunOmnisculpt(
      {"synth", "--preset", "tiny", "--frames", "2", "--out", (folder / "file" / "drive").string()},
      folder);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(CountLines(result.err), 1) << result.err;
  EXPECT_NE(result.err.find("--out"), std::string::npos) << result.err;

  result = RunOmnisculpt({"synth", "--list-presets"}, folder);
  EXPECT_EQ(result.exit_code, 0);
  fs::remove_all(folder);
}

TEST(SynthCommandTest, RigPresetsFrameStepAndExposureFromTheCommandLine) {
  const fs::path folder = TempFolder("rig_presets");
  fs::create_directories(folder);
  CommandResult result = RunOmnisculpt({"synth", "--list-rig-presets"}, folder);
  EXPECT_EQ(result.exit_code, 0) << result.err;
  for (const char* name : {"ladybug", "pinhole", "car", "fisheye5"}) {
    EXPECT_NE(result.out.find(name), std::string::npos) << result.out;
  }
  result = RunOmnisculpt({"synth", "--list-presets"}, folder);
  EXPECT_NE(result.out.find("fisheye5"), std::string::npos) << result.out;

  result =
      RunOmnisculpt({"synth", "--rig-preset", "drone", "--out", (folder / "d").string()}, folder);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(CountLines(result.err), 1) << result.err;
  EXPECT_NE(result.err.find("ladybug, pinhole, car, fisheye5"), std::string::npos) << result.err;
  result = RunOmnisculpt({"synth", "--preset", "tiny", "--frames", "3", "--frame-step", "0",
                          "--out", (folder / "d").string()},
                         folder);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_NE(result.err.find("--frame-step"), std::string::npos) << result.err;
  EXPECT_FALSE(fs::exists(folder / "d"));
  result = RunOmnisculpt({"synth", "--preset", "tiny", "--frames", "3", "--rig-height", "0.2",
                          "--out", (folder / "d").string()},
                         folder);
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_EQ(CountLines(result.err), 1) << result.err;
  EXPECT_NE(result.err.find("--rig-height"), std::string::npos) << result.err;
  EXPECT_FALSE(fs::exists(folder / "d"));

  const fs::path drive = folder / "fisheye";
  result = RunOmnisculpt({"--quiet", "synth", "--preset", "tiny", "--frames", "5", "--rig-preset",
                          "fisheye5", "--image-scale", "0.2", "--frame-step", "2",
                          "--exposure-spread", "0.3", "--rig-height", "2", "--out", drive.string()},
                         folder);
  ASSERT_EQ(result.exit_code, 0) << result.err;
  const Rig rig = ReadRigJson(drive / "rig.json");
  EXPECT_EQ(rig.name, "fisheye5");
  EXPECT_FALSE(rig.central);
  ASSERT_EQ(rig.NumCameras(), 5u);
  EXPECT_EQ(rig.cameras[0].width, 144);
  for (const char* frame : {"000000", "000002", "000004"}) {
    EXPECT_TRUE(fs::exists(drive / "images" / "cam4" / (std::string(frame) + ".png"))) << frame;
  }
  EXPECT_FALSE(fs::exists(drive / "images" / "cam4" / "000001.png"));
  EXPECT_EQ(testing::SplitText(testing::ReadTextFile(drive / "frames.csv")).size(), 1u + 3u * 5u);
  const std::vector<StampedPose> poses = ReadTum(drive / "gt" / "poses.tum");
  EXPECT_EQ(poses.size(), 3u);
  for (const StampedPose& pose : poses) {  // the rig 2 m above the road (z = 0), give or take
    EXPECT_NEAR(pose.world_from_rig.translation.z(), 2.0, 0.1);  // the suspension's bounce
  }
  EXPECT_NE(testing::ReadTextFile(drive / "gt" / "scene.json").find("exposure_gains"),
            std::string::npos);

  // calib show describes each rig file of data/rigs/.
  for (const char* file : {"ladybug-like.json", "pinhole.json", "car.json", "fisheye5.json"}) {
    result = RunOmnisculpt(
        {"calib", "show", (fs::path(OMNI_SOURCE_DIR) / "data" / "rigs" / file).string()}, folder);
    EXPECT_EQ(result.exit_code, 0) << file << ": " << result.err;
    EXPECT_NE(result.out.find("hfov"), std::string::npos) << file;
  }
  result = RunOmnisculpt({"calib", "show", "--rig-preset", "car"}, folder);
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("front_left"), std::string::npos) << result.out;
  fs::remove_all(folder);
}

}  // namespace
}  // namespace omni
