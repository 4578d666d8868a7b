// `omnisculpt surface --from-gt` end to end on a short tiny synthetic drive: surface_closed.ply
// is a closed oriented 2-manifold by the independent mesh checker of calib/, surface.ply an
// oriented 2-manifold with boundary made of its triangles, of SfM points only, coloured as
// points.ply,
// stats/keyframes.csv has one row per keyframe with the documented columns, few points are
// rejected, and a missing drive is one error line with exit code 2.

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "calib/mesh_check.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "tests/apps/run_omnisculpt.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

using RunResult = testing::CommandResult;
using testing::ReadTextFile;

std::vector<std::string> Split(const std::string& text, char separator) {
  return testing::SplitText(text, separator);
}

// Every triangle of `part` is a triangle of `whole`, with the same orientation, its vertices at
// the same positions.
void ExpectTrianglesSubset(const TriangleMesh& part, const TriangleMesh& whole) {
  auto key = [](const Eigen::Vector3d& v) { return std::array<double, 3>{v.x(), v.y(), v.z()}; };
  std::map<std::array<double, 3>, int> whole_index;
  for (size_t v = 0; v < whole.vertices.size(); ++v)
    whole_index[key(whole.vertices[v])] = static_cast<int>(v);
  std::set<std::array<int, 3>> whole_triangles;
  auto canonical = [](int a, int b, int c) {
    if (b < a && b < c) return std::array<int, 3>{b, c, a};
    if (c < a && c < b) return std::array<int, 3>{c, a, b};
    return std::array<int, 3>{a, b, c};
  };
  for (const Eigen::Vector3i& t : whole.triangles)
    whole_triangles.insert(canonical(t[0], t[1], t[2]));
  size_t missing = 0;
  for (const Eigen::Vector3i& t : part.triangles) {
    int w[3];
    bool found = true;
    for (int k = 0; k < 3; ++k) {
      const auto it = whole_index.find(key(part.vertices[t[k]]));
      found = found && it != whole_index.end();
      w[k] = found ? it->second : -1;
    }
    missing += found && whole_triangles.count(canonical(w[0], w[1], w[2])) ? 0 : 1;
  }
  EXPECT_EQ(missing, 0u) << "of " << part.triangles.size();
}

class SurfaceCommandTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() { dir_ = new testing::TempDir("surface_command_test"); }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }

  static RunResult Run(const std::vector<std::string>& arguments) {
    return testing::RunOmnisculpt(arguments, dir_->path());
  }

  // A `synth --preset tiny` drive of its first `frames` frames, made in dir_/name; empty when
  // synth failed.
  static fs::path TinyDrive(const std::string& name, int frames) {
    const fs::path drive = dir_->path() / name;
    const RunResult synth = Run({"--quiet", "synth", "--preset", "tiny", "--frames",
                                 std::to_string(frames), "--out", drive.string()});
    EXPECT_EQ(synth.exit_code, 0) << synth.err;
    return synth.exit_code == 0 ? drive : fs::path();
  }

  static testing::TempDir* dir_;
};
testing::TempDir* SurfaceCommandTest::dir_ = nullptr;

// The columns of stats/keyframes.csv documented in docs/design.md §5.
const char* const kColumns =
    "keyframe,batch,points_in,points_filtered,points_added,points_rejected,points_duplicate,"
    "steiner_added,rays_new,rays_old,cells_e,cells_n,o_left_in_e,cells_t,cells_f,cells_o,"
    "triangles,ms_steiner,ms_enclose,ms_shrink,ms_insert,ms_rays,ms_grow,ms_total,"
    "genus_free_before,genus_free_after,genus_groups,genus_euler_change,smoothed_vertices,"
    "smoothing_rejected,ms_genus,ms_smooth,rays_old_candidates,old_walk_cells,ms_rays_select,"
    "ms_rays_old,points_invalid,points_filtered_ground,points_filtered_length,"
    "points_filtered_aperture,enclose_rounds,cells_e_added,cells_active,smoothing_candidates,"
    "cells_grow_extra,old_ray_facets,old_ray_facets_uncrossed,old_ray_queries,"
    "old_ray_query_voxels,old_ray_facet_tests,old_ray_plane_passes,cells_enclosed_free,"
    "ms_enclosed_free,keyframes,points_merged";

