// The SfM outputs shared by `omnisculpt sfm` and `reconstruct` (pipeline/point_colors.h,
// pipeline/sfm_stats.h): point colours from a hand-made drive whose images have known
// colours (linear in the pixel, so a bilinear sample is exact), and the statistics files.

#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "calib/drive.h"
#include "calib/error.h"
#include "calib/rig_io.h"
#include "pipeline/point_colors.h"
#include "pipeline/sfm_stats.h"
#include "tests/apps/run_omnisculpt.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

constexpr int kWidth = 40, kHeight = 30;

// Camera 0 writes colour images, camera 1 grey ones; the value at pixel (x, y) of frame f:
Eigen::Vector3d ColourAt(int frame, double x, double y) {
  return {3.0 * x + 20.0 * frame, 4.0 * y + 5.0, 200.0 - 2.0 * x - 3.0 * y};
}
double GreyAt(int frame, double x, double y) { return 2.0 * x + y + 40.0 + 10.0 * frame; }

Rig TwoCameraRig() {
  Rig rig;
  rig.name = "two";
  for (int c = 0; c < 2; ++c) {
    Camera camera;
    camera.name = "cam" + std::to_string(c);
    camera.width = kWidth;
    camera.height = kHeight;
    camera.params = {30.0, 30.0, 19.5, 14.5};
    camera.cam_from_rig.translation = Eigen::Vector3d(0.1 * c, 0.0, 0.0);
    rig.cameras.push_back(camera);
  }
  return rig;
}

// Frames 0, 1, 2; frame 1's camera-0 image is corrupt.
fs::path WriteDrive(const fs::path& root) {
  const Rig rig = TwoCameraRig();
  WriteRigJson(rig, root / "rig.json");
  for (int c = 0; c < 2; ++c) fs::create_directories(root / "images" / rig.cameras[c].name);
  for (int f = 0; f < 3; ++f) {
    cv::Mat bgr(kHeight, kWidth, CV_8UC3), grey(kHeight, kWidth, CV_8UC1);
    for (int y = 0; y < kHeight; ++y) {
      for (int x = 0; x < kWidth; ++x) {
        const Eigen::Vector3d rgb = ColourAt(f, x, y);
        bgr.at<cv::Vec3b>(y, x) =
            cv::Vec3b(static_cast<uint8_t>(rgb[2]), static_cast<uint8_t>(rgb[1]),
                      static_cast<uint8_t>(rgb[0]));
        grey.at<uint8_t>(y, x) = static_cast<uint8_t>(GreyAt(f, x, y));
      }
    }
    const std::string name = "00000" + std::to_string(f) + ".png";
    if (f == 1)
      std::ofstream(root / "images" / "cam0" / name, std::ios::binary) << "not a png";
    else
      EXPECT_TRUE(cv::imwrite((root / "images" / "cam0" / name).string(), bgr));
    EXPECT_TRUE(cv::imwrite((root / "images" / "cam1" / name).string(), grey));
  }
  return root;
}

FinalizedRay Ray(const Rig& rig, int keyframe, int camera, const Eigen::Vector2d& pixel) {
  FinalizedRay ray;
  ray.keyframe = keyframe;
  ray.camera = camera;
  EXPECT_TRUE(rig.cameras[camera].Unproject(pixel, &ray.bearing));
  return ray;
}

