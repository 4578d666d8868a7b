#include "sfm/colmap_model.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <sstream>

#include "calib/colmap_text.h"
#include "sfm/synthetic.h"

namespace omni {
namespace {

Camera MakeCamera(CameraModel model, std::vector<double> params) {
  Camera camera;
  camera.width = 640;
  camera.height = 480;
  camera.model = model;
  camera.params = std::move(params);
  return camera;
}

TEST(ColmapModel, CameraModelsAndTheHalfPixelShift) {
  std::vector<double> params;
  EXPECT_EQ(ColmapCameraModel(MakeCamera(CameraModel::kPinhole, {300, 310, 319.5, 239.5}), &params),
            "PINHOLE");
  EXPECT_EQ(params, (std::vector<double>{300, 310, 320, 240}));
  EXPECT_EQ(ColmapCameraModel(MakeCamera(CameraModel::kOpenCV,
                                         {300, 310, 319.5, 239.5, 0.1, -0.2, 1e-3, 2e-3, 0}),
                              &params),
            "OPENCV");
  EXPECT_EQ(params, (std::vector<double>{300, 310, 320, 240, 0.1, -0.2, 1e-3, 2e-3}));
  EXPECT_EQ(ColmapCameraModel(MakeCamera(CameraModel::kOpenCV,
                                         {300, 310, 319.5, 239.5, 0.1, -0.2, 1e-3, 2e-3, 0.05}),
                              &params),
            "FULL_OPENCV");
  EXPECT_EQ(params,
            (std::vector<double>{300, 310, 320, 240, 0.1, -0.2, 1e-3, 2e-3, 0.05, 0, 0, 0}));
  EXPECT_EQ(ColmapCameraModel(
                MakeCamera(CameraModel::kFisheye, {300, 310, 319.5, 239.5, 0.01, 0.02, 0.03, 0.04}),
                &params),
            "OPENCV_FISHEYE");
  EXPECT_EQ(params, (std::vector<double>{300, 310, 320, 240, 0.01, 0.02, 0.03, 0.04}));
}

// Two keyframes of a two-camera rig and one point seen by both: the image poses are
// cam_from_world, the 2-D points are the projections (+0.5), the track links them.
TEST(ColmapModel, WritesPosesObservationsAndTracks) {
  const Rig rig = MakeSyntheticRingRig(2, false, 0.1);
  const Eigen::Vector3d point(3.0, 0.4, 0.2);
  std::vector<FinalizedKeyframe> keyframes(2);
  for (int k = 0; k < 2; ++k) {
    keyframes[k].keyframe = 5 + k;
    keyframes[k].frame = 10 * k;
    keyframes[k].world_from_rig =
        Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * k, Eigen::Vector3d::UnitZ())),
                Eigen::Vector3d(0.5 * k, 0.0, 0.0));
  }
  FinalizedPoint finalized;
  finalized.position = point;
  for (int k = 0; k < 2; ++k) {
    const Rigid3d cam_from_world =
        rig.cameras[0].cam_from_rig * keyframes[k].world_from_rig.Inverse();
    finalized.rays.push_back(
        {5 + k, Eigen::Vector3d::Zero(), 0, (cam_from_world * point).normalized()});
  }
  keyframes[1].points.push_back(finalized);
  const std::filesystem::path folder = std::filesystem::temp_directory_path() /
                                       ("omni_colmap_model_test_" + std::to_string(::getpid()));
  const ColmapModelStats stats = WriteColmapTextModel(
      rig, keyframes,
      [](int frame, int camera) {
        return "images/cam" + std::to_string(camera) + "/" + std::to_string(frame) + ".png";
      },
      folder);
  EXPECT_EQ(stats.images, 4);
  EXPECT_EQ(stats.points, 1);
  EXPECT_EQ(stats.observations, 2);
  EXPECT_LT(stats.mean_reprojection_error, 1e-6);

  std::ifstream images(folder / "images.txt");
  std::string line;
  std::vector<std::string> data;
  while (std::getline(images, line))
    if (line.empty() || line[0] != '#') data.push_back(line);
  ASSERT_EQ(data.size(), 8u);
  // Image 3 = keyframe 1, camera 0: pose and its one 2-D point.
  std::istringstream header(data[4]);
  long id, camera;
  double qw, qx, qy, qz, tx, ty, tz;
  std::string name;
  ASSERT_TRUE(header >> id >> qw >> qx >> qy >> qz >> tx >> ty >> tz >> camera >> name);
  EXPECT_EQ(id, 3);
  EXPECT_EQ(camera, 1);
  EXPECT_EQ(name, "images/cam0/10.png");
  const Rigid3d expected = rig.cameras[0].cam_from_rig * keyframes[1].world_from_rig.Inverse();
  EXPECT_LT((Eigen::Vector3d(tx, ty, tz) - expected.translation).norm(), 1e-9);
  EXPECT_LT(RotationAngleBetween(Eigen::Quaterniond(qw, qx, qy, qz), expected.rotation), 1e-9);
  std::istringstream points2d(data[5]);
  double x, y;
  long point3d;
  ASSERT_TRUE(points2d >> x >> y >> point3d);
  Eigen::Vector2d pixel;
  ASSERT_TRUE(rig.cameras[0].Project(expected * point, &pixel));
  EXPECT_NEAR(x, pixel.x() + 0.5, 1e-5);
  EXPECT_NEAR(y, pixel.y() + 0.5, 1e-5);
  EXPECT_EQ(point3d, 1);
  EXPECT_TRUE(data[3].empty());  // camera 1 of keyframe 0 sees nothing

  std::ifstream points(folder / "points3D.txt");
  std::vector<std::string> point_lines;
  while (std::getline(points, line))
    if (!line.empty() && line[0] != '#') point_lines.push_back(line);
  ASSERT_EQ(point_lines.size(), 1u);
  std::istringstream track(point_lines[0]);
  double px, py, pz, r, g, b, error;
  long image1, index1, image2, index2;
  ASSERT_TRUE(track >> id >> px >> py >> pz >> r >> g >> b >> error >> image1 >> index1 >> image2 >>
              index2);
  EXPECT_LT((Eigen::Vector3d(px, py, pz) - point).norm(), 1e-6);
  EXPECT_EQ(image1, 1);
  EXPECT_EQ(index1, 0);
  EXPECT_EQ(image2, 3);
  EXPECT_EQ(index2, 0);
  std::filesystem::remove_all(folder);
}

