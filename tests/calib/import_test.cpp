// Kalibr and Ladybug importers against transforms and intrinsics computed by hand here.

#include "calib/import.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "calib/error.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

class ImportTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           (std::string("omni_import_test_") + info->name() + "_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  fs::path Write(const std::string& name, const std::string& text) {
    const fs::path path = dir_ / name;
    std::ofstream(path) << text;
    return path;
  }

  fs::path dir_;
};

// A 4x4 matrix as Kalibr writes it: a YAML list of rows, full precision.
std::string YamlMatrix(const Eigen::Matrix4d& m, const std::string& indent) {
  std::string text;
  char row[256];
  for (int r = 0; r < 4; ++r) {
    std::snprintf(row, sizeof(row), "%s- [%.17g, %.17g, %.17g, %.17g]\n", indent.c_str(), m(r, 0),
                  m(r, 1), m(r, 2), m(r, 3));
    text += row;
  }
  return text;
}

Eigen::Matrix4d MakeTransform(double angle, const Eigen::Vector3d& axis,
                              const Eigen::Vector3d& translation) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = Eigen::AngleAxisd(angle, axis.normalized()).toRotationMatrix();
  m.topRightCorner<3, 1>() = translation;
  return m;
}

Eigen::Matrix4d ToMatrix4(const Rigid3d& transform) {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = transform.rotation.toRotationMatrix();
  m.topRightCorner<3, 1>() = transform.translation;
  return m;
}

void ExpectTransformNear(const Rigid3d& actual, const Eigen::Matrix4d& expected, double tol) {
  EXPECT_LT((ToMatrix4(actual) - expected).cwiseAbs().maxCoeff(), tol)
      << "actual:\n"
      << ToMatrix4(actual) << "\nexpected:\n"
      << expected;
}

std::string KalibrCamera(int index, const std::string& model, const std::string& distortion,
                         const std::string& coeffs, const std::string& intrinsics,
                         const std::string& resolution, const std::string& rostopic) {
  std::string text = "cam" + std::to_string(index) + ":\n";
  text += "  camera_model: " + model + "\n";
  if (!distortion.empty()) text += "  distortion_model: " + distortion + "\n";
  if (!coeffs.empty()) text += "  distortion_coeffs: " + coeffs + "\n";
  text += "  intrinsics: " + intrinsics + "\n";
  text += "  resolution: " + resolution + "\n";
  if (!rostopic.empty()) text += "  rostopic: " + rostopic + "\n";
  return text;
}

TEST_F(ImportTest, KalibrChainedExtrinsicsAndModels) {
  const Eigen::Matrix4d cam1_from_cam0 =
      MakeTransform(0.35, {0.2, 1.0, -0.1}, {-0.12, 0.015, 0.02});
  const Eigen::Matrix4d cam2_from_cam1 = MakeTransform(-1.1, {0.1, 0.9, 0.3}, {0.05, -0.2, 0.07});
  // Listed out of order on purpose: the importer sorts cam0, cam1, cam2.
  std::string text;
  text += KalibrCamera(2, "pinhole", "none", "", "[400.0, 401.0, 330.0, 250.0]", "[640, 480]",
                       "/stereo/right/image_raw");
  text += "  T_cn_cnm1:\n" + YamlMatrix(cam2_from_cam1, "  ");
  text += KalibrCamera(0, "pinhole", "radtan", "[-0.28, 0.07, 0.0002, -0.0001]",
                       "[458.654, 457.296, 367.215, 248.375]", "[752, 480]", "/cam0/image_raw");
  text += "  cam_overlaps: [1]\n";
  text += KalibrCamera(1, "pinhole", "equidistant", "[0.01, -0.02, 0.003, -0.0004]",
                       "[350.1, 350.2, 511.5, 383.5]", "[1024, 768]", "/cam1/image_raw");
  text += "  T_cn_cnm1:\n" + YamlMatrix(cam1_from_cam0, "  ");
  const Rig rig = ImportKalibr(Write("camchain.yaml", text));

  ASSERT_EQ(rig.NumCameras(), 3u);
  EXPECT_EQ(rig.name, "camchain");
  EXPECT_EQ(rig.cameras[0].name, "cam0");
  EXPECT_EQ(rig.cameras[1].name, "cam1");
  EXPECT_EQ(rig.cameras[2].name, "right");

  const Camera& cam0 = rig.cameras[0];
  EXPECT_EQ(cam0.model, CameraModel::kOpenCV);
  EXPECT_EQ(cam0.width, 752);
  EXPECT_EQ(cam0.height, 480);
  const std::vector<double> cam0_params = {458.654, 457.296, 367.215, 248.375, -0.28,
                                           0.07,    0.0002,  -0.0001, 0.0};
  EXPECT_EQ(cam0.params, cam0_params);

  const Camera& cam1 = rig.cameras[1];
  EXPECT_EQ(cam1.model, CameraModel::kFisheye);
  EXPECT_EQ(cam1.width, 1024);
  EXPECT_EQ(cam1.height, 768);
  const std::vector<double> cam1_params = {350.1, 350.2, 511.5, 383.5, 0.01, -0.02, 0.003, -0.0004};
  EXPECT_EQ(cam1.params, cam1_params);

  const Camera& cam2 = rig.cameras[2];
  EXPECT_EQ(cam2.model, CameraModel::kPinhole);
  const std::vector<double> cam2_params = {400.0, 401.0, 330.0, 250.0};
  EXPECT_EQ(cam2.params, cam2_params);

  // cam0 is the rig frame; cam2_from_rig = cam2_from_cam1 * cam1_from_cam0 * cam0_from_rig.
  const Eigen::Matrix4d cam0_from_rig = Eigen::Matrix4d::Identity();
  const Eigen::Matrix4d cam1_from_rig = cam1_from_cam0 * cam0_from_rig;
  const Eigen::Matrix4d cam2_from_rig = cam2_from_cam1 * cam1_from_cam0 * cam0_from_rig;
  ExpectTransformNear(cam0.cam_from_rig, cam0_from_rig, 1e-12);
  ExpectTransformNear(cam1.cam_from_rig, cam1_from_rig, 1e-9);
  ExpectTransformNear(cam2.cam_from_rig, cam2_from_rig, 1e-9);

  // Centres 12 cm and more apart: more than the 5 cm of KalibrImportOptions.
  EXPECT_FALSE(rig.central);
  KalibrImportOptions loose;
  loose.central_max_center_offset_m = 1.0;
  EXPECT_TRUE(ImportKalibr(dir_ / "camchain.yaml", loose).central);
}