TEST_F(SurfaceCommandTest, TinyDriveGivesAClosedOrientedManifoldAndOneStatsRowPerKeyframe) {
  const fs::path drive = TinyDrive("drive", 12);
  ASSERT_FALSE(drive.empty());

  // Keyframes one by one (no batch), so that every keyframe has its own row.
  const fs::path out = dir_->path() / "surface";
  const RunResult surface =
      Run({"--quiet", "surface", "--from-gt", drive.string(), "--out", out.string(), "--no-batch",
           "--init-keyframes", "4", "--snapshot-every", "4"});
  ASSERT_EQ(surface.exit_code, 0) << surface.out << surface.err;
  std::smatch match;
  ASSERT_TRUE(std::regex_search(surface.out, match, std::regex(R"(surface: (\d+) keyframes)")))
      << surface.out;
  const int keyframes = std::stoi(match[1]);
  EXPECT_GE(keyframes, 8);

  // surface_closed.ply: δO, a closed oriented 2-manifold.
  const TriangleMesh closed = ReadPlyMesh(out / "surface_closed.ply");
  EXPECT_GT(closed.triangles.size(), 1000u);
  const MeshCheckReport report = CheckMesh(closed);
  EXPECT_TRUE(report.ok) << report.ToText();
  EXPECT_TRUE(report.closed_manifold);
  EXPECT_TRUE(report.oriented);
  EXPECT_EQ(report.boundary_edges, 0);
  // surface.ply: its observed part, an oriented 2-manifold with boundary whose triangles are
  // triangles of δO (the same vertex positions, written from the same floats).
  const TriangleMesh mesh = ReadPlyMesh(out / "surface.ply");
  EXPECT_GT(mesh.triangles.size(), closed.triangles.size() / 2);
  EXPECT_LT(mesh.triangles.size(), closed.triangles.size());
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  const MeshCheckReport observed = CheckMesh(mesh, bounded);
  EXPECT_TRUE(observed.ok) << observed.ToText();
  EXPECT_GT(observed.boundary_loops, 0);
  EXPECT_FALSE(CheckMesh(mesh).ok);  // not closed
  ExpectTrianglesSubset(mesh, closed);

  const std::vector<std::string> lines = Split(ReadTextFile(out / "stats" / "keyframes.csv"), '\n');
  ASSERT_FALSE(lines.empty());
  EXPECT_EQ(lines[0], kColumns);
  const std::vector<std::string> columns = Split(kColumns, ',');
  ASSERT_EQ(static_cast<int>(lines.size()), keyframes + 1);
  long added = 0, rejected = 0, last_id = -1, last_triangles = -1;
  std::vector<std::string> expected_snapshots;
  for (size_t i = 1; i < lines.size(); ++i) {
    const std::vector<std::string> cells = Split(lines[i], ',');
    ASSERT_EQ(cells.size(), columns.size()) << lines[i];
    auto field = [&](const char* name) {
      for (size_t k = 0; k < columns.size(); ++k) {
        if (columns[k] == name) return std::stod(cells[k]);
      }
      ADD_FAILURE() << "no column " << name;
      return 0.0;
    };
    EXPECT_GT(field("keyframe"), last_id) << "keyframe ids increase";
    last_id = static_cast<long>(field("keyframe"));
    EXPECT_EQ(field("batch"), 0.0);
    EXPECT_EQ(field("points_in"), field("points_filtered") + field("points_added") +
                                      field("points_rejected") + field("points_duplicate"));
    EXPECT_EQ(field("points_filtered"), field("points_invalid") + field("points_filtered_ground") +
                                            field("points_filtered_length") +
                                            field("points_filtered_aperture"));
    EXPECT_LE(field("cells_o"), field("cells_f"));
    EXPECT_LE(field("cells_f"), field("cells_t"));
    // E (the default: the new points' conflict zones) is empty only without points.
    if (field("points_added") > 0) {
      EXPECT_GT(field("cells_e"), 0.0);
    }
    EXPECT_GE(field("ms_total"), field("ms_rays"));
    added += static_cast<long>(field("points_added"));
    rejected += static_cast<long>(field("points_rejected"));
    last_triangles = static_cast<long>(field("triangles"));
    if (i % 4 == 0) {
      expected_snapshots.push_back("surface_" + std::to_string(last_id) + ".ply");
      expected_snapshots.push_back("observed_" + std::to_string(last_id) + ".ply");
    }
  }
  // --snapshot-every 4: after keyframes 4, 8, 12 (sculpted), each δO, a closed oriented
  // manifold, and its observed part, with boundary, whose triangles are δO's; the last ones the
  // final surfaces.
  std::vector<std::string> snapshots;
  for (const auto& entry : fs::directory_iterator(out / "snapshots")) {
    const std::string name = entry.path().filename().string();
    snapshots.push_back(name);
    if (name.rfind("observed_", 0) == 0) {
      const TriangleMesh observed_snapshot = ReadPlyMesh(entry.path());
      const MeshCheckReport snapshot_report = CheckMesh(observed_snapshot, bounded);
      EXPECT_TRUE(snapshot_report.ok) << entry.path() << ": " << snapshot_report.ToText();
      EXPECT_EQ(observed_snapshot.colors.size(), observed_snapshot.vertices.size());
      ExpectTrianglesSubset(observed_snapshot,
                            ReadPlyMesh(out / "snapshots" / ("surface_" + name.substr(9))));
    } else {
      const MeshCheckReport snapshot_report = CheckMesh(ReadPlyMesh(entry.path()));
      EXPECT_TRUE(snapshot_report.ok) << entry.path() << ": " << snapshot_report.ToText();
    }
  }
  std::sort(snapshots.begin(), snapshots.end());
  std::sort(expected_snapshots.begin(), expected_snapshots.end());
  EXPECT_EQ(snapshots, expected_snapshots);
  ASSERT_FALSE(expected_snapshots.empty());
  if (keyframes % 4 == 0) {
    const std::string last = std::to_string(last_id) + ".ply";
    EXPECT_EQ(ReadPlyMesh(out / "snapshots" / ("surface_" + last)).triangles.size(),
              closed.triangles.size());
    const TriangleMesh last_observed = ReadPlyMesh(out / "snapshots" / ("observed_" + last));
    EXPECT_EQ(last_observed.triangles, mesh.triangles);
    EXPECT_EQ(last_observed.colors, mesh.colors);
  }
  EXPECT_EQ(last_triangles, static_cast<long>(closed.triangles.size()));
  EXPECT_GT(added, 1000);

  // The rest of the reconstruction folder: one ground-truth pose per keyframe, taken from the
  // drive's poses, and every point fed to the sculptor.
  const std::vector<StampedPose> keyframe_poses = ReadTum(out / "poses.tum");
  ASSERT_EQ(static_cast<int>(keyframe_poses.size()), keyframes);
  const std::vector<StampedPose> drive_poses = ReadTum(drive / "gt" / "poses.tum");
  for (const StampedPose& pose : keyframe_poses) {
    const auto same_time = [&](const StampedPose& p) {
      return std::abs(p.timestamp - pose.timestamp) < 1e-6;
    };
    const auto it = std::find_if(drive_poses.begin(), drive_poses.end(), same_time);
    ASSERT_NE(it, drive_poses.end()) << pose.timestamp;
    EXPECT_LT((it->world_from_rig.translation - pose.world_from_rig.translation).norm(), 1e-6);
  }
  EXPECT_GE(static_cast<long>(ReadPlyPoints(out / "points.ply").points.size()), added + rejected);
  const double rejected_share =
      static_cast<double>(rejected) / static_cast<double>(added + rejected);
  std::cout << "surface command: " << keyframes << " keyframes, " << added << " points added, "
            << rejected << " rejected (" << 100.0 * rejected_share << "%), "
            << mesh.triangles.size() << " triangles\n";
  EXPECT_LT(rejected_share, 0.05);
}

