#pragma once
// A small hand-made drive and reconstruction for the evaluation's tests: a ring rig of four
// cameras, a street of boxes, ground-truth poses, and a reconstruction related to them by a
// similarity (the eval report's tests and the eval command's).

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "eval/primitives.h"
#include "eval/report.h"

namespace omni::testing {

namespace fs = std::filesystem;

inline Rig MakeRig() {
  Rig rig;
  rig.name = "ring";
  for (int k = 0; k < 4; ++k) {
    Camera camera;
    camera.name = "cam" + std::to_string(k);
    camera.width = 48;
    camera.height = 32;
    camera.params = {24.0, 24.0, 23.5, 15.5};
    Eigen::Matrix3d rig_from_cam;
    rig_from_cam << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    rig_from_cam = Eigen::AngleAxisd(k * M_PI / 2, Eigen::Vector3d::UnitZ()) * rig_from_cam;
    camera.cam_from_rig.rotation = Eigen::Quaterniond(rig_from_cam.transpose());
    camera.cam_from_rig.translation = -(rig_from_cam.transpose() * (0.05 * rig_from_cam.col(2)));
    rig.cameras.push_back(camera);
  }
  return rig;
}

// A street: ground, two rows of blocks, closed by a big box around (normals towards the drive).
inline TriangleMesh MakeStreet() {
  TriangleMesh mesh = FlipOrientation(MakeBox({-20, -20, -1}, {80, 20, 30}));
  for (int i = 0; i < 5; ++i) {
    AppendMesh(MakeBox({i * 12.0, 6, -1}, {i * 12.0 + 9, 12, 8.0 + i}), &mesh);
    AppendMesh(MakeBox({i * 12.0 + 3, -12, -1}, {i * 12.0 + 11, -6, 10.0 - i}), &mesh);
  }
  return mesh;
}

// MakeStreet's triangles labelled 0 (the enclosure), 1 (a north block) and 2 (a south block),
// and the names of the labels as gt/scene.json gives them.
inline std::vector<uint8_t> StreetLabels() {
  std::vector<uint8_t> labels(12, 0);
  for (int i = 0; i < 5; ++i) {
    labels.insert(labels.end(), 12, 1);
    labels.insert(labels.end(), 12, 2);
  }
  return labels;
}
inline const char* kStreetLabelsJson = R"({"mesh_labels": ["enclosure", "north", "south"]})";

// MakeStreet without its north row of blocks.
inline TriangleMesh StreetWithoutNorthRow() {
  TriangleMesh mesh = FlipOrientation(MakeBox({-20, -20, -1}, {80, 20, 30}));
  for (int i = 0; i < 5; ++i) {
    AppendMesh(MakeBox({i * 12.0 + 3, -12, -1}, {i * 12.0 + 11, -6, 10.0 - i}), &mesh);
  }
  return mesh;
}

inline std::vector<StampedPose> MakeGtPoses(int frames) {
  std::vector<StampedPose> poses;
  for (int f = 0; f < frames; ++f) {
    StampedPose pose;
    pose.timestamp = f / 15.0;
    pose.world_from_rig.translation = Eigen::Vector3d(0.5 * f, 0.3 * std::sin(0.05 * f), 2.0);
    pose.world_from_rig.rotation =
        Eigen::AngleAxisd(0.02 * std::sin(0.1 * f), Eigen::Vector3d::UnitZ());
    poses.push_back(pose);
  }
  return poses;
}

class EvalTest : public ::testing::Test {
 protected:
  void SetUp() override {
    root_ = fs::temp_directory_path() /
            ("omni_eval_test_" +
             std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(root_);
    drive_ = root_ / "drive";
    rec_ = root_ / "rec";
    fs::create_directories(drive_ / "gt");
    fs::create_directories(rec_ / "stats");
    WriteRigJson(MakeRig(), drive_ / "rig.json");
    gt_poses_ = MakeGtPoses(120);
    WriteTum(gt_poses_, drive_ / "gt" / "poses.tum");
    gt_mesh_ = MakeStreet();
    WritePlyMesh(gt_mesh_, drive_ / "gt" / "mesh.ply");
  }
  void TearDown() override { fs::remove_all(root_); }

  // The reconstruction: every 4th frame, in a world frame related to GT by a similarity.
  void WriteReconstruction(const Sim3d& estimated_from_gt, const TriangleMesh& gt_frame_surface) {
    std::vector<StampedPose> keyframes;
    for (size_t f = 0; f < gt_poses_.size(); f += 4) {
      StampedPose pose = gt_poses_[f];
      pose.world_from_rig = TransformPose(estimated_from_gt, pose.world_from_rig);
      keyframes.push_back(pose);
    }
    WriteTum(keyframes, rec_ / "poses.tum");
    TriangleMesh surface = gt_frame_surface;
    for (auto& v : surface.vertices) v = estimated_from_gt * v;
    WritePlyMesh(surface, rec_ / "surface.ply");
    PointCloud cloud;
    for (const auto& v : gt_frame_surface.vertices) cloud.points.push_back(estimated_from_gt * v);
    WritePlyPoints(cloud, rec_ / "points.ply");
    std::ofstream(rec_ / "stats" / "keyframes.csv")
        << "keyframe,points_in,E,enclose_ms,grow_ms\n0,10,1000,1.5,2.0\n1,12,1100,1.7,2.2\n"
           "2,9,1050,1.6,2.1\n";
  }

  static EvalOptions SmallOptions() {
    EvalOptions options;
    options.ray_errors.pixels = 20000;
    options.surfaces.samples = 20000;
    options.surfaces.visibility_rays = 50000;
    options.render_width = 200;
    options.keyframe_views = 2;
    return options;
  }

  fs::path root_, drive_, rec_;
  std::vector<StampedPose> gt_poses_;
  TriangleMesh gt_mesh_;
};

inline const Sim3d kEstimatedFromGt(
    0.2, Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d(0.2, 0.3, 1).normalized())),
    Eigen::Vector3d(3, -4, 1));

}  // namespace omni::testing
