// `omnisculpt surface --colmap`: a COLMAP text model written by hand (a rig of two
// cameras driving through a closed room, points on its walls) is grouped into one keyframe per
// rig frame, its tracks become rays, and the command sculpts a closed oriented 2-manifold
// (surface_closed.ply) and its observed part (surface.ply), coloured by the model's RGB.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "pipeline/colmap_keyframes.h"
#include "calib/error.h"
#include "calib/mesh_check.h"
#include "calib/ply.h"

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
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omni
