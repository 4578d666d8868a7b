#include "calib/camera.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

namespace omni {
namespace {

constexpr double kPi = 3.14159265358979323846;

Camera MakePinhole() {
  Camera camera;
  camera.name = "pinhole";
  camera.width = 512;
  camera.height = 384;
  camera.model = CameraModel::kPinhole;
  camera.params = {300.0, 310.0, 255.5, 191.5};
  return camera;
}

// A wide 640x480 camera with strong barrel distortion. Its radial map r (1 + k1 r² + k2 r⁴ +
// k3 r⁶) increases up to r ≈ 1.5 (distorted radius ≈ 0.945); the image corners reach a
// distorted radius of 400 / 440 ≈ 0.91, so the model is one-to-one over the whole image.
Camera MakeOpenCV() {
  Camera camera;
  camera.name = "opencv";
  camera.width = 640;
  camera.height = 480;
  camera.model = CameraModel::kOpenCV;
  camera.params = {440.0, 445.0, 319.5, 239.5, -0.35, 0.15, 1e-3, -5e-4, -0.03};
  return camera;
}

// Pincushion distortion with stronger tangential terms: the distorted point lies outside the
// undistorted one, so the undistortion iterates inwards.
Camera MakeOpenCVPincushion() {
  Camera camera;
  camera.name = "opencv-pincushion";
  camera.width = 640;
  camera.height = 480;
  camera.model = CameraModel::kOpenCV;
  camera.params = {500.0, 500.0, 330.0, 235.0, 0.12, 0.05, -2e-3, 1e-3, 0.01};
  return camera;
}

// A 190° lens (95° at about 400 px from the centre) on an 800x600 sensor whose corners image
// directions up to about 120° off-axis; θd(θ) increases up to about 132°.
Camera MakeFisheye() {
  Camera camera;
  camera.name = "fisheye";
  camera.width = 800;
  camera.height = 600;
  camera.model = CameraModel::kFisheye;
  camera.params = {234.0, 236.0, 399.5, 299.5, 0.03, -0.01, 0.002, -0.0003};
  return camera;
}

std::vector<Camera> AllCameras() {
  return {MakePinhole(), MakeOpenCV(), MakeOpenCVPincushion(), MakeFisheye()};
}

// Every pixel centre of the image plus its outer border (the -0.5 edges and corners).
std::vector<Eigen::Vector2d> DenseGrid(const Camera& camera) {
  std::vector<Eigen::Vector2d> pixels;
  const double right = camera.width - 0.5 - 1e-9, bottom = camera.height - 0.5 - 1e-9;
  for (int v = -1; v <= camera.height; ++v) {
    for (int u = -1; u <= camera.width; ++u) {
      pixels.emplace_back(u < 0 ? -0.5 : (u == camera.width ? right : u),
                          v < 0 ? -0.5 : (v == camera.height ? bottom : v));
    }
  }
  return pixels;
}

TEST(CameraModel, NamesAndParamCounts) {
  for (CameraModel model : {CameraModel::kPinhole, CameraModel::kOpenCV, CameraModel::kFisheye}) {
    EXPECT_EQ(CameraModelFromName(CameraModelName(model)), model);
    // The description lists one name per parameter.
    const std::string description(CameraParamsDescription(model));
    const int words = 1 + static_cast<int>(std::count(description.begin(), description.end(), ' '));
    EXPECT_EQ(words, NumCameraParams(model));
  }
  EXPECT_EQ(NumCameraParams(CameraModel::kPinhole), 4);
  EXPECT_EQ(NumCameraParams(CameraModel::kOpenCV), 9);
  EXPECT_EQ(NumCameraParams(CameraModel::kFisheye), 8);
  EXPECT_EQ(CameraModelName(CameraModel::kOpenCV), "opencv");
  EXPECT_FALSE(CameraModelFromName("kannala").has_value());
  EXPECT_FALSE(CameraModelFromName("").has_value());
}

TEST(Camera, PixelBearingPixelRoundTripOverWholeImage) {
  for (const Camera& camera : AllCameras()) {
    ASSERT_EQ(camera.Check(), "");
    int failures = 0;
    double max_error = 0.0, max_norm_error = 0.0;
    for (const Eigen::Vector2d& pixel : DenseGrid(camera)) {
      Eigen::Vector3d bearing;
      if (!camera.Unproject(pixel, &bearing)) {
        ++failures;
        continue;
      }
      max_norm_error = std::max(max_norm_error, std::abs(bearing.norm() - 1.0));
      Eigen::Vector2d reprojected;
      ASSERT_TRUE(camera.Project(bearing, &reprojected)) << camera.name;
      max_error = std::max(max_error, (reprojected - pixel).norm());
    }
    EXPECT_EQ(failures, 0) << camera.name;
    EXPECT_LT(max_error, 1e-6) << camera.name;
    EXPECT_LT(max_norm_error, 1e-12) << camera.name;
  }
}

TEST(Camera, StrongDistortionReallyBendsTheCorners) {
  // Guards the round-trip test against a model that ignores its distortion.
  const Camera opencv = MakeOpenCV();
  Camera undistorted = opencv;
  undistorted.model = CameraModel::kPinhole;
  undistorted.params.resize(4);
  Eigen::Vector3d bent, straight;
  ASSERT_TRUE(opencv.Unproject(Eigen::Vector2d(-0.5, -0.5), &bent));
  ASSERT_TRUE(undistorted.Unproject(Eigen::Vector2d(-0.5, -0.5), &straight));
  // Barrel distortion: the corner pixel sees farther off-axis than a pinhole would.
  EXPECT_GT(std::acos(bent.z()) - std::acos(straight.z()), 0.1);

  const Camera fisheye = MakeFisheye();
  Eigen::Vector3d corner;
  ASSERT_TRUE(fisheye.Unproject(Eigen::Vector2d(-0.5, -0.5), &corner));
  EXPECT_GT(std::acos(corner.z()), 110.0 * kPi / 180.0);
}

TEST(Camera, BearingPixelBearingRoundTrip) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (const Camera& camera : AllCameras()) {
    int checked = 0;
    for (int i = 0; i < 2000; ++i) {
      // Directions up to 60° off-axis for perspective models, 125° for the fisheye.
      const double max_angle = (camera.model == CameraModel::kFisheye ? 125.0 : 60.0) * kPi / 180;
      const double angle = max_angle * std::sqrt(uniform(rng));
      const double azimuth = 2.0 * kPi * uniform(rng);
      const Eigen::Vector3d bearing(std::sin(angle) * std::cos(azimuth),
                                    std::sin(angle) * std::sin(azimuth), std::cos(angle));
      Eigen::Vector2d pixel;
      // The distorted models fold back before 60°; Project must say so, not lie.
      if (!camera.Project(3.0 * bearing, &pixel)) continue;
      Eigen::Vector3d back;
      ASSERT_TRUE(camera.Unproject(pixel, &back)) << camera.name << " " << pixel.transpose();
      EXPECT_LT((back - bearing).norm(), 1e-9) << camera.name;
      ++checked;
    }
    EXPECT_GT(checked, 1000) << camera.name;
  }
}

TEST(Camera, MatchesOpenCVProjectPoints) {
  // Reference pixels computed with cv::projectPoints and cv::fisheye::projectPoints (OpenCV 4.6)
  // for the same intrinsics.
  struct Case {
    Eigen::Vector3d point;
    Eigen::Vector2d pixel;
  };
  const Case opencv_cases[] = {{{0.3, -0.2, 1.0}, {445.69891988000001, 154.44990099}},
                               {{-0.9, 0.6, 1.0}, {22.287502439999969, 440.24037486999998}},
                               {{1.1, 0.7, 1.0}, {653.76844000000006, 455.63071500000001}},
                               {{0.0, 0.0, 1.0}, {319.5, 239.5}}};
  const Case fisheye_cases[] = {{{0.3, -0.2, 1.0}, {467.10786582395059, 254.04285944600474}},
                                {{-2.0, 1.5, 1.0}, {170.6816135950022, 472.58057433198553}},
                                {{5.0, -1.0, 1.0}, {725.19001862629977, 233.80526120016515}},
                                {{0.01, 0.02, 1.0}, {401.83964519357187, 304.21928432207659}}};
  const Camera opencv = MakeOpenCV(), fisheye = MakeFisheye();
  for (const Case& c : opencv_cases) {
    Eigen::Vector2d pixel;
    ASSERT_TRUE(opencv.Project(c.point, &pixel));
    EXPECT_LT((pixel - c.pixel).norm(), 1e-8) << c.point.transpose();
  }
  for (const Case& c : fisheye_cases) {
    Eigen::Vector2d pixel;
    ASSERT_TRUE(fisheye.Project(c.point, &pixel));
    EXPECT_LT((pixel - c.pixel).norm(), 1e-8) << c.point.transpose();
  }
}

Eigen::Matrix<double, 2, 3> NumericJacobian(const Camera& camera, const Eigen::Vector3d& bearing) {
  Eigen::Matrix<double, 2, 3> jacobian;
  const double h = 1e-5 * bearing.norm();
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d plus = bearing, minus = bearing;
    plus[k] += h;
    minus[k] -= h;
    Eigen::Vector2d p_plus, p_minus;
    EXPECT_TRUE(camera.Project(plus, &p_plus));
    EXPECT_TRUE(camera.Project(minus, &p_minus));
    jacobian.col(k) = (p_plus - p_minus) / (2.0 * h);
  }
  return jacobian;
}

