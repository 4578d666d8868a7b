#include "calib/drive.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <opencv2/imgcodecs.hpp>

#include "calib/error.h"
#include "calib/rig_io.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

using omni::testing::TempDir;
using omni::testing::WriteBytes;

constexpr int kWidth = 32;
constexpr int kHeight = 24;

Rig TwoCameraRig() {
  Rig rig;
  rig.name = "two";
  for (const char* name : {"left", "right"}) {
    Camera camera;
    camera.name = name;
    camera.width = kWidth;
    camera.height = kHeight;
    camera.model = CameraModel::kPinhole;
    camera.params = {20.0, 20.0, 15.5, 11.5};
    rig.cameras.push_back(camera);
  }
  return rig;
}

// A grey image whose pixels encode the frame, so that the loaded image can be recognised.
cv::Mat FrameImage(int value, int width = kWidth, int height = kHeight) {
  return cv::Mat(height, width, CV_8UC1, cv::Scalar(value));
}

void WriteImage(const std::filesystem::path& path, const cv::Mat& image) {
  ASSERT_TRUE(cv::imwrite(path.string(), image)) << path;
}

// drive/rig.json and drive/images/<camera>/<frame><extension> for the given files.
std::filesystem::path MakeDrive(const TempDir& dir, const std::vector<std::string>& left_files,
                                const std::vector<std::string>& right_files) {
  const std::filesystem::path drive = dir / "drive";
  std::filesystem::create_directories(drive / "images" / "left");
  std::filesystem::create_directories(drive / "images" / "right");
  WriteRigJson(TwoCameraRig(), drive / "rig.json");
  int value = 1;
  for (const std::string& file : left_files) {
    WriteImage(drive / "images" / "left" / file, FrameImage(value++));
  }
  for (const std::string& file : right_files) {
    WriteImage(drive / "images" / "right" / file, FrameImage(value++));
  }
  return drive;
}

std::string OpenError(const std::filesystem::path& folder, const DriveOptions& options = {}) {
  try {
    Drive::Open(folder, options);
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no InputError for " << folder;
  return "";
}

std::string LoadError(const Drive& drive, size_t frame, size_t camera) {
  try {
    drive.LoadGray(frame, camera);
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no InputError loading frame " << frame << " camera " << camera;
  return "";
}

TEST(NaturalLess, DigitRunsCompareByValue) {
  EXPECT_TRUE(NaturalLess("2", "10"));
  EXPECT_FALSE(NaturalLess("10", "2"));
  EXPECT_TRUE(NaturalLess("10", "a2"));
  EXPECT_TRUE(NaturalLess("a2", "a10"));
  EXPECT_TRUE(NaturalLess("a", "a1"));
  EXPECT_TRUE(NaturalLess("frame_9_b", "frame_10_a"));
  EXPECT_FALSE(NaturalLess("x7", "x7"));
  // Equal values with leading zeros still have a strict order.
  EXPECT_NE(NaturalLess("01", "1"), NaturalLess("1", "01"));
  std::vector<std::string> names = {"img10", "img2", "img1", "img02x", "img100", "img9"};
  std::sort(names.begin(), names.end(), NaturalLess);
  const std::vector<std::string> expected = {"img1", "img2", "img02x", "img9", "img10", "img100"};
  EXPECT_EQ(names, expected);
}

TEST(Drive, ListsCompleteFramesInNaturalOrder) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {"f10.png", "f2.png", "f1.png", "f9.jpg", "f3.PNG"},
                                {"f9.png", "f1.png", "f10.jpg", "f2.png", "f3.png"});
  WriteBytes(folder / "images" / "left" / "notes.txt", "not an image");
  const Drive drive = Drive::Open(folder);
  const std::vector<std::string> expected = {"f1", "f2", "f3", "f9", "f10"};
  EXPECT_EQ(drive.frame_names(), expected);
  EXPECT_EQ(drive.NumFrames(), 5u);
  EXPECT_TRUE(drive.incomplete_frames().empty());
  EXPECT_EQ(drive.rig().NumCameras(), 2u);
  EXPECT_EQ(drive.ImagePath(2, 0), folder / "images" / "left" / "f3.PNG");
  EXPECT_EQ(drive.ImagePath(4, 1), folder / "images" / "right" / "f10.jpg");
  EXPECT_EQ(drive.GroundTruthPosesPath(), folder / "gt" / "poses.tum");
  // Images come back as 8-bit grey of the written content (left f2 was written with value 2).
  const cv::Mat image = drive.LoadGray(1, 0);
  EXPECT_EQ(image.type(), CV_8UC1);
  EXPECT_EQ(image.cols, kWidth);
  EXPECT_EQ(image.rows, kHeight);
  EXPECT_EQ(image.at<uint8_t>(5, 5), 2);
}