// Without smoothing the vertices of the surfaces are the points where they lie: every vertex of
// surface.ply is a point of points.ply (no Steiner vertex) and carries its colour (the mean of
// the images where it is seen, tested in tests/pipeline/sfm_outputs_test.cpp); the vertices of
// surface_closed.ply that are not points are Steiner vertices, grey (the street test of
// tests/surface/observed_mesh_test.cpp checks that δO has some).
TEST_F(SurfaceCommandTest, SurfaceVerticesArePointsWithTheirColours) {
  const fs::path drive = TinyDrive("drive_colours", 10);
  ASSERT_FALSE(drive.empty());
  const fs::path out = dir_->path() / "colours";
  const RunResult r = Run({"--quiet", "surface", "--from-gt", drive.string(), "--out", out.string(),
                           "--no-smoothing", "--init-keyframes", "4"});
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const PointCloud points = ReadPlyPoints(out / "points.ply");
  ASSERT_EQ(points.colors.size(), points.points.size());
  std::map<std::array<float, 3>, Rgb8> color_of;
  auto key = [](const Eigen::Vector3d& v) {
    return std::array<float, 3>{static_cast<float>(v.x()), static_cast<float>(v.y()),
                                static_cast<float>(v.z())};
  };
  for (size_t i = 0; i < points.points.size(); ++i)
    color_of[key(points.points[i])] = points.colors[i];
  const TriangleMesh mesh = ReadPlyMesh(out / "surface.ply");
  const TriangleMesh closed = ReadPlyMesh(out / "surface_closed.ply");
  ASSERT_GT(mesh.triangles.size(), 100u);
  ASSERT_EQ(mesh.colors.size(), mesh.vertices.size());
  ASSERT_EQ(closed.colors.size(), closed.vertices.size());
  size_t not_points = 0, wrong = 0, coloured = 0;
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    const auto it = color_of.find(key(mesh.vertices[v]));
    if (it == color_of.end()) {
      ++not_points;
      continue;
    }
    wrong += it->second == mesh.colors[v] ? 0 : 1;
    // The synthetic city is grey, and stays grey, textured.
    EXPECT_TRUE(mesh.colors[v][0] == mesh.colors[v][1] && mesh.colors[v][1] == mesh.colors[v][2]);
    coloured += mesh.colors[v][0] != 128 ? 1 : 0;
  }
  EXPECT_EQ(not_points, 0u);
  EXPECT_EQ(wrong, 0u);
  EXPECT_GT(coloured, mesh.vertices.size() / 2);  // sampled from the images, not the fallback
  size_t steiner = 0;
  for (size_t v = 0; v < closed.vertices.size(); ++v) {
    const auto it = color_of.find(key(closed.vertices[v]));
    if (it != color_of.end()) {
      EXPECT_EQ(it->second, closed.colors[v]);
      continue;
    }
    ++steiner;
    EXPECT_EQ(closed.colors[v], Rgb8(128, 128, 128));
  }
  std::cout << "colours: " << mesh.vertices.size() << " observed vertices, " << steiner
            << " Steiner vertices in the closed surface\n";
  ExpectTrianglesSubset(mesh, closed);
}