TEST(Camera, AnalyticJacobianMatchesNumeric) {
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (const Camera& camera : AllCameras()) {
    int checked = 0;
    for (int i = 0; i < 500; ++i) {
      // A pixel anywhere in the image, its bearing scaled by an arbitrary length.
      const Eigen::Vector2d pixel(uniform(rng) * (camera.width - 1),
                                  uniform(rng) * (camera.height - 1));
      Eigen::Vector3d bearing;
      ASSERT_TRUE(camera.Unproject(pixel, &bearing));
      bearing *= 0.2 + 5.0 * uniform(rng);
      Eigen::Vector2d projected;
      Eigen::Matrix<double, 2, 3> analytic;
      ASSERT_TRUE(camera.Project(bearing, &projected, &analytic));
      const Eigen::Matrix<double, 2, 3> numeric = NumericJacobian(camera, bearing);
      EXPECT_LT((analytic - numeric).norm(), 1e-6 * numeric.norm())
          << camera.name << " at " << pixel.transpose() << "\n"
          << analytic << "\n"
          << numeric;
      // Scaling the bearing does not move the pixel: the Jacobian annihilates the bearing.
      EXPECT_LT((analytic * bearing).norm(), 1e-9 * analytic.norm() * bearing.norm());
      ++checked;
    }
    EXPECT_EQ(checked, 500);
  }
  // On the optical axis and next to it.
  for (const Camera& camera : AllCameras()) {
    for (const Eigen::Vector3d& bearing :
         {Eigen::Vector3d(0, 0, 1), Eigen::Vector3d(1e-9, -2e-9, 2), Eigen::Vector3d(1e-4, 0, 1)}) {
      Eigen::Vector2d projected;
      Eigen::Matrix<double, 2, 3> analytic;
      ASSERT_TRUE(camera.Project(bearing, &projected, &analytic));
      const Eigen::Matrix<double, 2, 3> numeric = NumericJacobian(camera, bearing);
      EXPECT_LT((analytic - numeric).norm(), 1e-6 * numeric.norm()) << camera.name;
    }
  }
}

