// Fields of view against closed forms, and the overlaps of the default Ladybug-like rig
// against its geometry (scripts/make_ladybug_like_rig.py).

#include "calib/rig_report.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "calib/rig_io.h"

namespace omni {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

Camera CenteredCamera(CameraModel model, int width, int height, double focal) {
  Camera camera;
  camera.name = "c";
  camera.model = model;
  camera.width = width;
  camera.height = height;
  // cx = (w - 1) / 2: the image edges at -0.5 and w - 0.5 lie w / 2 from the principal point.
  camera.params = {focal, focal, (width - 1) / 2.0, (height - 1) / 2.0};
  if (model == CameraModel::kFisheye) camera.params.insert(camera.params.end(), 4, 0.0);
  return camera;
}

TEST(RigReport, PinholeFieldOfViewIsTwoAtanHalfSizeOverFocal) {
  const double f = 500.0;
  const Camera camera = CenteredCamera(CameraModel::kPinhole, 640, 480, f);
  const CameraFieldOfView fov = ComputeFieldOfView(camera);
  EXPECT_NEAR(fov.horizontal_deg, 2.0 * std::atan(640 / (2 * f)) * kDegPerRad, 1e-9);
  EXPECT_NEAR(fov.vertical_deg, 2.0 * std::atan(480 / (2 * f)) * kDegPerRad, 1e-9);
  EXPECT_NEAR(fov.diagonal_deg, 2.0 * std::atan(800 / (2 * f)) * kDegPerRad, 1e-9);
}

TEST(RigReport, EquidistantFieldOfViewIsSizeOverFocal) {
  // Equidistant without distortion: the angle from the axis is r / f, so the horizontal field
  // is w / f radians (here 122 degrees, wider than a pinhole could be at this focal).
  const double f = 300.0;
  const Camera camera = CenteredCamera(CameraModel::kFisheye, 640, 480, f);
  const CameraFieldOfView fov = ComputeFieldOfView(camera);
  EXPECT_NEAR(fov.horizontal_deg, 640 / f * kDegPerRad, 1e-6);
  EXPECT_NEAR(fov.vertical_deg, 480 / f * kDegPerRad, 1e-6);
}

class DefaultRigOverlap : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    rig_ = new Rig(ReadRigJson(std::string(OMNI_SOURCE_DIR) + "/data/rigs/ladybug-like.json"));
  }
  static void TearDownTestSuite() {
    delete rig_;
    rig_ = nullptr;
  }
  static Rig* rig_;
};
Rig* DefaultRigOverlap::rig_ = nullptr;

TEST_F(DefaultRigOverlap, SideNeighboursOverlapByTheirEightDegrees) {
  const Rig& rig = *rig_;
  ASSERT_EQ(rig.NumCameras(), 6u);
  // The side cameras are upright pinholes, so an image column is a vertical plane: a column
  // of cam k sees azimuth atan((u - cx) / f) from its axis at every height. The next camera is
  // 72 degrees away with the same +-40 degrees, so cam k's columns beyond f tan(32 deg) from
  // the centre are seen by it: a share (w / 2 - f tan 32) / w of the pixels.
  const Camera& cam0 = rig.cameras[0];
  const double expected = (cam0.width / 2.0 - cam0.fx() * std::tan(32.0 / kDegPerRad)) / cam0.width;
  const int samples = 64;
  for (size_t k = 0; k < 5; ++k) {
    const size_t next = (k + 1) % 5;
    for (const auto& [from, to] : {std::pair{k, next}, std::pair{next, k}}) {
      const double overlap = ComputeViewOverlap(rig, from, to, samples);
      EXPECT_GT(overlap, 0.0) << from << " -> " << to;
      EXPECT_LT(overlap, 0.30) << from << " -> " << to;
      // One grid column (1 / samples of the width) of sampling error at most.
      EXPECT_NEAR(overlap, expected, 1.0 / samples) << from << " -> " << to;
    }
  }
}

TEST_F(DefaultRigOverlap, NonNeighboursDoNotOverlap) {
  // 144 degrees apart with +-40 degrees each.
  EXPECT_EQ(ComputeViewOverlap(*rig_, 0, 2), 0.0);
  EXPECT_EQ(ComputeViewOverlap(*rig_, 2, 0), 0.0);
  EXPECT_EQ(ComputeViewOverlap(*rig_, 1, 3), 0.0);
  EXPECT_EQ(ComputeViewOverlap(*rig_, 4, 1), 0.0);
}

TEST_F(DefaultRigOverlap, UpCameraOverlapsEverySideCameraSymmetrically) {
  // cam5 sees elevations above 90 - 48.2 degrees towards the front (its 96 degree vertical
  // field lies along rig x), and the side cameras see up to 48.2 degrees of elevation at their
  // image centre column: a thin overlap with each of them, mirror-symmetric about the rig's
  // x-z plane (cam1 <-> cam4, cam2 <-> cam3).
  const Rig& rig = *rig_;
  for (size_t k = 0; k < 5; ++k) {
    const double up_in_side = ComputeViewOverlap(rig, 5, k);
    const double side_in_up = ComputeViewOverlap(rig, k, 5);
    EXPECT_GT(up_in_side, 0.0) << k;
    EXPECT_LT(up_in_side, 0.30) << k;
    EXPECT_GT(side_in_up, 0.0) << k;
    EXPECT_LT(side_in_up, 0.30) << k;
  }
  EXPECT_NEAR(ComputeViewOverlap(rig, 5, 1), ComputeViewOverlap(rig, 5, 4), 4.0 / (64 * 64));
  EXPECT_NEAR(ComputeViewOverlap(rig, 5, 2), ComputeViewOverlap(rig, 5, 3), 4.0 / (64 * 64));
  EXPECT_NEAR(ComputeViewOverlap(rig, 1, 5), ComputeViewOverlap(rig, 4, 5), 4.0 / (64 * 64));
  EXPECT_DOUBLE_EQ(ComputeViewOverlap(rig, 3, 3), 1.0);
}

TEST_F(DefaultRigOverlap, DescriptionListsCamerasAndOnlyOverlappingPairs) {
  const std::string text = DescribeRig(*rig_);
  for (int k = 0; k < 6; ++k) {
    EXPECT_NE(text.find("cam" + std::to_string(k) + " "), std::string::npos) << text;
  }
  EXPECT_NE(text.find("central: no"), std::string::npos) << text;
  EXPECT_NE(text.find("cam0 / cam1:"), std::string::npos) << text;
  EXPECT_NE(text.find("cam0 / cam4:"), std::string::npos) << text;
  EXPECT_NE(text.find("cam0 / cam5:"), std::string::npos) << text;
  EXPECT_EQ(text.find("cam0 / cam2:"), std::string::npos) << text;
  EXPECT_EQ(text.find("cam1 / cam3:"), std::string::npos) << text;
  // The horizontal field of view of the side cameras is the rig's 80 degrees.
  EXPECT_NEAR(ComputeFieldOfView(rig_->cameras[0]).horizontal_deg, 80.0, 1e-4);
}

}  // namespace
}  // namespace omni