// Step 6: --no-genus-refinement and --no-smoothing switch each part off on the same
// stream, --smooth-every-keyframe smooths in the keyframes instead of once at the end.
// Smoothing moves vertices only (same triangles, same vertex count); without refinement
// no group is added and F ∩ E outside O is left as step 5 made it; each output is a closed
// oriented 2-manifold.
TEST_F(SurfaceCommandTest, StepSixSwitchesTurnEachPartOff) {
  const fs::path drive = TinyDrive("drive6", 10);
  ASSERT_FALSE(drive.empty());
  auto run = [&](const std::string& name, std::vector<std::string> flags) {
    const fs::path out = dir_->path() / name;
    std::vector<std::string> args = {
        "--quiet",       "surface", "--from-gt",  drive.string(),     "--out", out.string(),
        "--point-noise", "0.05",    "--no-batch", "--init-keyframes", "4"};
    args.insert(args.end(), flags.begin(), flags.end());
    const RunResult r = Run(args);
    EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
    return out;
  };
  const fs::path full = run("s6_full", {});
  const fs::path every = run("s6_every", {"--smooth-every-keyframe"});
  const fs::path no_smooth = run("s6_no_smooth", {"--no-smoothing"});
  const fs::path none = run("s6_none", {"--no-smoothing", "--no-genus-refinement"});
  const TriangleMesh m_full = ReadPlyMesh(full / "surface_closed.ply");
  const TriangleMesh m_no_smooth = ReadPlyMesh(no_smooth / "surface_closed.ply");
  const TriangleMesh m_none = ReadPlyMesh(none / "surface_closed.ply");
  for (const TriangleMesh* m : {&m_full, &m_no_smooth, &m_none}) {
    const MeshCheckReport report = CheckMesh(*m);
    EXPECT_TRUE(report.ok) << report.ToText();
  }
  EXPECT_EQ(m_full.triangles, m_no_smooth.triangles);
  ASSERT_EQ(m_full.vertices.size(), m_no_smooth.vertices.size());
  size_t moved = 0;
  for (size_t i = 0; i < m_full.vertices.size(); ++i) {
    moved += m_full.vertices[i] == m_no_smooth.vertices[i] ? 0 : 1;
  }
  EXPECT_GT(moved, m_full.vertices.size() / 4);
  const TriangleMesh m_every = ReadPlyMesh(every / "surface_closed.ply");
  EXPECT_TRUE(CheckMesh(m_every).ok);
  EXPECT_EQ(m_every.triangles, m_full.triangles);
  EXPECT_NE(m_every.vertices, m_full.vertices);
  // By default the smoothing ran once, when the surface was taken; with
  // --smooth-every-keyframe, in the keyframes (below).
  const nlohmann::json smoothing =
      nlohmann::json::parse(ReadTextFile(full / "surface.json")).at("smoothing");
  EXPECT_FALSE(smoothing.at("every_keyframe").get<bool>());
  EXPECT_EQ(smoothing.at("at_extraction_runs").get<int>(), 1);
  EXPECT_GT(smoothing.at("at_extraction_vertices").get<int>(), 100);
  EXPECT_EQ(nlohmann::json::parse(ReadTextFile(every / "surface.json"))
                .at("smoothing")
                .at("at_extraction_runs")
                .get<int>(),
            0);
  // The stats columns of step 6.
  const std::vector<std::string> columns = Split(kColumns, ',');
  auto sum = [&](const fs::path& out, const char* name) {
    const std::vector<std::string> lines =
        Split(ReadTextFile(out / "stats" / "keyframes.csv"), '\n');
    const size_t k = std::find(columns.begin(), columns.end(), name) - columns.begin();
    EXPECT_LT(k, columns.size()) << name;
    double total = 0.0;
    for (size_t i = 1; i < lines.size(); ++i) total += std::stod(Split(lines[i], ',').at(k));
    return total;
  };
  EXPECT_GT(sum(every, "smoothed_vertices"), 0.0);
  EXPECT_EQ(sum(full, "smoothed_vertices"), 0.0);
  EXPECT_GT(sum(full, "smoothing_candidates"), 0.0);
  EXPECT_EQ(sum(no_smooth, "smoothed_vertices"), 0.0);
  EXPECT_EQ(sum(none, "genus_groups"), 0.0);
  EXPECT_EQ(sum(none, "genus_free_before"), sum(none, "genus_free_after"));
  EXPECT_LE(sum(full, "genus_free_after"), sum(full, "genus_free_before"));
}