TEST(Camera, FisheyeJacobianBeyondNinetyDegrees) {
  const Camera camera = MakeFisheye();
  std::mt19937 rng(13);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (int i = 0; i < 200; ++i) {
    const double angle = (90.0 + 35.0 * uniform(rng)) * kPi / 180.0;
    const double azimuth = 2.0 * kPi * uniform(rng);
    const Eigen::Vector3d bearing(std::sin(angle) * std::cos(azimuth),
                                  std::sin(angle) * std::sin(azimuth), std::cos(angle));
    Eigen::Vector2d projected;
    Eigen::Matrix<double, 2, 3> analytic;
    ASSERT_TRUE(camera.Project(bearing, &projected, &analytic));
    const Eigen::Matrix<double, 2, 3> numeric = NumericJacobian(camera, bearing);
    EXPECT_LT((analytic - numeric).norm(), 1e-6 * numeric.norm());
  }
}

TEST(Camera, PinholeRejectsBearingsBehind) {
  const Camera camera = MakePinhole();
  Eigen::Vector2d pixel(-1.0, -1.0);
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.1, 0.2, -1.0), &pixel));
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.0, 0.0, -1.0), &pixel));
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(1.0, 0.0, 0.0), &pixel));
  EXPECT_FALSE(camera.Project(Eigen::Vector3d::Zero(), &pixel));
  EXPECT_FALSE(MakeOpenCV().Project(Eigen::Vector3d(0.1, 0.2, -1.0), &pixel));
  ASSERT_TRUE(camera.Project(Eigen::Vector3d(0.0, 0.0, 2.0), &pixel));
  EXPECT_EQ(pixel, Eigen::Vector2d(255.5, 191.5));
}

TEST(Camera, OpenCVRejectsDirectionsBeyondTheFold) {
  // r (1 + k1 r² + k2 r⁴ + k3 r⁶) stops increasing near r = 1.5: beyond it, two directions share
  // a pixel and Project must refuse.
  const Camera camera = MakeOpenCV();
  Eigen::Vector2d pixel;
  EXPECT_TRUE(camera.Project(Eigen::Vector3d(1.4, 0.0, 1.0), &pixel));
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(1.6, 0.0, 1.0), &pixel));
  // Where the radial slope turns positive again (r large), the map is still not one-to-one.
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(10.0, 0.0, 1.0), &pixel));
  // A pixel farther out than the largest distorted radius has no bearing.
  Eigen::Vector3d bearing;
  EXPECT_FALSE(camera.Unproject(Eigen::Vector2d(319.5 + 440.0 * 1.2, 239.5), &bearing));
}

