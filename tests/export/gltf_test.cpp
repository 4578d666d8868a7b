// The .glb and .obj writers against a strict reader written from the glTF 2.0 specification
// (tests/export/strict_glb_reader.h; Debian 12 packages no glTF validator).

#include "export/gltf.h"

#include <gtest/gtest.h>

#include <sstream>

#include "tests/calib/io_temp_dir.h"
#include "tests/export/strict_glb_reader.h"

namespace omni {
namespace {

using testing::GlbContent;
using testing::ReadGlbStrictly;

// A tetrahedron with coloured vertices at coordinates a float does not hold exactly, and a
// cloud of seven coloured points (odd sizes: the BIN chunk needs padding).
TriangleMesh Tetrahedron() {
  TriangleMesh mesh;
  mesh.vertices = {{0.1, 0.2, 0.3}, {10.7, -0.25, 1.0 / 3.0}, {0.5, 8.125, -2.0}, {1.0, 1.0, 5.5}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}};
  mesh.colors = {Rgb8(255, 0, 0), Rgb8(0, 255, 0), Rgb8(0, 0, 255), Rgb8(17, 130, 201)};
  return mesh;
}

PointCloud SevenPoints() {
  PointCloud cloud;
  for (int i = 0; i < 7; ++i) {
    cloud.points.emplace_back(0.3 * i, -1.7 * i, 100.0 + i);
    cloud.colors.emplace_back(static_cast<uint8_t>(30 * i), static_cast<uint8_t>(7 + i), 250);
  }
  return cloud;
}

TEST(Glb, StrictReaderReadsBackTheMeshAndThePoints) {
  const TriangleMesh mesh = Tetrahedron();
  const PointCloud cloud = SevenPoints();
  const GlbContent glb = ReadGlbStrictly(EncodeGlb(mesh, cloud));
  ASSERT_EQ(glb.error, "");
  ASSERT_EQ(glb.meshes.count("surface"), 1u);
  ASSERT_EQ(glb.meshes.count("points"), 1u);
  const testing::GlbPrimitive& surface = glb.meshes.at("surface");
  EXPECT_EQ(surface.mode, 4);
  ASSERT_EQ(surface.positions.size(), mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    EXPECT_EQ(surface.positions[i], mesh.vertices[i].cast<float>()) << i;
    EXPECT_EQ(surface.colors[i], mesh.colors[i].cast<int>()) << i;
  }
  ASSERT_EQ(surface.indices.size(), 3 * mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      EXPECT_EQ(surface.indices[3 * t + k], static_cast<uint32_t>(mesh.triangles[t][k]));
  const testing::GlbPrimitive& points = glb.meshes.at("points");
  EXPECT_EQ(points.mode, 0);
  EXPECT_TRUE(points.indices.empty());
  ASSERT_EQ(points.positions.size(), cloud.points.size());
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    EXPECT_EQ(points.positions[i], cloud.points[i].cast<float>()) << i;
    EXPECT_EQ(points.colors[i], cloud.colors[i].cast<int>()) << i;
  }
  // The root node turns z up into glTF's y up; the scene holds it.
  EXPECT_EQ(glb.json["scenes"][0]["nodes"], nlohmann::json::array({0}));
  EXPECT_EQ(glb.json["nodes"][0]["children"].size(), 2u);
}

TEST(Glb, WithoutColoursOrPointsOnlyWhatThereIs) {
  TriangleMesh mesh = Tetrahedron();
  mesh.colors.clear();
  const GlbContent glb = ReadGlbStrictly(EncodeGlb(mesh, PointCloud()));
  ASSERT_EQ(glb.error, "");
  EXPECT_EQ(glb.meshes.size(), 1u);
  EXPECT_TRUE(glb.meshes.at("surface").colors.empty());
  const GlbContent points_only = ReadGlbStrictly(EncodeGlb(TriangleMesh(), SevenPoints()));
  ASSERT_EQ(points_only.error, "");
  EXPECT_EQ(points_only.meshes.count("surface"), 0u);
  EXPECT_EQ(points_only.meshes.at("points").positions.size(), 7u);
}

// The strict reader itself fails on broken files (so its "" above means something).
TEST(Glb, StrictReaderRejectsBrokenFiles) {
  const std::string good = EncodeGlb(Tetrahedron(), SevenPoints());
  std::string bad = good;
  bad[4] = 1;  // version 1
  EXPECT_EQ(ReadGlbStrictly(bad).error, "version is not 2");
  bad = good + "    ";  // header length no longer the file size
  EXPECT_EQ(ReadGlbStrictly(bad).error, "header length is not the file size");
  bad = good;
  bad[12] += 1;  // JSON chunk length not a multiple of 4
  EXPECT_EQ(ReadGlbStrictly(bad).error, "JSON chunk length not a multiple of 4");
  // Valid chunks around a broken JSON: a max that is not the data's, a misaligned attribute,
  // a bufferView beyond the buffer.
  const GlbContent content = ReadGlbStrictly(good);
  const uint32_t json_length = *reinterpret_cast<const uint32_t*>(good.data() + 12);
  const std::string bin_chunk = good.substr(20 + json_length);  // its header and data
  auto rebuilt = [&bin_chunk](const nlohmann::json& gltf) {
    std::string json = gltf.dump();
    while (json.size() % 4 != 0) json.push_back(' ');
    const uint32_t header[5] = {0x46546C67, 2,
                                static_cast<uint32_t>(20 + json.size() + bin_chunk.size()),
                                static_cast<uint32_t>(json.size()), 0x4E4F534A};
    return std::string(reinterpret_cast<const char*>(header), 20) + json + bin_chunk;
  };
  ASSERT_EQ(ReadGlbStrictly(rebuilt(content.json)).error, "");
  nlohmann::json broken = content.json;
  broken["accessors"][0]["max"][0] = broken["accessors"][0]["max"][0].get<double>() + 1.0;
  EXPECT_EQ(ReadGlbStrictly(rebuilt(broken)).error,
            "surface: POSITION accessors[0]: max[0] is not the data's");
  broken = content.json;
  broken["bufferViews"][1]["byteOffset"] = broken["bufferViews"][1]["byteOffset"].get<size_t>() + 2;
  EXPECT_EQ(ReadGlbStrictly(rebuilt(broken)).error,
            "surface: COLOR_0 accessors[1]: vertex attribute not aligned to 4 bytes");
  broken = content.json;
  broken["bufferViews"][0]["byteLength"] = broken["buffers"][0]["byteLength"].get<size_t>() + 4;
  EXPECT_EQ(ReadGlbStrictly(rebuilt(broken)).error,
            "surface: POSITION accessors[0]: bufferView beyond its buffer");
}

TEST(Glb, RefusesWhatItCannotWrite) {
  EXPECT_THROW(EncodeGlb(TriangleMesh(), PointCloud()), std::invalid_argument);
  TriangleMesh mesh = Tetrahedron();
  mesh.colors.pop_back();
  EXPECT_THROW(EncodeGlb(mesh, PointCloud()), std::invalid_argument);
  mesh = Tetrahedron();
  mesh.triangles.push_back({0, 1, 4});
  EXPECT_THROW(EncodeGlb(mesh, PointCloud()), std::invalid_argument);
  PointCloud cloud = SevenPoints();
  cloud.colors.pop_back();
  EXPECT_THROW(EncodeGlb(Tetrahedron(), cloud), std::invalid_argument);
}

TEST(Obj, VerticesWithColoursAndOneBasedFaces) {
  testing::TempDir dir;
  const TriangleMesh mesh = Tetrahedron();
  WriteObj(mesh, dir / "mesh.obj");
  std::istringstream text(testing::ReadBytes(dir / "mesh.obj"));
  std::string line;
  std::vector<Eigen::Vector3d> vertices, colors;
  std::vector<Eigen::Vector3i> faces;
  while (std::getline(text, line)) {
    std::istringstream fields(line);
    std::string kind;
    fields >> kind;
    if (kind == "v") {
      Eigen::Vector3d v, c;
      ASSERT_TRUE(fields >> v.x() >> v.y() >> v.z() >> c.x() >> c.y() >> c.z()) << line;
      vertices.push_back(v);
      colors.push_back(c);
    } else if (kind == "f") {
      Eigen::Vector3i f;
      ASSERT_TRUE(fields >> f.x() >> f.y() >> f.z()) << line;
      faces.push_back(f - Eigen::Vector3i::Ones());
    }
  }
  ASSERT_EQ(vertices.size(), mesh.vertices.size());
  for (size_t i = 0; i < vertices.size(); ++i) {
    EXPECT_NEAR((vertices[i] - mesh.vertices[i]).norm(), 0.0, 1e-7) << i;
    EXPECT_NEAR((colors[i] * 255.0 - mesh.colors[i].cast<double>()).norm(), 0.0, 0.1) << i;
  }
  EXPECT_EQ(faces, mesh.triangles);
}

}  // namespace
}  // namespace omni