TEST_F(ImportTest, KalibrImuCamWithoutChain) {
  const Eigen::Matrix4d cam0_from_imu = MakeTransform(2.0, {1.0, -0.5, 0.2}, {0.01, 0.02, -0.03});
  const Eigen::Matrix4d cam1_from_imu = MakeTransform(0.7, {-0.3, 0.4, 1.0}, {-0.02, 0.01, 0.0});
  std::string text;
  text += KalibrCamera(0, "pinhole", "radtan", "[0.1, 0.01, 0.0, 0.0]",
                       "[300.0, 300.0, 320.0, 240.0]", "[640, 480]", "/cam0/image_raw");
  text += "  T_cam_imu:\n" + YamlMatrix(cam0_from_imu, "  ");
  text += KalibrCamera(1, "pinhole", "radtan", "[0.1, 0.01, 0.0, 0.0]",
                       "[300.0, 300.0, 320.0, 240.0]", "[640, 480]", "/cam0/image_raw");
  text += "  T_cam_imu:\n" + YamlMatrix(cam1_from_imu, "  ");
  const Rig rig = ImportKalibr(Write("camchain-imucam.yaml", text));

  ASSERT_EQ(rig.NumCameras(), 2u);
  // Both rostopics name "cam0": not unique, so the names fall back to camN.
  EXPECT_EQ(rig.cameras[0].name, "cam0");
  EXPECT_EQ(rig.cameras[1].name, "cam1");
  // Rig frame = cam0: cam1_from_rig = cam1_from_imu * imu_from_cam0.
  const Eigen::Matrix4d cam1_from_rig = cam1_from_imu * cam0_from_imu.inverse();
  ExpectTransformNear(rig.cameras[0].cam_from_rig, Eigen::Matrix4d::Identity(), 1e-12);
  ExpectTransformNear(rig.cameras[1].cam_from_rig, cam1_from_rig, 1e-9);
  // The two centres are a few centimetres apart: central.
  ASSERT_LT(rig.MaxCenterOffset(), 0.05);
  EXPECT_TRUE(rig.central);
}

