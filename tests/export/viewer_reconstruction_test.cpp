// `omnisculpt export` and `omnisculpt view` on the reconstruction of the short drive with
// snapshots (the ctest fixture viewer_reconstruction, OMNI_VIEWER_REC_DIR): the files they
// write against the reconstruction's own files, read strictly.

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>

#include "calib/ply.h"
#include "calib/tum.h"
#include "tests/apps/run_omnisculpt.h"
#include "tests/calib/io_temp_dir.h"
#include "tests/export/strict_glb_reader.h"
#include "tests/export/viewer_data.h"

namespace omni {
namespace {

namespace fs = std::filesystem;
using testing::Base64Decoded;
using testing::CommandResult;
using testing::ExpectSameMesh;
using testing::GlbContent;
using testing::ReadBytes;
using testing::ReadGlbStrictly;
using testing::RunOmnisculpt;
using testing::ScriptValue;

const fs::path kReconstruction(OMNI_VIEWER_REC_DIR);

// A copy of the reconstruction (the browser test writes the fixture's own viewer/).
fs::path CopyOfReconstruction(const testing::TempDir& dir) {
  const fs::path copy = dir / "rec";
  fs::create_directories(copy);
  for (const auto& entry : fs::directory_iterator(kReconstruction)) {
    const std::string name = entry.path().filename().string();
    if (name == "viewer" || name == "viewer.incomplete" || name == "export") continue;
    fs::copy(entry.path(), copy / name, fs::copy_options::recursive);
  }
  return copy;
}

TEST(ExportViewerReconstruction, GlbMatchesSurfacePlyAndPointsPly) {
  testing::TempDir dir;
  for (const bool closed : {false, true}) {
    const fs::path glb_file = dir / (closed ? "closed.glb" : "surface.glb");
    std::vector<std::string> arguments = {"--quiet", "export", kReconstruction.string(), "--format",
                                          "glb",     "--out",  glb_file.string()};
    if (closed) arguments.push_back("--closed");
    const CommandResult run = RunOmnisculpt(arguments, dir.path());
    ASSERT_EQ(run.exit_code, 0) << run.err;
    const GlbContent glb = ReadGlbStrictly(ReadBytes(glb_file));
    ASSERT_EQ(glb.error, "");
    const TriangleMesh ply =
        ReadPlyMesh(kReconstruction / (closed ? "surface_closed.ply" : "surface.ply"));
    ASSERT_FALSE(ply.triangles.empty());
    ASSERT_FALSE(ply.colors.empty());
    ExpectSameMesh(glb.meshes.at("surface"), ply);
    const PointCloud points = ReadPlyPoints(kReconstruction / "points.ply");
    const testing::GlbPrimitive& glb_points = glb.meshes.at("points");
    EXPECT_EQ(glb_points.mode, 0);
    ASSERT_EQ(glb_points.positions.size(), points.points.size());
    size_t differing = 0;
    for (size_t i = 0; i < points.points.size(); ++i)
      if (glb_points.positions[i] != points.points[i].cast<float>() ||
          glb_points.colors[i] != points.colors[i].cast<int>())
        ++differing;
    EXPECT_EQ(differing, 0u);
  }
}

TEST(ExportViewerReconstruction, PlyAndObjMatchSurfacePly) {
  testing::TempDir dir;
  const TriangleMesh ply = ReadPlyMesh(kReconstruction / "surface.ply");
  ASSERT_EQ(RunOmnisculpt({"--quiet", "export", kReconstruction.string(), "--format", "ply",
                           "--out", (dir / "copy.ply").string()},
                          dir.path())
                .exit_code,
            0);
  const TriangleMesh again = ReadPlyMesh(dir / "copy.ply");
  EXPECT_EQ(again.vertices, ply.vertices);
  EXPECT_EQ(again.triangles, ply.triangles);
  EXPECT_EQ(again.colors, ply.colors);
  ASSERT_EQ(RunOmnisculpt({"--quiet", "export", kReconstruction.string(), "--format", "obj",
                           "--out", (dir / "mesh.obj").string()},
                          dir.path())
                .exit_code,
            0);
  size_t v = 0, f = 0;
  for (const std::string& line : testing::SplitText(ReadBytes(dir / "mesh.obj"))) {
    v += line.rfind("v ", 0) == 0;
    f += line.rfind("f ", 0) == 0;
  }
  EXPECT_EQ(v, ply.vertices.size());
  EXPECT_EQ(f, ply.triangles.size());
}

TEST(ExportViewerReconstruction, RefusesToOverwriteAndBadInput) {
  testing::TempDir dir;
  const fs::path target = dir / "keep.glb";
  testing::WriteBytes(target, "the user's file");
  CommandResult run = RunOmnisculpt(
      {"export", kReconstruction.string(), "--format", "glb", "--out", target.string()},
      dir.path());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(testing::SplitText(run.err).size(), 1u) << run.err;
  EXPECT_NE(run.err.find(target.string()), std::string::npos) << run.err;
  EXPECT_EQ(ReadBytes(target), "the user's file");
  run = RunOmnisculpt({"export", kReconstruction.string(), "--format", "stl"}, dir.path());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--format"), std::string::npos) << run.err;
  run = RunOmnisculpt({"export", (dir / "nothing").string(), "--format", "glb"}, dir.path());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("surface.ply"), std::string::npos) << run.err;
}

TEST(ExportViewerReconstruction, ViewWritesTheDataOfTheReconstruction) {
  testing::TempDir dir;
  const fs::path rec = CopyOfReconstruction(dir);
  const CommandResult run = RunOmnisculpt({"--quiet", "view", rec.string()}, dir.path());
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const fs::path viewer = rec / "viewer";
  for (const char* file : {"index.html", "viewer.js", "viewer.css", "lib/three.min.js",
                           "lib/GLTFLoader.js", "lib/OrbitControls.js", "data/surface.js"})
    EXPECT_TRUE(fs::exists(viewer / file)) << file;
  const nlohmann::json scene = ScriptValue(viewer / "data" / "scene.js");
  // Keyframes: those of poses.tum, with the points seen so far growing to all of them.
  const std::vector<StampedPose> poses = ReadTum(rec / "poses.tum");
  ASSERT_EQ(scene["keyframes"].size(), poses.size());
  EXPECT_EQ(scene["keyframes"][5]["pose"][0].get<double>(),
            poses[5].world_from_rig.translation.x());
  size_t previous = 0;
  for (const nlohmann::json& k : scene["keyframes"]) {
    EXPECT_GE(k["points"].get<size_t>(), previous);
    previous = k["points"];
  }
  EXPECT_EQ(previous, scene["surface"]["points"].get<size_t>());
  // Every rig camera of cameras.txt, each with a pose at every keyframe.
  const nlohmann::json summary = nlohmann::json::parse(ReadBytes(rec / "reconstruct.json"));
  ASSERT_EQ(scene["cameras"].size(), 6u);  // the short drive's Ladybug-like rig
  for (const nlohmann::json& camera : scene["cameras"]) {
    ASSERT_EQ(camera["poses"].size(), poses.size());
    EXPECT_FALSE(camera["poses"][0].is_null());
  }
  EXPECT_EQ(scene["loop_closures"].size(), summary["loop_closures"].size());
  EXPECT_GE(scene["loop_closures"].size(), 1u);
  // The surface: surface.ply; the points: every point of the COLMAP model.
  const GlbContent surface = ReadGlbStrictly(
      Base64Decoded(ScriptValue(viewer / "data" / "surface.js").get<std::string>()));
  ASSERT_EQ(surface.error, "");
  ExpectSameMesh(surface.meshes.at("surface"), ReadPlyMesh(rec / "surface.ply"));
  // (points.ply also has the frame points, which no keyframe sees: not in the model.)
  EXPECT_EQ(surface.meshes.at("points").positions.size(),
            summary["colmap_points"].get<size_t>());
  EXPECT_GT(summary["points"].get<size_t>(), summary["colmap_points"].get<size_t>());
  // One snapshot per keyframe of snapshots/, in keyframe order, each the .glb of its observed
  // surface (observed_<keyframe>.ply, coloured) whole, a part of its closed δO
  // (surface_<keyframe>.ply) that holds most of it: the viewer needs neither the final points
  // nor their positions, although in non-central mode the map moves after the first keyframes.
  size_t observed_files = 0, closed_files = 0;
  for (const auto& entry : fs::directory_iterator(rec / "snapshots")) {
    const std::string name = entry.path().filename().string();
    observed_files += name.rfind("observed_", 0) == 0 && entry.path().extension() == ".ply";
    closed_files += name.rfind("surface_", 0) == 0 && entry.path().extension() == ".ply";
  }
  ASSERT_GE(observed_files, 2u);
  EXPECT_EQ(closed_files, observed_files);
  ASSERT_EQ(scene["snapshots"].size(), observed_files);
  long last_keyframe = -1;
  for (const nlohmann::json& s : scene["snapshots"]) {
    EXPECT_GT(s["keyframe"].get<long>(), last_keyframe);
    last_keyframe = s["keyframe"];
    EXPECT_TRUE(s["observed"].get<bool>());
    const GlbContent glb = ReadGlbStrictly(
        Base64Decoded(ScriptValue(viewer / s["file"].get<std::string>()).get<std::string>()));
    ASSERT_EQ(glb.error, "") << s["file"];
    const std::string number = std::to_string(last_keyframe);
    const TriangleMesh observed = ReadPlyMesh(rec / "snapshots" / ("observed_" + number + ".ply"));
    const TriangleMesh closed = ReadPlyMesh(rec / "snapshots" / ("surface_" + number + ".ply"));
    ASSERT_EQ(observed.colors.size(), observed.vertices.size());
    ExpectSameMesh(glb.meshes.at("surface"), observed);
    EXPECT_EQ(s["triangles"].get<size_t>(), observed.triangles.size());
    EXPECT_LT(s["triangles"].get<size_t>(), closed.triangles.size());
    EXPECT_GT(s["triangles"].get<size_t>(), closed.triangles.size() * 3 / 4)
        << "keyframe " << number;
  }
  // A second run replaces the viewer it wrote.
  EXPECT_EQ(RunOmnisculpt({"--quiet", "view", rec.string()}, dir.path()).exit_code, 0);
  EXPECT_FALSE(fs::exists(rec / "viewer.incomplete"));
}

TEST(ExportViewerReconstruction, ViewKeepsAViewerFolderOfOtherFiles) {
  testing::TempDir dir;
  const fs::path rec = CopyOfReconstruction(dir);
  fs::create_directories(rec / "viewer");
  testing::WriteBytes(rec / "viewer" / "notes.txt", "mine");
  const CommandResult run = RunOmnisculpt({"view", rec.string()}, dir.path());
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_EQ(testing::SplitText(run.err).size(), 1u) << run.err;
  EXPECT_NE(run.err.find("viewer"), std::string::npos) << run.err;
  EXPECT_EQ(ReadBytes(rec / "viewer" / "notes.txt"), "mine");
  EXPECT_FALSE(fs::exists(rec / "viewer" / "index.html"));
}

// An HTTP/1.0 GET on 127.0.0.1:port; the whole answer.
std::string HttpGet(int port, const std::string& target) {
  const int s = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in where{};
  where.sin_family = AF_INET;
  where.sin_port = htons(static_cast<uint16_t>(port));
  inet_pton(AF_INET, "127.0.0.1", &where.sin_addr);
  if (connect(s, reinterpret_cast<sockaddr*>(&where), sizeof(where)) != 0) {
    close(s);
    return "connect failed";
  }
  const std::string request = "GET " + target + " HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n";
  send(s, request.data(), request.size(), 0);
  std::string answer;
  char buffer[65536];
  for (ssize_t n; (n = recv(s, buffer, sizeof(buffer), 0)) > 0;) answer.append(buffer, n);
  close(s);
  return answer;
}

TEST(ExportViewerReconstruction, ServePrintsTheAddressAndServesTheViewerOnly) {
  testing::TempDir dir;
  const fs::path rec = CopyOfReconstruction(dir);
  int out[2];
  ASSERT_EQ(pipe(out), 0);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    dup2(out[1], STDOUT_FILENO);
    close(out[0]);
    execl(OMNI_EXECUTABLE, OMNI_EXECUTABLE, "--quiet", "view", rec.c_str(), "--serve", "--port",
          "0", static_cast<char*>(nullptr));
    _exit(127);
  }
  close(out[1]);
  std::string line;
  char c;
  while (read(out[0], &c, 1) == 1 && c != '\n') line.push_back(c);
  close(out[0]);
  std::smatch match;
  const bool printed =
      std::regex_search(line, match, std::regex("http://127\\.0\\.0\\.1:([0-9]+)/index\\.html"));
  std::string index, escape, script;
  if (printed) {
    const int port = std::stoi(match[1]);
    index = HttpGet(port, "/index.html");
    escape = HttpGet(port, "/../reconstruct.json");
    script = HttpGet(port, "/data/scene.js");
  }
  kill(pid, SIGTERM);
  waitpid(pid, nullptr, 0);
  ASSERT_TRUE(printed) << line;
  const std::string page = ReadBytes(rec / "viewer" / "index.html");
  ASSERT_FALSE(page.empty());
  EXPECT_EQ(index.substr(0, 15), "HTTP/1.0 200 OK");
  EXPECT_EQ(index.substr(index.find("\r\n\r\n") + 4), page);
  EXPECT_EQ(escape.substr(0, 22), "HTTP/1.0 404 Not Found");
  EXPECT_NE(script.find("Content-Type: text/javascript"), std::string::npos);
  EXPECT_EQ(script.substr(script.find("\r\n\r\n") + 4),
            ReadBytes(rec / "viewer" / "data" / "scene.js"));
}

TEST(ExportViewerReconstruction, ServeOnATakenPortIsBadInput) {
  testing::TempDir dir;
  const int s = socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in where{};
  where.sin_family = AF_INET;
  inet_pton(AF_INET, "127.0.0.1", &where.sin_addr);
  ASSERT_EQ(bind(s, reinterpret_cast<sockaddr*>(&where), sizeof(where)), 0);
  ASSERT_EQ(listen(s, 1), 0);
  socklen_t length = sizeof(where);
  getsockname(s, reinterpret_cast<sockaddr*>(&where), &length);
  const CommandResult run = RunOmnisculpt({"view", kReconstruction.string(), "--serve", "--port",
                                           std::to_string(ntohs(where.sin_port))},
                                          dir.path());
  close(s);
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_NE(run.err.find("--port"), std::string::npos) << run.err;
}

}  // namespace
}  // namespace omni
