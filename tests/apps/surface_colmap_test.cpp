// `omnisculpt surface --colmap`: a COLMAP text model written by hand (a rig of two
// cameras driving through a closed room, points on its walls) is grouped into one keyframe per
// rig frame, its tracks become rays, and the command sculpts a closed oriented 2-manifold
// (surface_closed.ply) and its observed part (surface.ply), coloured by the model's RGB; with
// --drive it writes the keyframes' rig poses (poses.tum) as the truth; --method advancing-front
// meshes the same points on the room's walls.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "calib/error.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "pipeline/colmap_keyframes.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

constexpr int kFrames = 10;
// Camera c of frame f: two cameras 0.6 m apart across the room, frames 1 m apart along x.
Eigen::Vector3d CameraCentre(int f, int c) { return Eigen::Vector3d(f, c == 0 ? -0.3 : 0.3, 2.0); }

struct Observation {
  Eigen::Vector3d position;
  std::vector<std::pair<int, int>> track;  // (frame, camera)
};

// Points on the walls, floor and ceiling of the room [-6, 15] x [-5, 5] x [0, 5] near each
// frame, each seen by both cameras of its frame and of up to three frames before.
std::vector<Observation> RoomPoints(uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<Observation> points;
  for (int f = 0; f < kFrames; ++f) {
    for (int i = 0; i < 150; ++i) {
      Observation o;
      const double x = f - 3.0 + 7.0 * u(rng), y = -5.0 + 10.0 * u(rng), z = 5.0 * u(rng);
      const double face = u(rng);
      if (face < 0.25) {
        o.position = {x, -5.0, z};
      } else if (face < 0.5) {
        o.position = {x, 5.0, z};
      } else if (face < 0.75) {
        o.position = {x, y, 0.0};
      } else {
        o.position = {x, y, 5.0};
      }
      if (f == 0 && u(rng) < 0.3) o.position = {-6.0, y, z};  // the room's end walls
      if (f == kFrames - 1 && u(rng) < 0.3) o.position = {15.0, y, z};
      for (int g = std::max(0, f - 3); g <= f; ++g) {
        o.track.emplace_back(g, 0);
        o.track.emplace_back(g, 1);
      }
      points.push_back(o);
    }
  }
  return points;
}

// Writes the model; rig: names "cam<c>/<frame>.png", otherwise "img<id>.png".
void WriteModel(const fs::path& folder, const std::vector<Observation>& points, bool rig) {
  fs::create_directories(folder);
  std::ofstream cameras(folder / "cameras.txt");
  cameras << "# Camera list\n1 SIMPLE_PINHOLE 640 480 500 320 240\n";
  std::ofstream images(folder / "images.txt");
  images << "# Image list with two lines of data per image\n";
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  auto image_id = [](int f, int c) { return 1 + 2 * f + c; };
  for (int f = 0; f < kFrames; ++f) {
    for (int c = 0; c < 2; ++c) {
      // cam_from_world: x_cam = R x_world + t, so t = -R C.
      const Eigen::Vector3d t = -(q.toRotationMatrix() * CameraCentre(f, c));
      char name[64];
      if (rig) {
        std::snprintf(name, sizeof(name), "cam%d/%06d.png", c, f);
      } else {
        std::snprintf(name, sizeof(name), "img%d.png", image_id(f, c));
      }
      images.precision(17);
      images << image_id(f, c) << " " << q.w() << " " << q.x() << " " << q.y() << " " << q.z()
             << " " << t.x() << " " << t.y() << " " << t.z() << " 1 " << name << "\n\n";
    }
  }
  std::ofstream out(folder / "points3D.txt");
  out << "# 3D point list\n";
  out.precision(17);
  for (size_t i = 0; i < points.size(); ++i) {
    const Eigen::Vector3d& p = points[i].position;
    // Each point's RGB from its index, so that the surfaces' vertex colours can be told apart.
    out << i + 1 << " " << p.x() << " " << p.y() << " " << p.z() << " " << (i % 256) << " "
        << ((i / 256) % 256) << " 77 0.5";
    for (const auto& [f, c] : points[i].track) out << " " << image_id(f, c) << " 0";
    out << "\n";
  }
}