TEST_F(ImportTest, KalibrRejectsUnsupportedCameraModel) {
  std::string text =
      KalibrCamera(0, "pinhole", "none", "", "[300, 300, 320, 240]", "[640, 480]", "");
  text +=
      KalibrCamera(1, "omni", "radtan", "[0, 0, 0, 0]", "[300, 300, 320, 240]", "[640, 480]", "");
  text += "  T_cn_cnm1:\n" + YamlMatrix(Eigen::Matrix4d::Identity(), "  ");
  const fs::path path = Write("omni.yaml", text);
  try {
    ImportKalibr(path);
    FAIL() << "expected InputError";
  } catch (const InputError& error) {
    EXPECT_EQ(error.field(), "cam1.camera_model");
    EXPECT_EQ(error.file(), path);
    EXPECT_NE(std::string(error.what()).find("omni"), std::string::npos) << error.what();
  }
}

TEST_F(ImportTest, KalibrRejectsMissingExtrinsicsAndBadFields) {
  const std::string cam0 =
      KalibrCamera(0, "pinhole", "none", "", "[300, 300, 320, 240]", "[640, 480]", "");
  const std::string cam1 =
      KalibrCamera(1, "pinhole", "none", "", "[300, 300, 320, 240]", "[640, 480]", "");
  auto field_of = [&](const std::string& text) -> std::string {
    try {
      ImportKalibr(Write("bad.yaml", text));
    } catch (const InputError& error) {
      return error.field();
    }
    return "(no error)";
  };
  EXPECT_EQ(field_of(cam0 + cam1), "cam1.T_cn_cnm1");
  EXPECT_EQ(
      field_of(cam0 + "  T_cam_imu:\n" + YamlMatrix(Eigen::Matrix4d::Identity(), "  ") + cam1),
      "cam1.T_cn_cnm1");
  Eigen::Matrix4d not_rigid = Eigen::Matrix4d::Identity();
  not_rigid(0, 0) = 2.0;
  EXPECT_EQ(field_of(cam0 + cam1 + "  T_cn_cnm1:\n" + YamlMatrix(not_rigid, "  ")),
            "cam1.T_cn_cnm1");
  EXPECT_EQ(field_of(KalibrCamera(0, "pinhole", "fov", "[0.9]", "[300, 300, 320, 240]",
                                  "[640, 480]", "")),
            "cam0.distortion_model");
  EXPECT_EQ(field_of(KalibrCamera(0, "pinhole", "none", "", "[300, 300, 320]", "[640, 480]", "")),
            "cam0.intrinsics");
  EXPECT_EQ(field_of(KalibrCamera(0, "pinhole", "none", "", "[300, 300, 320, 240]", "[640]", "")),
            "cam0.resolution");
  EXPECT_EQ(field_of(cam1), "cam0");  // numbering must start at cam0
  EXPECT_THROW(ImportKalibr(Write("broken.yaml", "cam0: [unclosed\n")), InputError);
  EXPECT_THROW(ImportKalibr(dir_ / "missing.yaml"), InputError);
}

// --- Ladybug ---------------------------------------------------------------------------------

constexpr int kLadybugWidth = 1024;
constexpr int kLadybugHeight = 768;

struct LadybugBlock {
  double fu, fv, rx, ry, rz, tx, ty, tz, u, v;
};
const LadybugBlock kBlocks[2] = {
    {0.42, 0.56, 0.3, -0.2, 1.3, 0.041, 0.012, -0.02, 0.51, 0.48},
    {0.40, 0.53, -1.45, 0.35, -0.6, -0.01, 0.039, 0.003, 0.495, 0.505},
};

std::string LadybugConf() {
  std::string text =
      "# Ladybug calibration export (hand-written for the test)\n"
      "SerialNumber 1234567\n"
      "Resolution 1024 768\n";
  char line[256];
  for (const LadybugBlock& b : kBlocks) {
    text += "BeginCamera\n";
    std::snprintf(line, sizeof(line), "  focalLength %.17g %.17g  # rectified\n", b.fu, b.fv);
    text += line;
    std::snprintf(line, sizeof(line),
                  "  CamToLadybugEulerZYX %.17g %.17g %.17g %.17g %.17g %.17g\n", b.rx, b.ry, b.rz,
                  b.tx, b.ty, b.tz);
    text += line;
    std::snprintf(line, sizeof(line), "  Center 0.1 0.2 0.3 %.17g %.17g\n", b.u, b.v);
    text += line;
    text += "  Distortion 1 2 3\n";
    text += "EndCamera\n";
  }
  return text;
}

// head_from_cam of a block, with the elementary rotations written out.
Eigen::Matrix4d HeadFromCam(const LadybugBlock& b) {
  Eigen::Matrix3d rx, ry, rz;
  rx << 1, 0, 0, 0, std::cos(b.rx), -std::sin(b.rx), 0, std::sin(b.rx), std::cos(b.rx);
  ry << std::cos(b.ry), 0, std::sin(b.ry), 0, 1, 0, -std::sin(b.ry), 0, std::cos(b.ry);
  rz << std::cos(b.rz), -std::sin(b.rz), 0, std::sin(b.rz), std::cos(b.rz), 0, 0, 0, 1;
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = rz * ry * rx;
  m.topRightCorner<3, 1>() = Eigen::Vector3d(b.tx, b.ty, b.tz);
  return m;
}