TEST(Drive, IncompleteFramesAreReportedNotUsed) {
  TempDir dir;
  const auto folder =
      MakeDrive(dir, {"1.png", "2.png", "3.png", "5.png"}, {"1.png", "3.png", "4.png", "5.png"});
  const Drive drive = Drive::Open(folder);
  const std::vector<std::string> expected = {"1", "3", "5"};
  EXPECT_EQ(drive.frame_names(), expected);
  ASSERT_EQ(drive.incomplete_frames().size(), 2u);
  EXPECT_EQ(drive.incomplete_frames()[0].frame_name, "2");
  EXPECT_EQ(drive.incomplete_frames()[0].missing_cameras, std::vector<std::string>{"right"});
  EXPECT_EQ(drive.incomplete_frames()[1].frame_name, "4");
  EXPECT_EQ(drive.incomplete_frames()[1].missing_cameras, std::vector<std::string>{"left"});
}

TEST(Drive, MissingCameraFolder) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {"1.png"}, {"1.png"});
  std::filesystem::remove_all(folder / "images" / "right");
  EXPECT_EQ(OpenError(folder), (folder / "images" / "right").string() +
                                   ": missing camera folder (rig.json has a camera \"right\")");
}

TEST(Drive, EmptyCameraFolder) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {"1.png"}, {});
  WriteBytes(folder / "images" / "right" / "readme.txt", "no images here");
  const std::string message = OpenError(folder);
  EXPECT_EQ(message.rfind((folder / "images" / "right").string() + ": no images", 0), 0u)
      << message;
}

TEST(Drive, TwoFilesForOneFrameInACamera) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {"1.png", "1.jpg"}, {"1.png"});
  EXPECT_EQ(OpenError(folder), (folder / "images" / "left").string() +
                                   ": two images for frame \"1\": 1.jpg and 1.png");
}

TEST(Drive, MissingPieces) {
  TempDir dir;
  EXPECT_EQ(OpenError(dir / "nothing"), (dir / "nothing").string() + ": no such folder");
  const auto folder = MakeDrive(dir, {"1.png"}, {"1.png"});
  std::filesystem::rename(folder / "rig.json", folder / "rig.bak");
  EXPECT_EQ(OpenError(folder), (folder / "rig.json").string() + ": cannot open");
  std::filesystem::rename(folder / "rig.bak", folder / "rig.json");
  std::filesystem::rename(folder / "images", folder / "pictures");
  const std::string message = OpenError(folder);
  EXPECT_EQ(message.rfind((folder / "images").string() + ": missing folder", 0), 0u) << message;
}

TEST(Drive, MinFrames) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {"1.png", "2.png", "3.png", "4.png", "5.png"},
                                {"1.png", "2.png", "3.png", "4.png"});
  DriveOptions options;
  options.min_frames = 5;
  EXPECT_EQ(OpenError(folder, options),
            folder.string() + ": drive too short: 4 complete frames, at least 5 needed");
  options.min_frames = 4;
  EXPECT_EQ(Drive::Open(folder, options).NumFrames(), 4u);
}

TEST(Drive, OptionsCheck) {
  DriveOptions options;
  EXPECT_EQ(options.Check(), "");
  options.image_extensions = {"png"};
  EXPECT_NE(options.Check(), "");
  options = DriveOptions();
  options.min_frames = 0;
  EXPECT_NE(options.Check(), "");
}