fs::path TempFolder(const std::string& name) {
  const fs::path path = fs::temp_directory_path() /
                        ("omni_surface_colmap_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(path);
  return path;
}

TEST(ColmapKeyframes, ImagesOfARigFrameFormOneKeyframeAndTracksGiveRays) {
  const fs::path dir = TempFolder("reader");
  const std::vector<Observation> points = RoomPoints(3);
  WriteModel(dir / "rig", points, true);
  WriteModel(dir / "single", points, false);

  const std::vector<SurfaceKeyframe> rig = LoadColmapKeyframes(dir / "rig");
  ASSERT_EQ(rig.size(), static_cast<size_t>(kFrames));
  size_t total = 0;
  for (int f = 0; f < kFrames; ++f) {
    EXPECT_EQ(rig[f].id.value, static_cast<uint32_t>(f));
    EXPECT_LT((rig[f].centre - 0.5 * (CameraCentre(f, 0) + CameraCentre(f, 1))).norm(), 1e-9);
    EXPECT_EQ(rig[f].points.size(), 150u);  // each point in the latest keyframe of its track
    for (const SurfacePoint& p : rig[f].points) {
      const Observation& o = points[p.id.value - 1];
      EXPECT_LT((p.position - o.position).norm(), 1e-12);
      ASSERT_EQ(p.rays.size(), o.track.size());
      for (size_t k = 0; k < p.rays.size(); ++k) {
        const auto [g, c] = o.track[k];
        EXPECT_EQ(p.rays[k].keyframe.value, static_cast<uint32_t>(g));
        EXPECT_LT((p.rays[k].origin - CameraCentre(g, c)).norm(), 1e-9);
      }
    }
    total += rig[f].points.size();
  }
  EXPECT_EQ(total, points.size());
  // Names sharing no frame: one keyframe per image.
  EXPECT_EQ(LoadColmapKeyframes(dir / "single").size(), static_cast<size_t>(2 * kFrames));
  // A missing model is an InputError.
  EXPECT_THROW(LoadColmapKeyframes(dir / "missing"), InputError);
  fs::remove_all(dir);
}

TEST(ColmapKeyframes, SurfaceCommandSculptsAClosedManifoldFromAModel) {
  const fs::path dir = TempFolder("command");
  WriteModel(dir / "model", RoomPoints(5), true);
  const fs::path out = dir / "out";
  const std::string command = std::string("'") + OMNI_EXECUTABLE + "' --quiet surface --colmap '" +
                              (dir / "model").string() + "' --out '" + out.string() +
                              "' --no-batch --init-keyframes 4 >'" + (dir / "stdout.txt").string() +
                              "' 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream log_stream(dir / "stdout.txt");
  std::stringstream log;
  log << log_stream.rdbuf();
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << log.str();
  EXPECT_NE(log.str().find("surface: 10 keyframes"), std::string::npos) << log.str();
  const TriangleMesh closed = ReadPlyMesh(out / "surface_closed.ply");
  EXPECT_GT(closed.triangles.size(), 200u);
  const MeshCheckReport report = CheckMesh(closed);
  EXPECT_TRUE(report.ok) << report.ToText();
  // surface.ply: the observed part, bounded, its vertices coloured by points3D.txt's RGB (blue
  // 77 for every point; the Steiner vertices of the closed one are grey).
  const TriangleMesh mesh = ReadPlyMesh(out / "surface.ply");
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  const MeshCheckReport observed = CheckMesh(mesh, bounded);
  EXPECT_TRUE(observed.ok) << observed.ToText();
  EXPECT_GT(mesh.triangles.size(), 100u);
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  for (const Rgb8& color : mesh.colors) EXPECT_EQ(color[2], 77);
  ASSERT_EQ(closed.colors.size(), closed.vertices.size());
  for (const Rgb8& color : closed.colors) {
    EXPECT_TRUE(color[2] == 77 || color == Rgb8(128, 128, 128));
  }
  // An SfM's points are sculpted as reconstruct sculpts its own: the surface written is a final
  // batch (sculpted alone: no keyframe-by-keyframe times), with the rays of the points the
  // aperture bound drops; --no-final-batch and a zero margin give the keyframe-by-keyframe
  // surface of the paper.
  const nlohmann::json summary = nlohmann::json::parse(std::ifstream(out / "surface.json"));
  EXPECT_TRUE(summary["final_batch"]["ran"].get<bool>()) << summary.dump(2);
  EXPECT_TRUE(summary["ms_median"].is_null()) << summary.dump(2);
  EXPECT_GT(summary["uncertain_rays"].get<size_t>(), 0u) << summary.dump(2);
  const fs::path paper = dir / "paper";
  const std::string paper_command =
      std::string("'") + OMNI_EXECUTABLE + "' --quiet surface --colmap '" +
      (dir / "model").string() + "' --out '" + paper.string() +
      "' --no-batch --init-keyframes 4 --no-final-batch --uncertain-ray-margin 0 >'" +
      (dir / "stdout.txt").string() + "' 2>&1";
  ASSERT_EQ(std::system(paper_command.c_str()), 0);
  const nlohmann::json paper_summary = nlohmann::json::parse(std::ifstream(paper / "surface.json"));
  EXPECT_FALSE(paper_summary["final_batch"]["ran"].get<bool>());
  EXPECT_TRUE(paper_summary["ms_median"].is_number());
  EXPECT_EQ(paper_summary["uncertain_rays"].get<size_t>(), 0u);
  EXPECT_EQ(paper_summary["points_filtered_aperture"], summary["points_filtered_aperture"]);
  EXPECT_TRUE(CheckMesh(ReadPlyMesh(paper / "surface_closed.ply")).ok);
  fs::remove_all(dir);
}

// Runs omnisculpt with `arguments`; returns its exit status and its output in *log.
int RunOmnisculpt(const fs::path& dir, const std::string& arguments, std::string* log) {
  const std::string command = std::string("'") + OMNI_EXECUTABLE + "' --quiet " + arguments +
                              " >'" + (dir / "stdout.txt").string() + "' 2>&1";
  const int status = std::system(command.c_str());
  std::ifstream log_stream(dir / "stdout.txt");
  std::stringstream text;
  text << log_stream.rdbuf();
  *log = text.str();
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// A drive of the room model's rig: rig.json (the two cameras 0.6 m apart on the rig's y axis,
// looking as the rig does) and an image file per camera and frame (never read).
void WriteRoomDrive(const fs::path& drive) {
  Rig rig;
  for (int c = 0; c < 2; ++c) {
    Camera camera;
    camera.name = "cam" + std::to_string(c);
    camera.width = 640;
    camera.height = 480;
    camera.params = {500, 500, 320, 240};
    camera.cam_from_rig.translation = -Eigen::Vector3d(0.0, c == 0 ? -0.3 : 0.3, 0.0);
    rig.cameras.push_back(camera);
    fs::create_directories(drive / "images" / camera.name);
    for (int f = 0; f < kFrames; ++f) {
      char name[32];
      std::snprintf(name, sizeof(name), "%06d.png", f);
      std::ofstream(drive / "images" / camera.name / name) << "x";
    }
  }
  WriteRigJson(rig, drive / "rig.json");
}

TEST(ColmapKeyframes, SurfaceCommandWritesTheKeyframesRigPosesOfADrive) {
  const fs::path dir = TempFolder("poses");
  WriteModel(dir / "model", RoomPoints(5), true);
  WriteRoomDrive(dir / "drive");
  const fs::path out = dir / "out";
  std::string log;
  ASSERT_EQ(RunOmnisculpt(dir,
                          "surface --colmap '" + (dir / "model").string() + "' --drive '" +
                              (dir / "drive").string() + "' --out '" + out.string() +
                              "' --no-batch --init-keyframes 4",
                          &log),
            0)
      << log;
  const std::vector<StampedPose> poses = ReadTum(out / "poses.tum");
  ASSERT_EQ(poses.size(), static_cast<size_t>(kFrames));
  // The model's cameras: cam_from_world rotation q for both, centres CameraCentre(f, c).
  const Eigen::Quaterniond q(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized()));
  for (int f = 0; f < kFrames; ++f) {
    EXPECT_NEAR(poses[f].timestamp, f / 15.0, 1e-6);  // frame index / 15, as `sfm` stamps
    EXPECT_LT(poses[f].world_from_rig.rotation.angularDistance(q.conjugate()), 1e-6) << f;
    EXPECT_LT((poses[f].world_from_rig.translation - Eigen::Vector3d(f, 0.0, 2.0)).norm(), 1e-6)
        << f;
  }
  // A model of images the drive does not have is refused, naming the frame.
  fs::remove(dir / "drive" / "images" / "cam0" / "000009.png");
  fs::remove(dir / "drive" / "images" / "cam1" / "000009.png");
  ASSERT_NE(
      RunOmnisculpt(dir,
                    "surface --colmap '" + (dir / "model").string() + "' --drive '" +
                        (dir / "drive").string() + "' --out '" + (dir / "out2").string() + "'",
                    &log),
      0);
  EXPECT_NE(log.find("the model's frame '000009' is not a frame of the drive"), std::string::npos)
      << log;
  fs::remove_all(dir);
}

TEST(ColmapKeyframes, AdvancingFrontMeshesTheModelsPointsOnTheRoomsWalls) {
  const fs::path dir = TempFolder("advancing_front");
  const std::vector<Observation> points = RoomPoints(5);
  WriteModel(dir / "model", points, true);
  const fs::path out = dir / "out";
  std::string log;
  ASSERT_EQ(RunOmnisculpt(dir,
                          "surface --colmap '" + (dir / "model").string() +
                              "' --method advancing-front --out '" + out.string() + "'",
                          &log),
            0)
      << log;
  EXPECT_FALSE(fs::exists(out / "surface_closed.ply"));
  const TriangleMesh mesh = ReadPlyMesh(out / "surface.ply");
  ASSERT_GT(mesh.triangles.size(), 500u);
  // Its vertices are the model's points (coloured by their RGB), its triangles on the walls:
  // the three vertices on one face of the room, but for the few that cut a corner.
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    bool found = false;
    for (const Observation& o : points)
      found = found || (o.position - mesh.vertices[i]).norm() < 1e-5;  // PLY floats
    ASSERT_TRUE(found) << "vertex " << i << " is not a point of the model";
    EXPECT_EQ(mesh.colors[i][2], 77);
  }
  // A triangle lies on the room when its centroid does (the distance to the nearest wall): those
  // across a corner of the room are off by a fraction of the points' spacing (0.7 m; up to 1.2 m
  // in the room's corners), one across the room by metres.
  auto off_the_walls = [](const Eigen::Vector3d& p) {
    const double planes[6] = {-6.0, 15.0, -5.0, 5.0, 0.0, 5.0};
    double distance = 1e9;
    for (int face = 0; face < 6; ++face)
      distance = std::min(distance, std::abs(p[face / 2] - planes[face]));
    return distance;
  };
  size_t on_the_walls = 0, near_the_walls = 0;
  double worst = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const double off =
        off_the_walls((mesh.vertices[t[0]] + mesh.vertices[t[1]] + mesh.vertices[t[2]]) / 3.0);
    worst = std::max(worst, off);
    on_the_walls += off < 1e-5 ? 1 : 0;
    near_the_walls += off < 0.35 ? 1 : 0;
  }
  EXPECT_GT(on_the_walls, 0.85 * mesh.triangles.size())
      << on_the_walls << " of " << mesh.triangles.size();
  EXPECT_GT(near_the_walls, 0.98 * mesh.triangles.size())
      << near_the_walls << " of " << mesh.triangles.size() << ", worst " << worst << " m";
  EXPECT_LT(worst, 2.5);  // none across the room (10 m wide, 5 m high)
  EXPECT_NE(log.find("surface: advancing front"), std::string::npos) << log;
  // --af-points sculpted: the points the sculptor inserts, as many as its run says it added.
  ASSERT_EQ(RunOmnisculpt(dir,
                          "surface --colmap '" + (dir / "model").string() + "' --out '" +
                              (dir / "sculptor").string() + "'",
                          &log),
            0)
      << log;
  ASSERT_EQ(RunOmnisculpt(dir,
                          "surface --colmap '" + (dir / "model").string() +
                              "' --method advancing-front --af-points sculpted --out '" +
                              (dir / "sculpted").string() + "'",
                          &log),
            0)
      << log;
  const nlohmann::json sculptor =
      nlohmann::json::parse(std::ifstream(dir / "sculptor" / "surface.json"));
  const nlohmann::json sculpted =
      nlohmann::json::parse(std::ifstream(dir / "sculpted" / "surface.json"));
  const size_t added = sculptor.at("points_added").get<size_t>();
  EXPECT_LT(added, points.size());  // the filters removed some
  EXPECT_EQ(sculpted.at("points").get<size_t>(), added);
  EXPECT_EQ(sculpted.at("points_from").get<std::string>(), "sculpted");
  EXPECT_LE(ReadPlyMesh(dir / "sculpted" / "surface.ply").vertices.size(), added);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omni