TEST_F(ImportTest, LadybugIntrinsicsAndExtrinsics) {
  const Rig rig = ImportLadybug(Write("ladybug.conf", LadybugConf()));
  ASSERT_EQ(rig.NumCameras(), 2u);
  for (int i = 0; i < 2; ++i) {
    const Camera& camera = rig.cameras[i];
    const LadybugBlock& b = kBlocks[i];
    EXPECT_EQ(camera.name, "cam" + std::to_string(i));
    EXPECT_EQ(camera.model, CameraModel::kPinhole);
    EXPECT_EQ(camera.width, kLadybugWidth);
    EXPECT_EQ(camera.height, kLadybugHeight);
    ASSERT_EQ(camera.params.size(), 4u);
    EXPECT_NEAR(camera.fx(), b.fu * 1024, 1e-9);
    EXPECT_NEAR(camera.fy(), b.fv * 768, 1e-9);
    EXPECT_NEAR(camera.cx(), b.u * 1024 - 0.5, 1e-9);
    EXPECT_NEAR(camera.cy(), b.v * 768 - 0.5, 1e-9);
    // cam_from_rig = (head_from_cam)^-1 = [R^T, -R^T t].
    const Eigen::Matrix4d head_from_cam = HeadFromCam(b);
    Eigen::Matrix4d cam_from_head = Eigen::Matrix4d::Identity();
    cam_from_head.topLeftCorner<3, 3>() = head_from_cam.topLeftCorner<3, 3>().transpose();
    cam_from_head.topRightCorner<3, 1>() =
        -head_from_cam.topLeftCorner<3, 3>().transpose() * head_from_cam.topRightCorner<3, 1>();
    ExpectTransformNear(camera.cam_from_rig, cam_from_head, 1e-12);
    EXPECT_LT((camera.CenterInRig() - Eigen::Vector3d(b.tx, b.ty, b.tz)).norm(), 1e-12);
  }
}

TEST_F(ImportTest, LadybugUprightRotatesPixels) {
  const fs::path path = Write("ladybug.conf", LadybugConf());
  const Rig native = ImportLadybug(path);
  LadybugImportOptions options;
  options.upright = true;
  const Rig upright = ImportLadybug(path, options);
  ASSERT_EQ(upright.NumCameras(), 2u);
  const int height = kLadybugHeight;
  for (int i = 0; i < 2; ++i) {
    const Camera& n = native.cameras[i];
    const Camera& u = upright.cameras[i];
    EXPECT_EQ(u.width, n.height);
    EXPECT_EQ(u.height, n.width);
    EXPECT_LT((u.CenterInRig() - n.CenterInRig()).norm(), 1e-12);
    // Points in front of the camera, given in the camera frame, then taken to the rig frame.
    const Eigen::Matrix4d head_from_cam = HeadFromCam(kBlocks[i]);
    for (const Eigen::Vector3d& in_cam :
         {Eigen::Vector3d(0.3, -0.2, 2.0), Eigen::Vector3d(-1.0, 0.7, 3.0),
          Eigen::Vector3d(0.0, 0.0, 5.0), Eigen::Vector3d(0.9, 0.6, 1.5)}) {
      const Eigen::Vector3d in_rig =
          head_from_cam.topLeftCorner<3, 3>() * in_cam + head_from_cam.topRightCorner<3, 1>();
      Eigen::Vector2d pixel, upright_pixel;
      ASSERT_TRUE(n.Project(n.cam_from_rig * in_rig, &pixel));
      ASSERT_TRUE(u.Project(u.cam_from_rig * in_rig, &upright_pixel));
      EXPECT_NEAR(upright_pixel.x(), height - 1 - pixel.y(), 1e-7) << in_cam.transpose();
      EXPECT_NEAR(upright_pixel.y(), pixel.x(), 1e-7) << in_cam.transpose();
    }
  }
}

