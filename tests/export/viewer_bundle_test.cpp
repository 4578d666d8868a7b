// WriteViewer (export/viewer_bundle.h) on a small reconstruction folder made here: which mesh
// of a snapshot the viewer shows, whether the map moved after the snapshot or not.

#include "export/viewer_bundle.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "calib/ply.h"
#include "calib/tum.h"
#include "tests/calib/io_temp_dir.h"
#include "tests/export/strict_glb_reader.h"
#include "tests/export/viewer_data.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

// Four triangles of a square fan around (0, 0, 0), shifted by `offset`, with or without colours.
TriangleMesh SquareFan(const Eigen::Vector3d& offset, bool colored) {
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {-1, 0, 0}, {0, -1, 0}};
  for (Eigen::Vector3d& v : mesh.vertices) v += offset;
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}, {0, 4, 1}};
  if (colored) mesh.colors.assign(mesh.vertices.size(), Rgb8(200, 30, 40));
  return mesh;
}

// A reconstruction folder whose final points are at the vertices of SquareFan(0), and whose map
// moved by 10 (many times the colour radius) after the snapshot of keyframe 3: that snapshot
// lies 10 away from every final point. Keyframe 1's snapshot did not move, but only its closed
// δO exists, with one vertex (a Steiner vertex) far from every point.
class ViewerBundleTest : public ::testing::Test {
 protected:
  void SetUp() override {
    fs::create_directories(rec_ / "snapshots");
    WritePlyMesh(SquareFan(Eigen::Vector3d::Zero(), true), rec_ / "surface.ply");
    std::vector<StampedPose> poses(5);
    for (size_t k = 0; k < poses.size(); ++k) {
      poses[k].timestamp = static_cast<double>(k);
      poses[k].world_from_rig.translation = Eigen::Vector3d(static_cast<double>(k), 0, 2);
    }
    WriteTum(poses, rec_ / "poses.tum");
    PointCloud points;
    points.points = SquareFan(Eigen::Vector3d::Zero(), false).vertices;
    points.colors.assign(points.points.size(), Rgb8(10, 220, 30));
    WritePlyPoints(points, rec_ / "points.ply");
    TriangleMesh closed_1 = SquareFan(Eigen::Vector3d::Zero(), false);
    closed_1.vertices[3] = Eigen::Vector3d(-20, 0, 0);
    WritePlyMesh(closed_1, rec_ / "snapshots" / "surface_1.ply");
    const Eigen::Vector3d moved(10, 0, 0);
    WritePlyMesh(SquareFan(moved, false), rec_ / "snapshots" / "surface_3.ply");
    TriangleMesh observed_3 = SquareFan(moved, true);
    observed_3.triangles.pop_back();  // the observed part: three of the four triangles
    WritePlyMesh(observed_3, rec_ / "snapshots" / "observed_3.ply");
    options_.assets = fs::path(OMNI_EXECUTABLE).parent_path() / "viewer_assets";
  }

  nlohmann::json Scene() const {
    return testing::ScriptValue(rec_ / "viewer" / "data" / "scene.js");
  }
  testing::GlbPrimitive SnapshotGlb(const nlohmann::json& snapshot) const {
    const testing::GlbContent glb = testing::ReadGlbStrictly(testing::Base64Decoded(
        testing::ScriptValue(rec_ / "viewer" / snapshot["file"].get<std::string>())
            .get<std::string>()));
    EXPECT_EQ(glb.error, "");
    return glb.meshes.at("surface");
  }

  testing::TempDir dir_;
  fs::path rec_ = dir_ / "rec";
  ViewerOptions options_;
};

TEST_F(ViewerBundleTest, ShowsTheObservedSnapshotWholeFarFromTheFinalPoints) {
  const ViewerSummary summary = WriteViewer(rec_, options_);
  EXPECT_EQ(summary.snapshots, 2u);
  const nlohmann::json scene = Scene();
  ASSERT_EQ(scene["snapshots"].size(), 2u);
  const nlohmann::json& moved = scene["snapshots"][1];
  EXPECT_EQ(moved["keyframe"].get<long>(), 3);
  EXPECT_TRUE(moved["observed"].get<bool>());
  EXPECT_EQ(moved["triangles"].get<size_t>(), 3u);
  // The observed snapshot as it is: its vertices, triangles and colours.
  testing::ExpectSameMesh(SnapshotGlb(moved), ReadPlyMesh(rec_ / "snapshots" / "observed_3.ply"));
}

// A folder without the observed snapshot of a keyframe (written before they existed): its
// closed δO without the triangles that have a vertex away from every final point, coloured as
// the nearest final point.
TEST_F(ViewerBundleTest, WithoutTheObservedSnapshotKeepsTheClosedTrianglesNearTheFinalPoints) {
  const ViewerSummary summary = WriteViewer(rec_, options_);
  EXPECT_EQ(summary.snapshots, 2u);
  const nlohmann::json scene = Scene();
  ASSERT_EQ(scene["snapshots"].size(), 2u);
  const nlohmann::json& closed_only = scene["snapshots"][0];
  EXPECT_EQ(closed_only["keyframe"].get<long>(), 1);
  EXPECT_FALSE(closed_only["observed"].get<bool>());
  EXPECT_EQ(closed_only["closed_triangles"].get<size_t>(), 4u);
  EXPECT_EQ(closed_only["triangles"].get<size_t>(), 2u);  // the two without vertex 3
  const testing::GlbPrimitive glb = SnapshotGlb(closed_only);
  EXPECT_EQ(glb.positions.size(), 4u);
  for (const Eigen::Vector3i& color : glb.colors) EXPECT_EQ(color, Eigen::Vector3i(10, 220, 30));

  // Without observed_3.ply, keyframe 3's closed δO is 10 away from every final point: nothing
  // of it is left, and the viewer has no snapshot of it.
  fs::remove(rec_ / "snapshots" / "observed_3.ply");
  EXPECT_EQ(WriteViewer(rec_, options_).snapshots, 1u);
  EXPECT_EQ(Scene()["snapshots"][0]["keyframe"].get<long>(), 1);
}

}  // namespace
}  // namespace omni