TEST(Drive, WrongImageSize) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {"1.png"}, {});
  WriteImage(folder / "images" / "right" / "1.png", FrameImage(9, 40, 24));
  const Drive drive = Drive::Open(folder);
  EXPECT_EQ(LoadError(drive, 0, 1), (folder / "images" / "right" / "1.png").string() +
                                        ": image is 40x24, rig.json gives camera right 32x24");
  EXPECT_NO_THROW(drive.LoadGray(0, 0));
}

TEST(Drive, CorruptOrVanishedImage) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {"1.png", "2.png"}, {"1.png", "2.png"});
  const auto corrupt = folder / "images" / "left" / "2.png";
  WriteBytes(corrupt, "\x89PNG\r\n\x1a\n garbage garbage garbage garbage");
  const Drive drive = Drive::Open(folder);
  EXPECT_EQ(LoadError(drive, 1, 0),
            corrupt.string() + ": truncated PNG (chunk bage runs past the end of the file)");
  const auto vanished = folder / "images" / "right" / "1.png";
  std::filesystem::remove(vanished);
  EXPECT_EQ(LoadError(drive, 0, 1), vanished.string() + ": cannot open");
}

// Damaged files are found before the decoders see them (they would print their own line on
// stderr naming no file), each problem named.
TEST(Drive, DamagedImageFilesAreNamedBeforeDecoding) {
  std::vector<uint8_t> png;
  cv::imencode(".png", FrameImage(3, kWidth, kHeight), png);
  const std::string whole(png.begin(), png.end());
  EXPECT_EQ(ImageFileProblem(whole), "");
  EXPECT_EQ(ImageFileProblem(""), "empty file (0 bytes)");
  EXPECT_EQ(ImageFileProblem(whole.substr(0, whole.size() / 2)).rfind("truncated PNG", 0), 0u);
  EXPECT_EQ(ImageFileProblem(whole.substr(0, whole.size() - 1)),
            "truncated PNG (the file ends before its IEND chunk)");
  std::string flipped = whole;
  flipped[flipped.size() / 2] ^= 0x10;
  EXPECT_EQ(ImageFileProblem(flipped), "corrupt PNG (chunk IDAT fails its CRC check)");
  EXPECT_EQ(ImageFileProblem("P5\n32 24\n255\n" + std::string(32 * 24, '\0')),
            "not a PNG or JPEG image (its first bytes are neither signature)");

  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", FrameImage(5, kWidth, kHeight), jpeg);
  const std::string jpeg_whole(jpeg.begin(), jpeg.end());
  EXPECT_EQ(ImageFileProblem(jpeg_whole), "");
  EXPECT_EQ(ImageFileProblem(jpeg_whole.substr(0, jpeg_whole.size() - 2)),
            "truncated JPEG (the file ends before its end-of-image marker)");
  EXPECT_EQ(ImageFileProblem(jpeg_whole.substr(0, jpeg_whole.size() / 2)),
            "truncated JPEG (the file ends before its end-of-image marker)");
}

// A 16-bit PNG is refused (dividing by 256 would hide a wrong export); colour is converted.
TEST(Drive, ColourLoadsAsGreyAndSixteenBitIsRefused) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {}, {});
  // Pure green in BGR: grey = 0.587 * 255 = 149.7.
  WriteImage(folder / "images" / "left" / "1.png",
             cv::Mat(kHeight, kWidth, CV_8UC3, cv::Scalar(0, 255, 0)));
  const auto deep = folder / "images" / "right" / "1.png";
  WriteImage(deep, cv::Mat(kHeight, kWidth, CV_16UC1, cv::Scalar(100 * 256 + 37)));
  const Drive drive = Drive::Open(folder);
  const cv::Mat colour = drive.LoadGray(0, 0);
  EXPECT_EQ(colour.type(), CV_8UC1);
  EXPECT_EQ(colour.size(), cv::Size(kWidth, kHeight));
  EXPECT_NEAR(colour.at<uint8_t>(3, 4), 150, 1);
  const std::string message = LoadError(drive, 0, 1);
  EXPECT_EQ(message.rfind(deep.string() + ": 16-bit PNG: expected 8 bits per channel", 0), 0u)
      << message;
}

