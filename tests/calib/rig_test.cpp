#include "calib/rig.h"

#include <gtest/gtest.h>

namespace omni {
namespace {

Camera MakeCamera(const std::string& name, const Rigid3d& cam_from_rig) {
  Camera camera;
  camera.name = name;
  camera.width = 512;
  camera.height = 384;
  camera.model = CameraModel::kPinhole;
  camera.params = {300.0, 300.0, 255.5, 191.5};
  camera.cam_from_rig = cam_from_rig;
  return camera;
}

// Camera centres given in the rig frame, with arbitrary orientations.
Rigid3d CamFromRigAt(const Eigen::Vector3d& center_in_rig, const Eigen::Quaterniond& rotation) {
  return Rigid3d(rotation, -(rotation * center_in_rig));
}

TEST(Rig, CentralCenterOfTwoCameras) {
  Rig rig;
  rig.name = "pair";
  const Eigen::Quaterniond yaw(Eigen::AngleAxisd(1.2, Eigen::Vector3d::UnitY()));
  const Eigen::Quaterniond tilt(Eigen::AngleAxisd(-0.4, Eigen::Vector3d(1, 1, 0).normalized()));
  rig.cameras.push_back(MakeCamera("left", CamFromRigAt(Eigen::Vector3d(0.1, 0.0, 0.0), yaw)));
  rig.cameras.push_back(MakeCamera("right", CamFromRigAt(Eigen::Vector3d(-0.1, 0.0, 0.2), tilt)));
  EXPECT_EQ(rig.Check(), "");
  EXPECT_EQ(rig.NumCameras(), 2u);
  EXPECT_LT((rig.cameras[0].CenterInRig() - Eigen::Vector3d(0.1, 0.0, 0.0)).norm(), 1e-15);
  EXPECT_LT((rig.CentralCenterInRig() - Eigen::Vector3d(0.0, 0.0, 0.1)).norm(), 1e-15);
  EXPECT_NEAR(rig.MaxCenterOffset(), std::sqrt(0.02), 1e-15);
  EXPECT_EQ(rig.FindCamera("right"), 1u);
  EXPECT_EQ(rig.FindCamera("left"), 0u);
  EXPECT_FALSE(rig.FindCamera("up").has_value());
}

TEST(Rig, FinestPixelAngleIsThatOfTheLongestFocalLength) {
  Rig rig;
  EXPECT_EQ(rig.FinestPixelAngle(), 0.0);
  rig.cameras.push_back(MakeCamera("wide", Rigid3d()));
  rig.cameras.push_back(MakeCamera("tele", Rigid3d()));
  rig.cameras[1].params = {800.0, 820.0, 255.5, 191.5};
  EXPECT_DOUBLE_EQ(rig.FinestPixelAngle(), 1.0 / 820.0);
  rig.cameras[1].params[1] = 790.0;
  EXPECT_DOUBLE_EQ(rig.FinestPixelAngle(), 1.0 / 800.0);
}

TEST(Rig, SingleCameraIsValidAndCentral) {
  Rig rig;
  rig.cameras.push_back(MakeCamera(
      "only", CamFromRigAt(Eigen::Vector3d(0.3, -0.2, 0.1), Eigen::Quaterniond::Identity())));
  EXPECT_EQ(rig.Check(), "");
  EXPECT_LT((rig.CentralCenterInRig() - Eigen::Vector3d(0.3, -0.2, 0.1)).norm(), 1e-15);
  EXPECT_EQ(rig.MaxCenterOffset(), 0.0);
}

TEST(Rig, CheckRejectsEmptyDuplicateAndInvalidCameras) {
  Rig rig;
  EXPECT_NE(rig.Check().find("cameras"), std::string::npos);

  rig.cameras.push_back(MakeCamera("cam0", Rigid3d()));
  rig.cameras.push_back(MakeCamera("cam1", Rigid3d()));
  rig.cameras.push_back(MakeCamera("cam0", Rigid3d()));
  const std::string duplicate = rig.Check();
  EXPECT_NE(duplicate.find("cameras[2] (cam0)"), std::string::npos) << duplicate;
  EXPECT_NE(duplicate.find("duplicate"), std::string::npos) << duplicate;
  EXPECT_EQ(duplicate.find("cameras[1]"), std::string::npos) << duplicate;

  rig.cameras[2].name = "cam2";
  EXPECT_EQ(rig.Check(), "");
  rig.cameras[1].model = CameraModel::kOpenCV;
  const std::string invalid = rig.Check();
  EXPECT_NE(invalid.find("cameras[1] (cam1): params: expected 9 values"), std::string::npos)
      << invalid;
}

}  // namespace
}  // namespace omni
