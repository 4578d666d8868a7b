#include "calib/tum.h"

#include <gtest/gtest.h>

#include <random>

#include "calib/error.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

using omni::testing::TempDir;
using omni::testing::WriteBytes;

std::string ReadError(const std::filesystem::path& path) {
  try {
    ReadTum(path);
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no InputError for " << path;
  return "";
}

TEST(Tum, RoundTripTo1e9) {
  TempDir dir;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uniform(-100.0, 100.0);
  std::normal_distribution<double> normal;
  std::vector<StampedPose> poses;
  for (int i = 0; i < 50; ++i) {
    StampedPose pose;
    // Small and large (Unix-time) stamps with more digits than 1e-9, increasing.
    pose.timestamp = i >= 25 ? 1.6e9 + i / 7.0 : i / 3.0 + 1e-11;
    pose.world_from_rig.rotation =
        Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized();
    pose.world_from_rig.translation = Eigen::Vector3d(uniform(rng), uniform(rng), uniform(rng));
    poses.push_back(pose);
  }
  const auto path = dir / "poses.tum";
  WriteTum(poses, path);
  EXPECT_FALSE(std::filesystem::exists(dir / "poses.tum.tmp"));
  const std::vector<StampedPose> read = ReadTum(path);
  ASSERT_EQ(read.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_NEAR(read[i].timestamp, poses[i].timestamp, 1e-9) << i;
    EXPECT_EQ(read[i].world_from_rig.translation, poses[i].world_from_rig.translation) << i;
    EXPECT_EQ(read[i].world_from_rig.rotation.coeffs(), poses[i].world_from_rig.rotation.coeffs())
        << i;
  }
}

TEST(Tum, QuaternionOrderIsXyzwAndCommentsAreSkipped) {
  TempDir dir;
  const auto path = dir / "hand.tum";
  // 90 degrees about z: qx qy qz qw = 0 0 s s.
  WriteBytes(path,
             "# timestamp tx ty tz qx qy qz qw\n\n   \n"
             "12.5 1 2 3 0 0 0.7071067811865476 0.7071067811865476\r\n"
             "  # indented comment\n"
             "13\t4 5 6 0 0 0 1.0004\n");
  const std::vector<StampedPose> poses = ReadTum(path);
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_EQ(poses[0].timestamp, 12.5);
  const Eigen::Vector3d moved = poses[0].world_from_rig * Eigen::Vector3d(1, 0, 0);
  EXPECT_NEAR((moved - Eigen::Vector3d(1, 3, 3)).norm(), 0.0, 1e-12);
  // A quaternion within 1e-3 of unit norm is normalised.
  EXPECT_EQ(poses[1].world_from_rig.rotation.w(), 1.0);
  EXPECT_EQ(poses[1].world_from_rig.translation, Eigen::Vector3d(4, 5, 6));
}

TEST(Tum, WrongFieldCountNamesTheLine) {
  TempDir dir;
  const auto path = dir / "short.tum";
  WriteBytes(path, "# header\n0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n");
  EXPECT_EQ(ReadError(path),
            path.string() + ": line 3: expected 8 values (timestamp tx ty tz qx qy qz qw), got 7");
}

TEST(Tum, NonNumberNamesTheLine) {
  TempDir dir;
  const auto path = dir / "text.tum";
  WriteBytes(path, "0 0 0 0 0 0 0 1\n1 0 abc 0 0 0 0 1\n");
  EXPECT_EQ(ReadError(path),
            path.string() + ": line 2: value 3: expected a decimal number, got \"abc\"");
  WriteBytes(path, "0 0 0 0 0 0 0 1x\n");
  EXPECT_EQ(ReadError(path),
            path.string() + ": line 1: value 8: expected a decimal number, got \"1x\"");
}

TEST(Tum, HexadecimalInfinityAndNanAreNotNumbers) {
  TempDir dir;
  const auto path = dir / "odd.tum";
  // strtod reads all of these; a TUM file has decimal numbers only.
  for (const char* token_text : {"0x10", "inf", "-INF", "nan", "1e", ".", "+-1", "1.2.3"}) {
    const std::string token = token_text;
    WriteBytes(path, "0 0 0 0 0 0 0 1\n" + token + " 0 0 0 0 0 0 1\n");
    EXPECT_EQ(ReadError(path),
              path.string() + ": line 2: value 1: expected a decimal number, got \"" + token + "\"")
        << token;
  }
  WriteBytes(path, "0 1e309 0 0 0 0 0 1\n");
  EXPECT_EQ(ReadError(path), path.string() +
                                 ": line 1: value 2: number out of range (too large for a "
                                 "double): \"1e309\"");
  // Plain decimal forms that are numbers.
  WriteBytes(path, "-1.5e-3 +2 .5 3. 0 0 0 1\n1E2 0 0 0 0 0 0 1\n");
  const std::vector<StampedPose> poses = ReadTum(path);
  ASSERT_EQ(poses.size(), 2u);
  EXPECT_EQ(poses[0].timestamp, -1.5e-3);
  EXPECT_EQ(poses[0].world_from_rig.translation, Eigen::Vector3d(2.0, 0.5, 3.0));
  EXPECT_EQ(poses[1].timestamp, 100.0);
}

TEST(Tum, TimestampsMustIncreaseStrictly) {
  TempDir dir;
  const auto path = dir / "order.tum";
  WriteBytes(path, "1 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n2 0 0 0 0 0 0 1\n");
  EXPECT_EQ(ReadError(path),
            path.string() + ": line 3: timestamps must increase: 2 is not after the line before");
  WriteBytes(path, "# t\n5 0 0 0 0 0 0 1\n\n4.5 0 0 0 0 0 0 1\n");
  EXPECT_EQ(ReadError(path),
            path.string() + ": line 4: timestamps must increase: 4.5 is not after the line before");
}

TEST(Tum, NonUnitQuaternionNamesTheLine) {
  TempDir dir;
  const auto path = dir / "bad_q.tum";
  WriteBytes(path, "0 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 2\n");
  const std::string message = ReadError(path);
  EXPECT_EQ(message.rfind(path.string() + ": line 2: expected a unit quaternion", 0), 0u)
      << message;
}

TEST(Tum, MissingFile) {
  TempDir dir;
  const auto path = dir / "none.tum";
  EXPECT_EQ(ReadError(path), path.string() + ": cannot open");
  EXPECT_EQ(ReadError(dir.path()), dir.path().string() + ": is a folder, not a file");
}

}  // namespace
}  // namespace omni
