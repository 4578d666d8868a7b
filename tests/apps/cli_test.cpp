// Runs the built `omnisculpt` executable and checks its exit codes and output.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "calib/rig_io.h"
#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

using testing::CommandResult;
using RunResult = CommandResult;

std::vector<std::string> Lines(const std::string& text) { return testing::SplitText(text); }

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           (std::string("omni_cli_test_") + info->name() + "_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  RunResult Run(const std::vector<std::string>& arguments) {
    return testing::RunOmnisculpt(arguments, dir_);
  }

  fs::path Write(const std::string& name, const std::string& text) {
    const fs::path path = dir_ / name;
    std::ofstream(path) << text;
    return path;
  }

  fs::path dir_;
};

const char* const kLadybugConf =
    "Resolution 1024 768\n"
    "BeginCamera\n"
    "focalLength 0.4 0.53\n"
    "CamToLadybugEulerZYX 0.1 -1.5 0.2 0.04 0 0\n"
    "Center 0 0 0 0.5 0.5\n"
    "EndCamera\n"
    "BeginCamera\n"
    "focalLength 0.4 0.53\n"
    "CamToLadybugEulerZYX 0.1 -1.5 1.45 0.012 0.038 0\n"
    "Center 0 0 0 0.5 0.5\n"
    "EndCamera\n";

TEST_F(CliTest, HelpListsCalib) {
  const RunResult result = Run({"--help"});
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("calib"), std::string::npos) << result.out;
}

TEST_F(CliTest, UnknownOptionIsOneErrorLineAndExitTwo) {
  for (const std::vector<std::string>& args :
       {std::vector<std::string>{"--no-such-option"},
        std::vector<std::string>{"calib", "show", "--no-such-option"}}) {
    const RunResult result = Run(args);
    EXPECT_EQ(result.exit_code, 2);
    const std::vector<std::string> lines = Lines(result.err);
    ASSERT_EQ(lines.size(), 1u) << result.err;
    EXPECT_NE(lines[0].find("--no-such-option"), std::string::npos) << lines[0];
  }
}

TEST_F(CliTest, BadOptionsAreOneErrorLineAndExitTwo) {
  // The options are checked before the drive is read: the drive need not exist.
  const RunResult result = Run({"surface", "--from-gt", (dir_ / "no_drive").string(), "--out",
                                (dir_ / "out").string(), "--init-keyframes", "0"});
  EXPECT_EQ(result.exit_code, 2);
  const std::vector<std::string> lines = Lines(result.err);
  ASSERT_EQ(lines.size(), 1u) << result.err;
  EXPECT_EQ(lines[0].rfind("omnisculpt: error: invalid options: SculptorOptions.init_keyframes", 0),
            0u)
      << lines[0];
  EXPECT_FALSE(fs::exists(dir_ / "out"));
}

TEST_F(CliTest, GlobalFlagsAreAcceptedAfterTheSubcommand) {
  const RunResult plain = Run({"calib", "show", "--default"});
  for (const char* flag : {"--quiet", "-q", "--verbose"}) {
    const RunResult result = Run({"calib", "show", "--default", flag});
    EXPECT_EQ(result.exit_code, 0) << flag << ": " << result.err;
    EXPECT_EQ(result.out, plain.out) << flag;
  }
}

TEST_F(CliTest, CalibNeedsASubcommand) {
  const RunResult result = Run({"calib"});
  EXPECT_EQ(result.exit_code, 2);
  EXPECT_TRUE(result.out.empty()) << result.out;
  EXPECT_EQ(Lines(result.err).size(), 1u) << result.err;
}

TEST_F(CliTest, ShowDescribesTheLadybugLikeRig) {
  const RunResult result =
      Run({"calib", "show", std::string(OMNI_SOURCE_DIR) + "/data/rigs/ladybug-like.json"});
  EXPECT_EQ(result.exit_code, 0) << result.err;
  EXPECT_NE(result.out.find("6 cameras"), std::string::npos) << result.out;
  for (int k = 0; k < 6; ++k) {
    EXPECT_NE(result.out.find("cam" + std::to_string(k)), std::string::npos) << result.out;
  }
  // The built-in rig is the same file.
  const RunResult builtin = Run({"calib", "show", "--default"});
  EXPECT_EQ(builtin.exit_code, 0) << builtin.err;
  EXPECT_EQ(builtin.out, result.out);
}

