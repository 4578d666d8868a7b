// End-to-end: `omnisculpt eval`, `mesh-check` and `render` on small hand-made drives.

#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include "calib/ply.h"
#include "eval/primitives.h"
#include "tests/eval/eval_drive.h"

namespace omni {
namespace {
namespace fs = std::filesystem;
using testing::EvalTest;
using testing::kEstimatedFromGt;

// The command line.
int RunOmnisculpt(const std::string& arguments, std::string* output = nullptr) {
  const std::string command = std::string(OMNI_EXECUTABLE) + " " + arguments + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  std::string text;
  char buffer[4096];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) text.append(buffer, n);
  const int status = pclose(pipe);
  if (output) *output = text;
  return WEXITSTATUS(status);
}

TEST_F(EvalTest, CommandLine) {
  std::string output;
  WritePlyMesh(MakeTorus(3, 1, 16, 8), root_ / "torus.ply");
  EXPECT_EQ(RunOmnisculpt("mesh-check " + (root_ / "torus.ply").string(), &output), 0) << output;
  EXPECT_NE(output.find("genus 1"), std::string::npos) << output;
  TriangleMesh cubes = MakeBox({0, 0, 0}, {1, 1, 1});
  AppendMesh(MakeBox({1, 1, 1}, {2, 2, 2}), &cubes);
  WritePlyMesh(WeldVertices(cubes), root_ / "cubes.ply");
  EXPECT_EQ(RunOmnisculpt("mesh-check --json " + (root_ / "cubes.ply").string(), &output), 1)
      << output;
  EXPECT_NE(output.find("\"nonmanifold_vertices\": 1"), std::string::npos) << output;
  EXPECT_EQ(RunOmnisculpt("mesh-check " + (root_ / "missing.ply").string(), &output), 2) << output;

  // A sheet of 5 × 5 squares with two holes inside: a 2-manifold with boundary, accepted only
  // when asked, with its three boundary loops (the rim and the two holes) counted.
  TriangleMesh sheet;
  for (int row = 0; row <= 5; ++row) {
    for (int column = 0; column <= 5; ++column) sheet.vertices.emplace_back(column, row, 0.0);
  }
  for (int row = 0; row < 5; ++row) {
    for (int column = 0; column < 5; ++column) {
      if ((column == 1 && row == 1) || (column == 3 && row == 3)) continue;
      const int a = row * 6 + column;
      sheet.triangles.emplace_back(a, a + 1, a + 7);
      sheet.triangles.emplace_back(a, a + 7, a + 6);
    }
  }
  WritePlyMesh(sheet, root_ / "sheet.ply");
  const std::string sheet_path = (root_ / "sheet.ply").string();
  EXPECT_EQ(RunOmnisculpt("mesh-check " + sheet_path, &output), 1) << output;
  EXPECT_EQ(RunOmnisculpt("mesh-check --allow-boundary " + sheet_path, &output), 0) << output;
  EXPECT_NE(output.find("boundary loops 3\n"), std::string::npos) << output;
  EXPECT_EQ(RunOmnisculpt("mesh-check --allow-boundary --json " + sheet_path, &output), 0)
      << output;
  EXPECT_NE(output.find("\"boundary_loops\": 3"), std::string::npos) << output;
  EXPECT_NE(output.find("\"ok\": true"), std::string::npos) << output;

  EXPECT_EQ(RunOmnisculpt("render " + (drive_ / "gt" / "mesh.ply").string() +
                              " --bird --width 64 --out " + (root_ / "bird.png").string(),
                          &output),
            0)
      << output;
  EXPECT_TRUE(fs::exists(root_ / "bird.png"));
  EXPECT_EQ(RunOmnisculpt("render " + (drive_ / "gt" / "mesh.ply").string() +
                              " --pose '5 0 2 0 0 0 1' --rig " + (drive_ / "rig.json").string() +
                              " --camera cam1 --width 24 --out " + (root_ / "view.png").string(),
                          &output),
            0)
      << output;
  EXPECT_TRUE(fs::exists(root_ / "view.png"));
  EXPECT_EQ(
      RunOmnisculpt("render " + (drive_ / "gt" / "mesh.ply").string() + " --out x.png", &output),
      2);

  WriteReconstruction(kEstimatedFromGt, gt_mesh_);
  EXPECT_EQ(RunOmnisculpt("eval --gt " + drive_.string() + " --rec " + rec_.string() +
                              " --pixels 5000 --samples 5000 --no-plots --no-renders",
                          &output),
            0)
      << output;
  EXPECT_TRUE(fs::exists(rec_ / "report" / "eval.json"));
  EXPECT_NE(output.find("pose registration RMS 0.0 cm over 30 keyframes"), std::string::npos)
      << output;
  EXPECT_EQ(output.find("behind the truth, what the true ray hits"), std::string::npos) << output;
  // A ground truth with labels (as synth writes), an estimate without the north row of blocks:
  // the console says what the pixels behind the truth should have hit.
  TriangleMesh labelled = gt_mesh_;
  labelled.labels = testing::StreetLabels();
  WritePlyMesh(labelled, drive_ / "gt" / "mesh.ply");
  std::ofstream(drive_ / "gt" / "scene.json") << testing::kStreetLabelsJson;
  WriteReconstruction(kEstimatedFromGt, testing::StreetWithoutNorthRow());
  EXPECT_EQ(RunOmnisculpt("eval --force --gt " + drive_.string() + " --rec " + rec_.string() +
                              " --pixels 5000 --samples 5000 --no-plots --no-renders",
                          &output),
            0)
      << output;
  EXPECT_NE(output.find("behind the truth, what the true ray hits: north 100 % ("),
            std::string::npos)
      << output;
  EXPECT_EQ(RunOmnisculpt("eval --gt " + drive_.string() + " --rec " + (root_ / "nowhere").string(),
                          &output),
            2);
  EXPECT_NE(output.find("poses.tum"), std::string::npos) << output;
}

}  // namespace
}  // namespace omni