TEST(DriveLoadRgb, ColourImagesComeRedFirstAndGreyOnesAsThreeEqualChannels) {
  testing::TempDir dir;
  const Drive drive = Drive::Open(WriteDrive(dir.path()));
  const cv::Mat colour = drive.LoadRgb(2, 0);
  ASSERT_EQ(colour.type(), CV_8UC3);
  const cv::Vec3b v = colour.at<cv::Vec3b>(7, 11);  // row y = 7, column x = 11
  const Eigen::Vector3d expected = ColourAt(2, 11, 7);
  EXPECT_EQ(v[0], expected[0]);
  EXPECT_EQ(v[1], expected[1]);
  EXPECT_EQ(v[2], expected[2]);
  const cv::Mat grey = drive.LoadRgb(2, 1);
  ASSERT_EQ(grey.type(), CV_8UC3);
  const cv::Vec3b g = grey.at<cv::Vec3b>(7, 11);
  EXPECT_EQ(g[0], GreyAt(2, 11, 7));
  EXPECT_EQ(g[1], g[0]);
  EXPECT_EQ(g[2], g[0]);
  EXPECT_THROW(drive.LoadRgb(1, 0), InputError);

  // BGRA files: 8-bit RGB too; 16-bit files are refused (calib/drive.h), naming the file.
  cv::Mat deep(kHeight, kWidth, CV_16UC3, cv::Scalar(30 * 256, 20 * 256, 10 * 256));  // B G R
  cv::Mat alpha(kHeight, kWidth, CV_8UC4, cv::Scalar(3, 2, 1, 128));
  ASSERT_TRUE(cv::imwrite(drive.ImagePath(0, 0).string(), deep));
  ASSERT_TRUE(cv::imwrite(drive.ImagePath(0, 1).string(), alpha));
  try {
    drive.LoadRgb(0, 0);
    ADD_FAILURE() << "a 16-bit PNG was read";
  } catch (const InputError& error) {
    EXPECT_EQ(std::string(error.what()).rfind(drive.ImagePath(0, 0).string() + ": 16-bit PNG", 0),
              0u)
        << error.what();
  }
  EXPECT_EQ(drive.LoadRgb(0, 1).at<cv::Vec3b>(5, 5), cv::Vec3b(1, 2, 3));
}

TEST(SampleRgbBilinear, IsExactOnALinearImageAndRepeatsTheBorder) {
  cv::Mat rgb(kHeight, kWidth, CV_8UC3);
  for (int y = 0; y < kHeight; ++y)
    for (int x = 0; x < kWidth; ++x)
      rgb.at<cv::Vec3b>(y, x) = cv::Vec3b(3 * x, 4 * y + 5, 200 - 2 * x - 3 * y);
  const Eigen::Vector3d inside = SampleRgbBilinear(rgb, {12.25, 3.75});
  EXPECT_LT((inside - ColourAt(0, 12.25, 3.75)).norm(), 1e-9);
  // Half a pixel outside: the border pixel.
  const Eigen::Vector3d border = SampleRgbBilinear(rgb, {-0.4, kHeight - 0.6});
  EXPECT_LT((border - ColourAt(0, 0, kHeight - 1)).norm(), 1e-9);
}

TEST(ColorPoints, MeanOfTheImageColourAtEachObservationWithinRounding) {
  testing::TempDir dir;
  const Drive drive = Drive::Open(WriteDrive(dir.path()));
  const Rig& rig = drive.rig();
  // Keyframes 3, 4 and 5 at frames 0, 1 and 2.
  std::vector<FinalizedKeyframe> keyframes(3);
  for (int k = 0; k < 3; ++k) {
    keyframes[k].keyframe = 3 + k;
    keyframes[k].frame = k;
  }
  const Eigen::Vector2d a0(10.25, 7.5), a1(31.75, 20.25), b(5.5, 12.0), d(17.0, 3.25);
  FinalizedPoint mixed;  // camera 0 at frame 0 (colour) and camera 1 at frame 2 (grey)
  mixed.rays = {Ray(rig, 3, 0, a0), Ray(rig, 5, 1, a1)};
  FinalizedPoint grey;  // camera 1 only
  grey.rays = {Ray(rig, 4, 1, b)};
  FinalizedPoint colour;  // camera 0 at frames 0 and 2, and a ray of an unknown keyframe
  colour.rays = {Ray(rig, 3, 0, d), Ray(rig, 5, 0, a1), Ray(rig, 9, 0, b)};
  FinalizedPoint outside;  // its one observation behind the camera
  outside.rays = {Ray(rig, 3, 0, a0)};
  outside.rays[0].bearing = -outside.rays[0].bearing;
  FinalizedPoint unreadable;  // seen only in the corrupt image
  unreadable.rays = {Ray(rig, 4, 0, a0)};
  keyframes[0].points = {mixed, grey};
  keyframes[2].points = {colour, outside, unreadable};

  PointColorOptions options;
  options.fallback_grey = 77;
  PointColorStats stats;
  const std::vector<Rgb8> colors = ColorPoints(
      rig, keyframes, [&drive](int frame, int camera) { return drive.LoadRgb(frame, camera); },
      options, &stats);
  ASSERT_EQ(colors.size(), 5u);

  auto expect_within_rounding = [](const Rgb8& got, const Eigen::Vector3d& expected) {
    for (int k = 0; k < 3; ++k) EXPECT_LE(std::abs(got[k] - expected[k]), 0.5 + 1e-9) << k;
  };
  const double g = GreyAt(2, a1.x(), a1.y());
  expect_within_rounding(colors[0], 0.5 * (ColourAt(0, a0.x(), a0.y()) + Eigen::Vector3d(g, g, g)));
  const double gb = GreyAt(1, b.x(), b.y());
  expect_within_rounding(colors[1], Eigen::Vector3d(gb, gb, gb));
  EXPECT_EQ(colors[1][0], colors[1][1]);
  EXPECT_EQ(colors[1][0], colors[1][2]);
  expect_within_rounding(colors[2],
                         0.5 * (ColourAt(0, d.x(), d.y()) + ColourAt(2, a1.x(), a1.y())));
  EXPECT_EQ(colors[3], Rgb8(77, 77, 77));
  EXPECT_EQ(colors[4], Rgb8(77, 77, 77));
  EXPECT_EQ(stats.points_uncoloured, 2u);
  EXPECT_EQ(stats.samples, 5u);  // 2 + 1 + 2
  EXPECT_EQ(stats.images_unreadable, 1u);
  EXPECT_EQ(stats.images_read, 4u);  // (0, 0), (2, 1), (1, 1), (2, 0); (1, 0) is corrupt
}