// Colours: one per point of the keyframes in their order, written as R G B; none: grey 128.
TEST(ColmapModel, WritesThePointColoursInTheKeyframesOrder) {
  const Rig rig = MakeSyntheticRingRig(1, false, 0.1);
  FinalizedKeyframe keyframe;
  keyframe.keyframe = 0;
  for (double y : {-0.5, 0.5}) {
    FinalizedPoint point;
    point.position = Eigen::Vector3d(3.0, y, 0.1);
    point.rays.push_back({0, Eigen::Vector3d::Zero(), 0,
                          (rig.cameras[0].cam_from_rig * point.position).normalized()});
    keyframe.points.push_back(point);
  }
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() /
      ("omni_colmap_model_colours_test_" + std::to_string(::getpid()));
  auto colours_written = [&](const std::vector<Eigen::Matrix<uint8_t, 3, 1>>& colours) {
    WriteColmapTextModel(
        rig, {keyframe}, [](int, int) { return std::string("a.png"); }, folder, colours);
    std::ifstream points(folder / "points3D.txt");
    std::string line;
    std::vector<Eigen::Vector3i> rgb;
    while (std::getline(points, line)) {
      if (line.empty() || line[0] == '#') continue;
      std::istringstream in(line);
      long id;
      double x, y, z;
      Eigen::Vector3i c;
      EXPECT_TRUE(in >> id >> x >> y >> z >> c[0] >> c[1] >> c[2]) << line;
      rgb.push_back(c);
    }
    return rgb;
  };
  const std::vector<Eigen::Vector3i> coloured = colours_written({{10, 200, 30}, {255, 0, 7}});
  ASSERT_EQ(coloured.size(), 2u);
  EXPECT_EQ(coloured[0], Eigen::Vector3i(10, 200, 30));
  EXPECT_EQ(coloured[1], Eigen::Vector3i(255, 0, 7));
  const std::vector<Eigen::Vector3i> grey = colours_written({});
  ASSERT_EQ(grey.size(), 2u);
  EXPECT_EQ(grey[1], Eigen::Vector3i(128, 128, 128));
  std::filesystem::remove_all(folder);
}