TEST_F(CliTest, ShowOfAMissingFileIsOneErrorLine) {
  const fs::path missing = dir_ / "no_such_rig.json";
  const RunResult result = Run({"calib", "show", missing.string()});
  EXPECT_EQ(result.exit_code, 2);
  const std::vector<std::string> lines = Lines(result.err);
  ASSERT_EQ(lines.size(), 1u) << result.err;
  EXPECT_NE(lines[0].find(missing.string()), std::string::npos) << lines[0];
  EXPECT_TRUE(result.out.empty()) << result.out;
}

TEST_F(CliTest, ImportOfAMalformedFileIsOneErrorLine) {
  const fs::path conf = Write("bad.conf", "Resolution 1024 768\nBeginCamera\nfocalLength x y\n");
  const fs::path out = dir_ / "rig.json";
  const RunResult result =
      Run({"calib", "import", "--format", "ladybug", conf.string(), "--out", out.string()});
  EXPECT_EQ(result.exit_code, 2);
  const std::vector<std::string> lines = Lines(result.err);
  ASSERT_EQ(lines.size(), 1u) << result.err;
  EXPECT_NE(lines[0].find("bad.conf"), std::string::npos) << lines[0];
  EXPECT_NE(lines[0].find("line 3"), std::string::npos) << lines[0];
  EXPECT_FALSE(fs::exists(out));

  const fs::path yaml = Write("bad.yaml", "cam0:\n  camera_model: omni\n");
  const RunResult kalibr =
      Run({"calib", "import", "--format", "kalibr", yaml.string(), "--out", out.string()});
  EXPECT_EQ(kalibr.exit_code, 2);
  ASSERT_EQ(Lines(kalibr.err).size(), 1u) << kalibr.err;
  EXPECT_NE(kalibr.err.find("cam0.camera_model"), std::string::npos) << kalibr.err;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(CliTest, ImportDoesNotOverwriteWithoutForce) {
  const fs::path conf = Write("ladybug.conf", kLadybugConf);
  const fs::path out = Write("rig.json", "do not overwrite\n");
  const RunResult refused =
      Run({"calib", "import", "--format", "ladybug", conf.string(), "--out", out.string()});
  EXPECT_EQ(refused.exit_code, 2);
  EXPECT_EQ(Lines(refused.err).size(), 1u) << refused.err;
  EXPECT_NE(refused.err.find("--force"), std::string::npos) << refused.err;
  EXPECT_EQ(testing::ReadTextFile(out), "do not overwrite\n");

  const RunResult forced = Run({"calib", "import", "--format", "ladybug", conf.string(), "--out",
                                out.string(), "--force", "--upright"});
  EXPECT_EQ(forced.exit_code, 0) << forced.err;
  EXPECT_NE(forced.out.find("pinhole"), std::string::npos) << forced.out;
  const Rig rig = ReadRigJson(out);
  ASSERT_EQ(rig.NumCameras(), 2u);
  EXPECT_EQ(rig.cameras[0].width, 768);  // upright: width and height swapped
  EXPECT_EQ(rig.cameras[0].height, 1024);
}

TEST_F(CliTest, ImportWritesARigThatShowReads) {
  const fs::path conf = Write("ladybug.conf", kLadybugConf);
  const fs::path out = dir_ / "imported.json";
  const RunResult imported =
      Run({"calib", "import", "--format", "ladybug", conf.string(), "--out", out.string()});
  ASSERT_EQ(imported.exit_code, 0) << imported.err;
  const RunResult shown = Run({"calib", "show", out.string()});
  EXPECT_EQ(shown.exit_code, 0) << shown.err;
  EXPECT_NE(shown.out.find("2 cameras"), std::string::npos) << shown.out;
  EXPECT_NE(shown.out.find("1024x768"), std::string::npos) << shown.out;
  EXPECT_NE(shown.out.find("central: yes"), std::string::npos) << shown.out;
}

}  // namespace
}  // namespace omni