// LoadRgb: a grey PNG (the fast decoder's case) gives OpenCV's pixels in all three channels; a
// colour PNG keeps its colours, in RGB order.
TEST(Drive, RgbOfGreyAndColourPngsIsOpenCvsDecode) {
  TempDir dir;
  const auto folder = MakeDrive(dir, {}, {});
  cv::Mat grey(kHeight, kWidth, CV_8UC1);
  cv::randu(grey, 0, 256);
  WriteImage(folder / "images" / "left" / "1.png", grey);
  WriteImage(folder / "images" / "right" / "1.png",
             cv::Mat(kHeight, kWidth, CV_8UC3, cv::Scalar(10, 120, 230)));  // BGR
  const Drive drive = Drive::Open(folder);
  const cv::Mat rgb = drive.LoadRgb(0, 0);
  ASSERT_EQ(rgb.type(), CV_8UC3);
  ASSERT_EQ(rgb.size(), grey.size());
  const cv::Mat decoded =
      cv::imread((folder / "images" / "left" / "1.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(decoded.type(), CV_8UC1);
  int differing = 0;
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x) {
      const cv::Vec3b& v = rgb.at<cv::Vec3b>(y, x);
      const uint8_t expected = decoded.at<uint8_t>(y, x);
      differing += (v[0] != expected || v[1] != expected || v[2] != expected) ? 1 : 0;
    }
  EXPECT_EQ(differing, 0);
  const cv::Vec3b colour = drive.LoadRgb(0, 1).at<cv::Vec3b>(5, 7);
  EXPECT_EQ(colour, cv::Vec3b(230, 120, 10));
}

// frames.csv: a frame's timestamp is the mean of its cameras' rows; a drive without it has
// none; a bad number, a frame without a row or timestamps that do not increase are bad input
// naming the file (and the line when there is one).
TEST(DriveTest, FrameTimestampsFromFramesCsv) {
  TempDir dir;
  const std::filesystem::path drive = MakeDrive(dir, {"0.png", "1.png"}, {"0.png", "1.png"});
  EXPECT_FALSE(Drive::Open(drive).HasTimestamps());
  WriteBytes(drive / "frames.csv",
             "frame,camera,timestamp_s,source\n0,left,100.5,a.png\n0,right,100.7,b.png\n"
             "1,left,1646304541.927203655,c.png\n1,right,1646304541.927203655,d.png\n");
  const Drive opened = Drive::Open(drive);
  ASSERT_TRUE(opened.HasTimestamps());
  EXPECT_NEAR(opened.FrameTimestamp(0), 100.6, 1e-9);
  EXPECT_NEAR(opened.FrameTimestamp(1), 1646304541.927203655, 1e-6);

  auto refused = [&](const std::string& csv, const std::string& expected) {
    WriteBytes(drive / "frames.csv", csv);
    try {
      Drive::Open(drive);
      ADD_FAILURE() << "accepted: " << csv;
    } catch (const InputError& error) {
      const std::string what = error.what();
      EXPECT_NE(what.find("frames.csv"), std::string::npos) << what;
      EXPECT_NE(what.find(expected), std::string::npos) << what;
    }
  };
  refused("frame,camera,timestamp_s\n0,left,1\n0,right,0x10\n1,left,2\n", "line 3");
  refused("frame,camera,timestamp_s\n0,left,1\n1,left,nan\n", "line 3");
  refused("frame,camera,timestamp_s\n0,left,1\n", "no row for frame \"1\"");
  refused("frame,camera,timestamp_s\n0,left,2\n1,left,1\n", "must increase");
  refused("frame,camera\n0,left\n", "timestamp_s");
  refused("frame,camera,timestamp_s\n0,left,1\n0,left,1\n1,left,2\n",
          "line 3: a second row for frame \"0\" camera \"left\"");
  refused("frame,camera,timestamp_s\n0,left,1e309\n1,left,2\n",
          "line 2: timestamp_s: number out of range (too large for a double)");
  refused("frame,camera,timestamp_s\n0,left,1.7e308\n0,right,1.7e308\n1,left,2\n",
          "frame \"0\": timestamp_s out of range");
  refused("frame,camera,timestamp_s\n0,left\n", "line 2: expected 3 fields, got 2");
}

}  // namespace
}  // namespace omni
