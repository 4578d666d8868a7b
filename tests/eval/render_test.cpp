#include "eval/render.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "eval/primitives.h"

namespace omni {
namespace {

TEST(Render, NormalColorsFollowFigureFour) {
  const RenderOptions options;
  const Eigen::Vector3d down = -Eigen::Vector3d::UnitZ();
  const Eigen::Vector3d ground = NormalColor(Eigen::Vector3d::UnitZ(), down, options);
  EXPECT_DOUBLE_EQ(ground.x(), 1.0);
  EXPECT_DOUBLE_EQ(ground.y(), 1.0);
  EXPECT_DOUBLE_EQ(ground.z(), 1.0);
  const Eigen::Vector3d view = -Eigen::Vector3d::UnitX();
  const Eigen::Vector3d east = NormalColor(Eigen::Vector3d::UnitX(), view, options);
  const Eigen::Vector3d north =
      NormalColor(Eigen::Vector3d::UnitY(), -Eigen::Vector3d::UnitY(), options);
  EXPECT_GT((east - north).norm(), 0.5);  // different directions, different hues
  EXPECT_NEAR(east.maxCoeff(), 1.0, 1e-12);
  EXPECT_NEAR(east.minCoeff(), 0.0, 1e-12);  // saturated: a wall is never grey
  // Seen obliquely the same wall is darker.
  const Eigen::Vector3d oblique =
      NormalColor(Eigen::Vector3d::UnitX(), Eigen::Vector3d(-1, 1, 0).normalized(), options);
  EXPECT_LT(oblique.maxCoeff(), 0.9);
  EXPECT_NEAR((oblique / oblique.maxCoeff() - east).norm(), 0.0, 1e-9);
}

TEST(Render, BirdsEyeShowsTheRoofWhiteAndTheSkyBlack) {
  const RayCaster caster(MakeBox({0, 0, 0}, {10, 5, 3}));
  RenderOptions straight_down;
  straight_down.bird_tilt_deg = 0.0;
  const cv::Mat image = RenderBirdsEye(caster, 200, 0, straight_down);
  ASSERT_EQ(image.cols, 200);
  EXPECT_EQ(image.rows, 104);  // 5 m + 2 × 2 % margin of the 10 m side, at 200 px per 10.4 m
  EXPECT_EQ(image.at<cv::Vec3b>(image.rows / 2, 100), cv::Vec3b(255, 255, 255));
  EXPECT_EQ(image.at<cv::Vec3b>(0, 0), cv::Vec3b(0, 0, 0));  // margin: no hit
}

TEST(Render, TiltedBirdsEyeShowsTheSouthWall) {
  const RayCaster caster(MakeBox({0, 0, 0}, {10, 5, 3}));
  const cv::Mat image = RenderBirdsEye(caster, 200);  // looking towards +y, 30° from vertical
  const Eigen::Vector3d view(0.0, 0.5, -std::sqrt(3.0) / 2.0);
  const Eigen::Vector3d wall = NormalColor(-Eigen::Vector3d::UnitY(), view, RenderOptions{});
  const Eigen::Vector3d roof = NormalColor(Eigen::Vector3d::UnitZ(), view, RenderOptions{});
  int wall_pixels = 0, roof_pixels = 0;
  for (int row = 0; row < image.rows; ++row) {
    const cv::Vec3b pixel = image.at<cv::Vec3b>(row, 100);
    const Eigen::Vector3d rgb(pixel[2] / 255.0, pixel[1] / 255.0, pixel[0] / 255.0);
    wall_pixels += (rgb - wall).norm() < 0.01;
    roof_pixels += (rgb - roof).norm() < 0.01;
  }
  // Projected heights: the wall 3 sin 30° = 1.5 m, the roof 5 cos 30° = 4.33 m.
  EXPECT_NEAR(static_cast<double>(wall_pixels) / roof_pixels, 1.5 / 4.33, 0.05);
}

TEST(Render, CameraViewColoursTheWallAhead) {
  const RayCaster room(FlipOrientation(MakeBox({-10, -10, -1}, {10, 10, 5})));
  Camera camera;
  camera.name = "front";
  camera.width = 40;
  camera.height = 30;
  camera.params = {20.0, 20.0, 19.5, 14.5};
  // Looking along +x of the world (camera z forward, y down).
  Eigen::Matrix3d world_from_cam;
  world_from_cam << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  const Rigid3d world_from_rig(Eigen::Quaterniond(world_from_cam), Eigen::Vector3d(0, 0, 1));
  const cv::Mat image = RenderCameraView(room, camera, world_from_rig);
  const cv::Vec3b center = image.at<cv::Vec3b>(15, 20);
  const Eigen::Vector3d expected =
      NormalColor(-Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitX(), RenderOptions{});
  EXPECT_NEAR(center[2], 255 * expected.x(), 1.0);
  EXPECT_NEAR(center[1], 255 * expected.y(), 1.0);
  EXPECT_NEAR(center[0], 255 * expected.z(), 1.0);
  // The bottom rows see the floor: grey levels (white shaded).
  const cv::Vec3b floor = image.at<cv::Vec3b>(29, 20);
  EXPECT_EQ(floor[0], floor[1]);
  EXPECT_EQ(floor[1], floor[2]);
  EXPECT_GT(floor[0], 0);

  const Camera small = ScaleCamera(camera, 20, 15);
  EXPECT_DOUBLE_EQ(small.params[2], 9.5);
  EXPECT_DOUBLE_EQ(small.params[0], 10.0);
}

TEST(Render, WritesPng) {
  const auto path = std::filesystem::temp_directory_path() / "omni_eval_render_test.png";
  const RayCaster caster(MakeBox({0, 0, 0}, {1, 1, 1}));
  const cv::Mat image = RenderBirdsEye(caster, 32);
  WritePng(image, path);
  const cv::Mat read = cv::imread(path.string());
  ASSERT_FALSE(read.empty());
  EXPECT_EQ(cv::norm(read, image, cv::NORM_INF), 0.0);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace omni