TEST(SfmStats, CountsFramesAndWritesBothFiles) {
  SfmStats stats;
  FrameResult tracked;
  tracked.tracked = true;
  tracked.inliers = 100;
  FrameResult lost;
  stats.AddFrame(true, 300, tracked);
  tracked.inliers = 50;
  stats.AddFrame(true, 200, tracked);
  stats.AddFrame(true, 10, lost);
  stats.AddFrame(false, 0, lost);
  stats.keyframes = 2;
  stats.points = 123;
  stats.colmap.observations = 400;
  stats.colmap.mean_reprojection_error = 0.25;
  stats.front.detect = 1.0;
  stats.front.detect_ahead = 3.0;  // on another thread: not part of the total
  stats.back.map_search = 0.5;
  stats.total_seconds = 2.0;
  EXPECT_EQ(stats.frames, 4u);
  EXPECT_EQ(stats.frames_skipped, 1u);
  EXPECT_EQ(stats.frames_not_tracked, 1u);
  testing::TempDir dir;
  WriteSfmStats(stats, dir.path());
  const std::string summary = testing::ReadTextFile(dir.path() / "sfm_summary.csv");
  for (const char* row :
       {"name,value\n", "\nframes,4\n", "\nframes_skipped,1\n", "\nframes_not_tracked,1\n",
        "\nkeyframes,2\n", "\npoints,123\n", "\nmean_matched_per_frame,170\n",
        "\nmean_inliers_per_tracked_frame,75\n", "\nobservations,400\n",
        "\nmean_reprojection_error_px,0.25\n", "\nframes_per_second,2\n", "\nusable,1\n"})
    EXPECT_NE(summary.find(row), std::string::npos) << row << " in\n" << summary;
  const std::vector<std::string> stages =
      testing::SplitText(testing::ReadTextFile(dir.path() / "sfm_stages.csv"));
  ASSERT_EQ(stages.size(), 15u);
  EXPECT_EQ(stages[0], "stage,seconds,ms_per_frame");
  EXPECT_EQ(stages[2], "detect,1,250");
  EXPECT_EQ(stages[6], "map_search,0.5,125");
  EXPECT_EQ(stages[9], "final_bundle_adjustment,0,0");
  EXPECT_EQ(stages[10], "final_frame_refinement,0,0");
  EXPECT_EQ(stages[12], "other,0.5,125");  // total - detect - map_search
  EXPECT_EQ(stages[13], "total,2,500");
  EXPECT_EQ(stages.back(), "detect_ahead,3,750");
}

}  // namespace
}  // namespace omni
