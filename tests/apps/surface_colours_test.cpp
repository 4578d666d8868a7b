// Vertex colours on a drive with coloured walls (`synth --colour`): each vertex of the observed
// surface (surface.ply, as `surface --from-gt` writes it) carries, within rounding, the mean
// colour of the keyframe images where its point is seen: over the rays' keyframes, every camera
// whose image the point projects into, the bilinear pixel there (recomputed here from the PNGs).
// Walls come out coloured, not grey.

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <unordered_map>
#include <vector>

#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "pipeline/gt_keyframes.h"
#include "surface/sculptor.h"
#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

TEST(SurfaceColours, VertexColoursAreTheImagesMeanOnADriveWithColouredWalls) {
  const fs::path dir =
      fs::temp_directory_path() / ("omni_surface_colours_test_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const fs::path drive = dir / "drive";
  const testing::CommandResult made =
      testing::RunOmnisculpt({"--quiet", "synth", "--preset", "tiny", "--frames", "10", "--colour",
                              "--out", drive.string()},
                             dir);
  ASSERT_EQ(made.exit_code, 0) << made.err;

  // The stream and its colours as `surface --from-gt` makes them.
  std::vector<StampedPose> poses;
  std::vector<size_t> frames;
  const std::vector<SurfaceKeyframe> stream =
      LoadGtKeyframes(drive, GtKeyframeOptions(), nullptr, &poses, &frames);
  ASSERT_GE(stream.size(), 4u);
  const std::unordered_map<PointId, Rgb8> colors = GtPointColors(drive, stream, frames);
  SculptorOptions options;
  options.init_keyframes = 4;
  options.smoothing.enabled = false;
  IncrementalSculptor sculptor(options);
  for (const SurfaceKeyframe& kf : stream) sculptor.AddKeyframe(kf);
  sculptor.Finish();
  std::vector<PointId> vertex_points;
  TriangleMesh observed = sculptor.ExtractObservedMesh(&vertex_points);
  ColorMeshVertices(vertex_points, colors, &observed);
  WritePlyMesh(observed, dir / "surface.ply");
  const TriangleMesh mesh = ReadPlyMesh(dir / "surface.ply");
  ASSERT_GT(mesh.triangles.size(), 100u);
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  ASSERT_EQ(vertex_points.size(), mesh.vertices.size());

  // The expected colour of each point, from the PNGs: OpenCV's BGR, bilinear at the pixel.
  const Rig rig = ReadRigJson(drive / "rig.json");
  std::map<std::pair<size_t, size_t>, cv::Mat> images;  // (frame, camera)
  auto image = [&](size_t frame, size_t camera) -> const cv::Mat& {
    cv::Mat& m = images[{frame, camera}];
    if (m.empty()) {
      char name[32];
      std::snprintf(name, sizeof(name), "%06zu.png", frame);
      m = cv::imread((drive / "images" / rig.cameras[camera].name / name).string(),
                     cv::IMREAD_COLOR);
    }
    return m;
  };
  std::unordered_map<uint32_t, size_t> index_of;
  for (size_t t = 0; t < stream.size(); ++t) index_of[stream[t].id.value] = t;
  std::unordered_map<PointId, Eigen::Vector3d> expected;
  for (const SurfaceKeyframe& kf : stream) {
    for (const SurfacePoint& p : kf.points) {
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      int count = 0;
      for (const SurfaceRay& ray : p.rays) {
        const size_t t = index_of.at(ray.keyframe.value);
        const Rigid3d rig_from_world = poses[t].world_from_rig.Inverse();
        for (size_t c = 0; c < rig.NumCameras(); ++c) {
          const Eigen::Vector3d in_camera =
              rig.cameras[c].cam_from_rig * (rig_from_world * p.position);
          Eigen::Vector2d px;
          if (!rig.cameras[c].Project(in_camera.normalized(), &px) ||
              !rig.cameras[c].IsInImage(px)) {
            continue;
          }
          const cv::Mat& m = image(frames[t], c);
          EXPECT_EQ(m.type(), CV_8UC3);
          const double x = std::clamp(px.x(), 0.0, m.cols - 1.0);
          const double y = std::clamp(px.y(), 0.0, m.rows - 1.0);
          const int x0 = std::min(static_cast<int>(x), m.cols - 2);
          const int y0 = std::min(static_cast<int>(y), m.rows - 2);
          const double ax = x - x0, ay = y - y0;
          for (int k = 0; k < 3; ++k) {
            auto at = [&](int r, int col) { return double(m.at<cv::Vec3b>(r, col)[2 - k]); };
            sum[k] += (1 - ay) * ((1 - ax) * at(y0, x0) + ax * at(y0, x0 + 1)) +
                      ay * ((1 - ax) * at(y0 + 1, x0) + ax * at(y0 + 1, x0 + 1));
          }
          ++count;
        }
      }
      if (count > 0) expected[p.id] = sum / count;
    }
  }

  size_t checked = 0, wrong = 0, coloured = 0;
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    const auto it = expected.find(vertex_points[v]);
    ASSERT_NE(it, expected.end()) << "vertex " << v << " has no observation in an image";
    ++checked;
    const Rgb8& rgb = mesh.colors[v];
    bool ok = true;
    for (int k = 0; k < 3; ++k) ok = ok && std::abs(rgb[k] - it->second[k]) <= 0.5 + 1e-3;
    wrong += ok ? 0 : 1;
    coloured += rgb[0] != rgb[1] || rgb[1] != rgb[2] ? 1 : 0;
  }
  EXPECT_GT(checked, 100u);
  EXPECT_EQ(wrong, 0u) << "of " << checked;
  EXPECT_GT(coloured, checked / 3) << "the walls are not coloured";
  fs::remove_all(dir);
}

}  // namespace
}  // namespace omni