// With --final-batch the surface written is every keyframe sculpted again at once at the first
// keyframes' s. It differs from the keyframe-by-keyframe surface (the default),
// is a closed oriented manifold with its observed part inside it, and inserts every point the
// stream kept (a batch rejects none: O is empty when its points go in).
TEST_F(SurfaceCommandTest, TheFinalBatchIsTheSurfaceWrittenWhenAsked) {
  const fs::path drive = TinyDrive("drive_final_batch", 12);
  ASSERT_FALSE(drive.empty());
  auto run = [&](const std::string& name, std::vector<std::string> extra) {
    const fs::path out = dir_->path() / name;
    std::vector<std::string> args = {"--quiet", "surface",    "--from-gt",        drive.string(),
                                     "--out",   out.string(), "--init-keyframes", "4"};
    args.insert(args.end(), extra.begin(), extra.end());
    const RunResult result = Run(args);
    EXPECT_EQ(result.exit_code, 0) << result.err;
    return out;
  };
  const fs::path batch = run("batch", {"--final-batch"});
  const fs::path stream = run("stream", {});
  const nlohmann::json batch_json = nlohmann::json::parse(ReadTextFile(batch / "surface.json"));
  const nlohmann::json stream_json = nlohmann::json::parse(ReadTextFile(stream / "surface.json"));
  EXPECT_TRUE(batch_json["final_batch"]["ran"].get<bool>());
  EXPECT_FALSE(stream_json["final_batch"]["ran"].get<bool>());
  // The stream's sculpting is the same in both runs: the same rows (times aside).
  const std::vector<std::string> batch_rows =
      Split(ReadTextFile(batch / "stats" / "keyframes.csv"), '\n');
  const std::vector<std::string> stream_rows =
      Split(ReadTextFile(stream / "stats" / "keyframes.csv"), '\n');
  ASSERT_EQ(batch_rows.size(), stream_rows.size());
  const TriangleMesh closed = ReadPlyMesh(batch / "surface_closed.ply");
  const TriangleMesh stream_closed = ReadPlyMesh(stream / "surface_closed.ply");
  const MeshCheckReport report = CheckMesh(closed);
  EXPECT_TRUE(report.ok) << report.ToText();
  EXPECT_NE(closed.triangles, stream_closed.triangles);
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  const TriangleMesh observed = ReadPlyMesh(batch / "surface.ply");
  EXPECT_TRUE(CheckMesh(observed, bounded).ok);
  ExpectTrianglesSubset(observed, closed);
  EXPECT_EQ(batch_json["points_rejected"].get<size_t>(), 0u);
  EXPECT_GE(batch_json["points_added"].get<size_t>(), stream_json["points_added"].get<size_t>());
}

TEST_F(SurfaceCommandTest, MissingDriveIsOneErrorLineAndExitCode2) {
  const fs::path missing = dir_->path() / "no_such_drive";
  const RunResult result =
      Run({"surface", "--from-gt", missing.string(), "--out", (dir_->path() / "unused").string()});
  EXPECT_EQ(result.exit_code, 2);
  const std::vector<std::string> lines = Split(result.err, '\n');
  ASSERT_EQ(lines.size(), 1u) << result.err;
  EXPECT_NE(lines[0].find(missing.string()), std::string::npos) << lines[0];
  EXPECT_FALSE(fs::exists(dir_->path() / "unused" / "surface.ply"));
}

}  // namespace
}  // namespace omni