TEST(Camera, FisheyeImagesBeyondNinetyDegrees) {
  const Camera camera = MakeFisheye();
  const double angle = 100.0 * kPi / 180.0;
  // Towards the image corner (the 95° circle is cropped left and right).
  const Eigen::Vector3d bearing(0.8 * std::sin(angle), 0.6 * std::sin(angle), std::cos(angle));
  Eigen::Vector2d pixel;
  ASSERT_TRUE(camera.Project(bearing, &pixel));
  EXPECT_TRUE(camera.IsInImage(pixel)) << pixel.transpose();
  const Eigen::Vector2d distorted((pixel.x() - camera.cx()) / camera.fx(),
                                  (pixel.y() - camera.cy()) / camera.fy());
  // θd = θ (1 + k1 θ² + ...) is larger than θ here, in the bearing's azimuth.
  EXPECT_GT(distorted.norm(), angle * 1.01);
  EXPECT_NEAR(distorted.x() * 0.6, distorted.y() * 0.8, 1e-12);
  Eigen::Vector3d back;
  ASSERT_TRUE(camera.Unproject(pixel, &back));
  EXPECT_LT((back - bearing).norm(), 1e-10);
  // The axis straight behind and directions past the monotone range are not imaged.
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.0, 0.0, -1.0), &pixel));
  const double past = 140.0 * kPi / 180.0;
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(std::sin(past), 0.0, std::cos(past)), &pixel));
}

TEST(Camera, FisheyeWithoutDistortionIsEquidistant) {
  Camera camera = MakeFisheye();
  camera.params = {200.0, 200.0, 400.0, 300.0, 0.0, 0.0, 0.0, 0.0};
  for (double degrees : {0.0, 30.0, 89.0, 120.0, 179.0}) {
    const double angle = degrees * kPi / 180.0;
    Eigen::Vector2d pixel;
    ASSERT_TRUE(camera.Project(Eigen::Vector3d(0.0, std::sin(angle), std::cos(angle)), &pixel));
    EXPECT_NEAR(pixel.y() - 300.0, 200.0 * angle, 1e-9);
  }
}

TEST(Camera, CheckNamesTheWrongField) {
  EXPECT_EQ(MakeOpenCV().Check(), "");
  {
    Camera camera = MakeOpenCV();
    camera.params = {440.0, 445.0, 319.5, 239.5};
    EXPECT_NE(camera.Check().find("params: expected 9 values (fx fy cx cy k1 k2 p1 p2 k3), got 4"),
              std::string::npos)
        << camera.Check();
  }
  {
    Camera camera = MakeFisheye();
    camera.params.push_back(0.0);
    EXPECT_NE(camera.Check().find("params: expected 8 values"), std::string::npos);
  }
  {
    Camera camera = MakePinhole();
    camera.width = 0;
    EXPECT_NE(camera.Check().find("width"), std::string::npos);
    EXPECT_EQ(camera.Check().find("height"), std::string::npos);
  }
  {
    Camera camera = MakePinhole();
    camera.height = -3;
    EXPECT_NE(camera.Check().find("height"), std::string::npos);
  }
  {
    Camera camera = MakePinhole();
    camera.params[0] = 0.0;
    EXPECT_NE(camera.Check().find("fx"), std::string::npos);
    camera.params[0] = 300.0;
    camera.params[1] = -5.0;
    EXPECT_NE(camera.Check().find("fy"), std::string::npos);
  }
  {
    Camera camera = MakeOpenCV();
    camera.params[5] = std::nan("");
    EXPECT_NE(camera.Check().find("params[5]"), std::string::npos);
  }
  {
    Camera camera = MakePinhole();
    camera.name.clear();
    EXPECT_NE(camera.Check().find("name"), std::string::npos);
  }
  {
    Camera camera = MakePinhole();
    camera.cam_from_rig.rotation = Eigen::Quaterniond(0.5, 0.0, 0.0, 0.0);
    EXPECT_NE(camera.Check().find("cam_from_rig"), std::string::npos);
    camera.cam_from_rig.rotation = Eigen::Quaterniond(0.0, 0.0, 0.0, 0.0);
    EXPECT_NE(camera.Check().find("cam_from_rig"), std::string::npos);
    camera.cam_from_rig.rotation = Eigen::Quaterniond(1.0, 1.0, 1.0, 1.0).normalized();
    EXPECT_EQ(camera.Check(), "");
  }
}

TEST(Camera, InvalidParamsNeverProjectOrCrash) {
  Camera camera = MakeOpenCV();
  camera.params.resize(4);
  Eigen::Vector2d pixel;
  Eigen::Vector3d bearing;
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0, 0, 1), &pixel));
  EXPECT_FALSE(camera.Unproject(Eigen::Vector2d(10, 10), &bearing));
}

}  // namespace
}  // namespace omni