TEST_F(ImportTest, LadybugRejectsMalformedLinesWithLineNumbers) {
  const std::string header = "# comment\nResolution 1024 768\n";  // lines 1, 2
  const std::string good_block =
      "BeginCamera\n"
      "focalLength 0.4 0.5\n"
      "CamToLadybugEulerZYX 0 0 0 0 0 0\n"
      "Center 0 0 0 0.5 0.5\n"
      "EndCamera\n";
  struct Case {
    std::string text;
    std::string field;
    std::string mentions;
  };
  const Case cases[] = {
      {header + "BeginCamera\nfocalLength 0.4\n", "line 4", "focalLength"},
      {header + "BeginCamera\nfocalLength 0.4 0.5\nCamToLadybugEulerZYX 0 0 abc 0 0 0\n", "line 5",
       "CamToLadybugEulerZYX"},
      {header + good_block + "Center 0 0 0 0.5 0.5\n", "line 8", "outside"},
      {"Resolution 1024\n" + good_block, "line 1", "Resolution"},
      {header + "BeginCamera\nfocalLength 0.4 0.5\nfocalLength 0.4 0.5\n", "line 5", "twice"},
      {header + good_block + "BeginCamera\nfocalLength 0.4 0.5\n", "line 8", "EndCamera"},
      {header + "BeginCamera\nfocalLength 0.4 0.5\nCenter 0 0 0 0.5 0.5\nEndCamera\n",
       "camera block at line 3", "CamToLadybugEulerZYX"},
      {good_block, "Resolution", "missing"},
      {"Resolution 0x400 768\n" + good_block, "line 1", "Resolution"},
      {"Resolution 1e12 768\n" + good_block, "line 1", "up to 65536"},
      {header + "BeginCamera\nfocalLength 1e20 0.5\nCamToLadybugEulerZYX 0 0 0 0 0 0\n"
                "Center 0 0 0 0.5 0.5\nEndCamera\n",
       "cameras[0].params[0]", "expected a focal length fx"},
      {header + "BeginCamera\nfocalLength 0.4 0.5\nCamToLadybugEulerZYX 0 0 0 1e300 0 0\n"
                "Center 0 0 0 0.5 0.5\nEndCamera\n",
       "cameras[0].cam_from_rig.t", "within 100 m"},
  };
  for (const Case& c : cases) {
    const fs::path path = Write("bad.conf", c.text);
    try {
      ImportLadybug(path);
      ADD_FAILURE() << "no error for:\n" << c.text;
    } catch (const InputError& error) {
      EXPECT_EQ(error.field(), c.field) << error.what();
      EXPECT_EQ(error.file(), path);
      EXPECT_NE(std::string(error.what()).find(c.mentions), std::string::npos) << error.what();
    }
  }
}

// Malformed YAML nodes, numbers out of range and implausible cameras are bad input naming the
// file, never a parser's exception.
TEST_F(ImportTest, KalibrRejectsOverflowOddNodesAndImplausibleCameras) {
  const std::string camera =
      KalibrCamera(0, "pinhole", "none", "", "[400, 400, 320, 240]", "[640, 480]", "");
  EXPECT_NO_THROW(ImportKalibr(Write("good.yaml", camera)));
  struct Case {
    std::string text;
    std::string mentions;
  };
  const Case cases[] = {
      {KalibrCamera(0, "pinhole", "none", "", "[400, 400, 320, 240]", "[1e300, 480]", ""),
       "cam0.resolution: expected two positive integers up to 65536"},
      {KalibrCamera(0, "pinhole", "none", "", "[1e309, 400, 320, 240]", "[640, 480]", ""),
       "cam0.intrinsics: expected 4 numbers"},
      {KalibrCamera(0, "pinhole", "none", "", "[0x10, 400, 320, 240]", "[640, 480]", ""),
       "cam0.intrinsics: expected 4 numbers"},
      {KalibrCamera(0, "pinhole", "none", "", "[1e20, 400, 320, 240]", "[640, 480]", ""),
       "cameras[0].params[0]: expected a focal length fx"},
      {"? [a, b]\n: 1\n" + camera, "malformed YAML"},
      {"cam99999999999:\n  camera_model: pinhole\n", "cam0: missing"},
      {"cam0: [1, 2]\n", "cam0: expected a map"},
      {"cam0:\n  camera_model: {a: 1}\n", "cam0.camera_model: expected a string"},
  };
  for (const Case& c : cases) {
    const fs::path path = Write("bad.yaml", c.text);
    try {
      ImportKalibr(path);
      ADD_FAILURE() << "no error for:\n" << c.text;
    } catch (const InputError& error) {
      EXPECT_EQ(error.file(), path) << error.what();
      EXPECT_NE(std::string(error.what()).find(c.mentions), std::string::npos) << error.what();
    }
  }
}

}  // namespace
}  // namespace omni