// frame_rays.txt: a point of points3D.txt with rays of frames between keyframes is listed under
// its POINT3D_ID, a frame point under 0, each ray with its frame's image name and centre; a point
// without a frame ray, or one left out of points3D.txt, is not. A model without frame rays
// removes an earlier frame_rays.txt.
TEST(ColmapModel, WritesTheFrameRaysBesideTheModel) {
  const Rig rig = MakeSyntheticRingRig(1, false, 0.1);
  FinalizedKeyframe keyframe;
  keyframe.keyframe = 0;
  keyframe.frame = 4;
  auto observed = [&](double y) {
    FinalizedPoint point;
    point.position = Eigen::Vector3d(3.0, y, 0.1);
    point.rays.push_back({0, Eigen::Vector3d::Zero(), 0,
                          (rig.cameras[0].cam_from_rig * point.position).normalized()});
    return point;
  };
  keyframe.points.push_back(observed(-0.5));  // no frame ray
  keyframe.points.push_back(observed(0.5));
  keyframe.points.back().frame_rays.push_back({0, 5, 0, Eigen::Vector3d(0.1, 0.2, 0.3)});
  keyframe.points.back().frame_rays.push_back({0, 6, 0, Eigen::Vector3d(0.2, 0.2, 0.3)});
  FinalizedPoint behind = observed(0.0);  // behind the camera: not in points3D.txt
  behind.position = Eigen::Vector3d(-3.0, 0.0, 0.1);
  behind.rays[0].bearing = -Eigen::Vector3d::UnitZ();
  behind.frame_rays.push_back({0, 5, 0, Eigen::Vector3d::Zero()});
  keyframe.points.push_back(behind);
  FinalizedPoint frame_point;
  frame_point.frame_point = true;
  frame_point.position = Eigen::Vector3d(2.0, 1.0, 0.5);
  frame_point.frame_rays.push_back({0, 7, 0, Eigen::Vector3d(0.4, 0.0, 0.0)});
  keyframe.points.push_back(frame_point);
  const std::filesystem::path folder =
      std::filesystem::temp_directory_path() /
      ("omni_colmap_model_frame_rays_test_" + std::to_string(::getpid()));
  const auto name = [](int frame, int camera) {
    return "images/cam" + std::to_string(camera) + "/" + std::to_string(frame) + ".png";
  };
  const ColmapModelStats stats = WriteColmapTextModel(rig, {keyframe}, name, folder,
                                                      {{1, 1, 1}, {2, 2, 2}, {3, 3, 3}, {4, 5, 6}});
  EXPECT_EQ(stats.points, 2);
  EXPECT_EQ(stats.frame_ray_points, 2);
  const ColmapModel model = ReadColmapModel(folder);
  ASSERT_EQ(model.points.size(), 2u);
  ASSERT_EQ(model.frame_rays.size(), 2u);
  const ColmapFrameRayPoint& map_point = model.frame_rays[0];
  EXPECT_EQ(map_point.point3d_id, model.points[1].id);
  EXPECT_LT((model.points[1].xyz - Eigen::Vector3d(3.0, 0.5, 0.1)).norm(), 1e-9);
  EXPECT_LT((map_point.xyz - Eigen::Vector3d(3.0, 0.5, 0.1)).norm(), 1e-9);
  EXPECT_EQ(map_point.color, Rgb8(2, 2, 2));
  ASSERT_EQ(map_point.rays.size(), 2u);
  EXPECT_EQ(map_point.rays[1].image_name, "images/cam0/6.png");
  EXPECT_LT((map_point.rays[1].centre - Eigen::Vector3d(0.2, 0.2, 0.3)).norm(), 1e-9);
  const ColmapFrameRayPoint& frame = model.frame_rays[1];
  EXPECT_EQ(frame.point3d_id, 0u);
  EXPECT_LT((frame.xyz - Eigen::Vector3d(2.0, 1.0, 0.5)).norm(), 1e-9);
  EXPECT_EQ(frame.color, Rgb8(4, 5, 6));
  ASSERT_EQ(frame.rays.size(), 1u);
  EXPECT_EQ(frame.rays[0].image_name, "images/cam0/7.png");

  keyframe.points.resize(1);
  WriteColmapTextModel(rig, {keyframe}, name, folder);
  EXPECT_FALSE(std::filesystem::exists(folder / "frame_rays.txt"));
  EXPECT_TRUE(ReadColmapModel(folder).frame_rays.empty());
  std::filesystem::remove_all(folder);
}

}  // namespace
}  // namespace omni
