#include "calib/ply.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <random>

#include "calib/error.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

using omni::testing::ReadBytes;
using omni::testing::TempDir;
using omni::testing::WriteBytes;
using Color = Eigen::Matrix<uint8_t, 3, 1>;

// Appends a value in big- or little-endian byte order.
template <typename T>
void Put(T value, bool big_endian, std::string* out) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  const uint16_t probe = 1;
  const bool host_little = *reinterpret_cast<const uint8_t*>(&probe) == 1;
  if (big_endian == host_little) std::reverse(bytes, bytes + sizeof(T));
  out->append(bytes, sizeof(T));
}

std::string MeshError(const std::filesystem::path& path) {
  try {
    ReadPlyMesh(path);
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no InputError for " << path;
  return "";
}

::testing::AssertionResult Contains(const std::string& text, const std::string& part) {
  if (text.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "\"" << text << "\" does not contain \"" << part << "\"";
}

TEST(Ply, MeshRoundTrip) {
  TempDir dir;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uniform(-50.0, 50.0);
  TriangleMesh mesh;
  for (int i = 0; i < 200; ++i)
    mesh.vertices.emplace_back(uniform(rng), uniform(rng), uniform(rng));
  std::uniform_int_distribution<int> index(0, 199);
  for (int i = 0; i < 300; ++i) mesh.triangles.emplace_back(index(rng), index(rng), index(rng));
  const auto path = dir / "mesh.ply";
  WritePlyMesh(mesh, path);
  EXPECT_FALSE(std::filesystem::exists(dir / "mesh.ply.tmp"));
  EXPECT_EQ(ReadBytes(path).rfind("ply\nformat binary_little_endian 1.0\n", 0), 0u);
  const TriangleMesh read = ReadPlyMesh(path);
  ASSERT_EQ(read.vertices.size(), mesh.vertices.size());
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    // Coordinates are stored as float.
    EXPECT_EQ(read.vertices[i], mesh.vertices[i].cast<float>().cast<double>()) << i;
  }
  EXPECT_EQ(read.triangles, mesh.triangles);
  // The same file read as points gives the vertices.
  const PointCloud cloud = ReadPlyPoints(path);
  EXPECT_EQ(cloud.points, read.vertices);
  EXPECT_TRUE(cloud.colors.empty());
  EXPECT_TRUE(read.colors.empty());
  EXPECT_EQ(ReadBytes(path).find("red"), std::string::npos);
}

TEST(Ply, ColouredMeshRoundTrip) {
  TempDir dir;
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  mesh.colors = {Color(255, 0, 0), Color(0, 255, 0), Color(0, 0, 255), Color(12, 128, 201)};
  const auto path = dir / "coloured.ply";
  WritePlyMesh(mesh, path);
  const std::string bytes = ReadBytes(path);
  EXPECT_NE(bytes.find("property uchar red\nproperty uchar green\nproperty uchar blue\n"
                       "element face"),
            std::string::npos);
  const TriangleMesh read = ReadPlyMesh(path);
  EXPECT_EQ(read.vertices, mesh.vertices);
  EXPECT_EQ(read.triangles, mesh.triangles);
  EXPECT_EQ(read.colors, mesh.colors);
  // The vertices read as a point cloud keep their colours.
  EXPECT_EQ(ReadPlyPoints(path).colors, mesh.colors);
  // A colour list that does not match the vertices is a bug of the caller.
  mesh.colors.pop_back();
  EXPECT_THROW(WritePlyMesh(mesh, dir / "bad.ply"), std::invalid_argument);
}

// Labels per triangle (synth's kinds of surface) round trip as a uchar face property, and a
// polygon's label goes to every triangle of its fan. Another program's face property `label`
// (real numbers, or ids beyond a byte) is not ours: the mesh reads without labels.
TEST(Ply, TriangleLabelsRoundTripAndFollowTheFans) {
  TempDir dir;
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  mesh.triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  mesh.labels = {3, 0, 255, 12};
  const auto path = dir / "labelled.ply";
  WritePlyMesh(mesh, path);
  EXPECT_NE(ReadBytes(path).find("property list uchar int vertex_indices\nproperty uchar label\n"),
            std::string::npos);
  const TriangleMesh read = ReadPlyMesh(path);
  EXPECT_EQ(read.triangles, mesh.triangles);
  EXPECT_EQ(read.labels, mesh.labels);
  // Without labels the file has no such property and reads back without them.
  mesh.labels.clear();
  WritePlyMesh(mesh, path);
  EXPECT_EQ(ReadBytes(path).find("label"), std::string::npos);
  EXPECT_TRUE(ReadPlyMesh(path).labels.empty());
  // A label list that does not match the triangles is a bug of the caller.
  mesh.labels = {1, 2, 3};
  EXPECT_THROW(WritePlyMesh(mesh, dir / "bad.ply"), std::invalid_argument);

  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
      "property float z\nelement face 2\n";
  const std::string vertices = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 2 0\n";
  // The label before the indices, a quad then a triangle.
  WriteBytes(path, head + "property int label\nproperty list uchar int vertex_indices\n" +
                       "end_header\n" + vertices + "7 4 0 1 2 3\n9 3 1 4 2\n");
  const TriangleMesh quad = ReadPlyMesh(path);
  ASSERT_EQ(quad.triangles.size(), 3u);
  EXPECT_EQ(quad.labels, (std::vector<uint8_t>{7, 7, 9}));
  WriteBytes(path, head + "property list uchar int vertex_indices\nproperty int label\n" +
                       "end_header\n" + vertices + "4 0 1 2 3 7\n3 1 4 2 256\n");
  TriangleMesh other = ReadPlyMesh(path);
  EXPECT_EQ(other.triangles.size(), 3u);
  EXPECT_TRUE(other.labels.empty());
  WriteBytes(path, head + "property list uchar int vertex_indices\nproperty float label\n" +
                       "end_header\n" + vertices + "4 0 1 2 3 7.5\n3 1 4 2 2\n");
  other = ReadPlyMesh(path);
  EXPECT_EQ(other.triangles.size(), 3u);
  EXPECT_TRUE(other.labels.empty());
}

TEST(Ply, ColouredPointsRoundTrip) {
  TempDir dir;
  PointCloud cloud;
  for (int i = 0; i < 100; ++i) {
    cloud.points.emplace_back(i * 0.25, -i * 0.5, i * 1024.0);
    cloud.colors.push_back(
        Color(static_cast<uint8_t>(i), static_cast<uint8_t>(255 - i), static_cast<uint8_t>(i * 7)));
  }
  const auto path = dir / "points.ply";
  WritePlyPoints(cloud, path);
  const PointCloud read = ReadPlyPoints(path);
  EXPECT_EQ(read.points, cloud.points);  // exactly representable as float
  EXPECT_EQ(read.colors, cloud.colors);
  const TriangleMesh mesh = ReadPlyMesh(path);
  EXPECT_EQ(mesh.vertices.size(), 100u);
  EXPECT_TRUE(mesh.triangles.empty());
}

TEST(Ply, UncolouredPointsRoundTrip) {
  TempDir dir;
  PointCloud cloud;
  cloud.points = {{1, 2, 3}, {4, 5, 6}};
  WritePlyPoints(cloud, dir / "p.ply");
  const PointCloud read = ReadPlyPoints(dir / "p.ply");
  EXPECT_EQ(read.points, cloud.points);
  EXPECT_TRUE(read.colors.empty());
}

TEST(Ply, HandWrittenAsciiWithExtrasAndQuads) {
  TempDir dir;
  const auto path = dir / "hand.ply";
  WriteBytes(path,
             "ply\r\n"
             "format ascii 1.0\r\n"
             "comment made by hand\n"
             "obj_info nothing\n"
             "element vertex 5\n"
             "property double x\n"
             "property float nx\n"
             "property double y\n"
             "property double z\n"
             "property int flags\n"
             "property uchar diffuse_red\n"
             "property uchar diffuse_green\n"
             "property uchar diffuse_blue\n"
             "element face 2\n"
             "property uchar flag\n"
             "property list uchar int vertex_index\n"
             "property list uchar float texcoord\n"
             "element edge 1\n"
             "property list int int pair\n"
             "property short weight\n"
             "end_header\n"
             "0 9 0 0 1 10 20 30\n"
             "1.5 9 0 0 2 11 21 31\n"
             "1 9 1 0 3 12 22 32\n"
             "0 9 1 -2.25e1 4 13 23 33\n"
             "2 9 2 2 5 255 0 1\n"
             "7 4 0 1 2 3 2 0.5 0.5\n"
             "7 3 1 4 2 0\n"
             "2 0 1 -3\n");
  const TriangleMesh mesh = ReadPlyMesh(path);
  ASSERT_EQ(mesh.vertices.size(), 5u);
  EXPECT_EQ(mesh.vertices[1], Eigen::Vector3d(1.5, 0, 0));
  EXPECT_EQ(mesh.vertices[3], Eigen::Vector3d(0, 1, -22.5));
  const std::vector<Eigen::Vector3i> expected = {{0, 1, 2}, {0, 2, 3}, {1, 4, 2}};
  EXPECT_EQ(mesh.triangles, expected);
  const PointCloud cloud = ReadPlyPoints(path);
  ASSERT_EQ(cloud.colors.size(), 5u);
  EXPECT_EQ(cloud.colors[0], Color(10, 20, 30));
  EXPECT_EQ(cloud.colors[4], Color(255, 0, 1));
}

TEST(Ply, HandWrittenBinaryBigEndian) {
  TempDir dir;
  const auto path = dir / "big.ply";
  std::string bytes =
      "ply\nformat binary_big_endian 1.0\n"
      "element vertex 4\n"
      "property float x\nproperty float y\nproperty float z\n"
      "property ushort quality\n"
      "property uchar red\nproperty uchar green\nproperty uchar blue\n"
      "element face 1\n"
      "property list int uint vertex_indices\n"
      "end_header\n";
  const float coords[4][3] = {{1.5f, -2.0f, 3.25f}, {0, 0, 0}, {1, 0, 0}, {0, 1e6f, -1e-3f}};
  for (int i = 0; i < 4; ++i) {
    for (float c : coords[i]) Put(c, true, &bytes);
    Put(static_cast<uint16_t>(1000 + i), true, &bytes);
    for (int c = 0; c < 3; ++c) Put(static_cast<uint8_t>(i * 10 + c), true, &bytes);
  }
  Put(static_cast<int32_t>(4), true, &bytes);
  for (uint32_t v : {3u, 2u, 1u, 0u}) Put(v, true, &bytes);
  WriteBytes(path, bytes);

  const TriangleMesh mesh = ReadPlyMesh(path);
  ASSERT_EQ(mesh.vertices.size(), 4u);
  for (int i = 0; i < 4; ++i) {
    EXPECT_EQ(mesh.vertices[i],
              Eigen::Vector3f(coords[i][0], coords[i][1], coords[i][2]).cast<double>());
  }
  const std::vector<Eigen::Vector3i> expected = {{3, 2, 1}, {3, 1, 0}};
  EXPECT_EQ(mesh.triangles, expected);
  const PointCloud cloud = ReadPlyPoints(path);
  ASSERT_EQ(cloud.colors.size(), 4u);
  EXPECT_EQ(cloud.colors[3], Color(30, 31, 32));
}

TEST(Ply, DoublePrecisionVerticesAreExact) {
  TempDir dir;
  const auto path = dir / "double.ply";
  std::string bytes =
      "ply\nformat binary_little_endian 1.0\n"
      "element vertex 2\nproperty double x\nproperty double y\nproperty double z\n"
      "end_header\n";
  const double values[6] = {0.1, 1.0 / 3.0, -1e-300, 123456789.123456789, 2.0 / 7.0, -0.0};
  for (double v : values) Put(v, false, &bytes);
  WriteBytes(path, bytes);
  const PointCloud cloud = ReadPlyPoints(path);
  ASSERT_EQ(cloud.points.size(), 2u);
  EXPECT_EQ(cloud.points[0], Eigen::Vector3d(values[0], values[1], values[2]));
  EXPECT_EQ(cloud.points[1], Eigen::Vector3d(values[3], values[4], values[5]));
  EXPECT_TRUE(ReadPlyMesh(path).triangles.empty());
}

TEST(Ply, MalformedHeadersAreRejected) {
  TempDir dir;
  const auto path = dir / "bad.ply";
  const std::string vertex =
      "element vertex 1\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n0 0 0\n";
  WriteBytes(path, "plx\nformat ascii 1.0\n" + vertex);
  EXPECT_TRUE(Contains(MeshError(path), path.string() + ": not a PLY file"));
  WriteBytes(path, "ply\nformat binary_middle_endian 1.0\n" + vertex);
  EXPECT_TRUE(
      Contains(MeshError(path),
               path.string() + ": header line 2: unsupported format \"binary_middle_endian\""));
  WriteBytes(path, "ply\nformat ascii 2.0\n" + vertex);
  EXPECT_TRUE(Contains(MeshError(path), "unsupported format"));
  WriteBytes(path, "ply\nformat ascii 1.0\nproperty float x\n" + vertex);
  EXPECT_TRUE(Contains(MeshError(path), "header line 3: property before any element"));
  WriteBytes(path, "ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\n");
  EXPECT_TRUE(Contains(MeshError(path), "header line 4: expected \"property <type> <name>\""));
  WriteBytes(path, "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n");
  EXPECT_TRUE(Contains(MeshError(path), path.string() + ": header: no end_header line"));
  WriteBytes(path,
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
             "end_header\n0 0\n");
  EXPECT_TRUE(Contains(MeshError(path), "element vertex: no scalar property z"));
  WriteBytes(path, "ply\nformat ascii 1.0\nelement vertex -1\n");
  EXPECT_TRUE(Contains(MeshError(path), "expected \"element <name> <count>\""));
  WriteBytes(path,
             "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int "
             "vertex_indices\nend_header\n");
  EXPECT_TRUE(Contains(MeshError(path), "no vertex element"));
}

TEST(Ply, TruncatedDataIsRejected) {
  TempDir dir;
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  const auto path = dir / "cut.ply";
  WritePlyMesh(mesh, path);
  const std::string bytes = ReadBytes(path);
  WriteBytes(path, bytes.substr(0, bytes.size() - 3));
  EXPECT_TRUE(Contains(MeshError(path), path.string() + ": element face: truncated data"));
  WriteBytes(path, bytes.substr(0, bytes.size() - 20));
  EXPECT_TRUE(Contains(MeshError(path), "element vertex: truncated data"));
  // A count far beyond the file's size.
  WriteBytes(path,
             "ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000000\n"
             "property float x\nproperty float y\nproperty float z\nend_header\n");
  EXPECT_TRUE(Contains(MeshError(path), "element vertex: truncated data"));
  // The same for ascii.
  WriteBytes(path,
             "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
             "property float z\nend_header\n0 0 0\n1 1\n");
  EXPECT_TRUE(Contains(MeshError(path), "element vertex: truncated data"));
}

TEST(Ply, FaceIndexOutOfRangeIsRejected) {
  TempDir dir;
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}, {0, 2, 3}};
  const auto path = dir / "range.ply";
  WritePlyMesh(mesh, path);
  EXPECT_TRUE(
      Contains(MeshError(path),
               path.string() + ": element face: face 1: vertex index 3 out of range [0, 3)"));
  mesh.triangles = {{0, -1, 2}};
  WritePlyMesh(mesh, path);
  EXPECT_TRUE(Contains(MeshError(path), "vertex index -1 out of range"));
  // Reading as points does not look at faces.
  EXPECT_EQ(ReadPlyPoints(path).points.size(), 3u);
}

TEST(Ply, BadFacesAreRejected) {
  TempDir dir;
  const auto path = dir / "faces.ply";
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\n";
  const std::string vertices = "0 0 0\n1 0 0\n0 1 0\n";
  WriteBytes(path, head + "element face 1\nproperty list uchar int corners\nend_header\n" +
                       vertices + "3 0 1 2\n");
  EXPECT_TRUE(Contains(MeshError(path), "element face: no integer list property vertex_indices"));
  EXPECT_EQ(ReadPlyPoints(path).points.size(), 3u);
  WriteBytes(path, head + "element face 1\nproperty list uchar int vertex_indices\nend_header\n" +
                       vertices + "2 0 1\n");
  EXPECT_TRUE(Contains(MeshError(path), "element face: face 0 has 2 vertices, at least 3 needed"));
}

TEST(Ply, NonNumberInAsciiIsRejected) {
  TempDir dir;
  const auto path = dir / "text.ply";
  WriteBytes(path,
             "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
             "property float z\nend_header\n0 zero 0\n");
  EXPECT_TRUE(Contains(MeshError(path), "element vertex: expected a decimal number"));
}

// The header describes the data exactly: no bytes after the last element (a count lower than
// the data is caught there), and ascii may end in white space only.
TEST(Ply, TrailingBytesAndLowCountsAreRejected) {
  TempDir dir;
  TriangleMesh mesh;
  mesh.vertices = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  mesh.triangles = {{0, 1, 2}};
  const auto path = dir / "extra.ply";
  WritePlyMesh(mesh, path);
  const std::string bytes = ReadBytes(path);
  WriteBytes(path, bytes + "x");
  EXPECT_EQ(MeshError(path),
            path.string() +
                ": data: 1 byte(s) after the last element of the header (its counts are lower than "
                "the data)");
  // One face fewer in the header than in the data.
  std::string low = bytes;
  low.replace(low.find("element face 1"), 14, "element face 0");
  WriteBytes(path, low);
  EXPECT_TRUE(
      Contains(MeshError(path), path.string() + ": data: 13 byte(s) after the last element"));
  // Ascii: trailing white space is fine, a value more is not.
  const std::string ascii =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
  WriteBytes(path, ascii + "\n  \r\n");
  EXPECT_EQ(ReadPlyMesh(path).triangles.size(), 1u);
  WriteBytes(path, ascii + "3 0 1 2\n");
  // The count starts after the last value read ("2", before its newline).
  EXPECT_TRUE(
      Contains(MeshError(path), path.string() + ": data: 9 byte(s) after the last element"));
}

TEST(Ply, NonFiniteCoordinatesAreRejected) {
  TempDir dir;
  const auto path = dir / "nan.ply";
  const float values[] = {std::numeric_limits<float>::quiet_NaN(),
                          std::numeric_limits<float>::infinity(),
                          -std::numeric_limits<float>::infinity()};
  for (const float value : values) {
    std::string bytes =
        "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\n"
        "property float y\nproperty float z\nend_header\n";
    for (const float v : {0.0f, 0.0f, 0.0f, 1.0f, value, 2.0f}) Put(v, false, &bytes);
    WriteBytes(path, bytes);
    EXPECT_TRUE(Contains(MeshError(path),
                         path.string() + ": element vertex: vertex 1: expected finite coordinates"))
        << value;
  }
  // Ascii: strtod's inf, nan and hexadecimal are not decimal numbers; 1e39 overflows a float's
  // range only once stored, so it is read as a double and kept finite.
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
      "property float z\nend_header\n";
  for (const char* token_text : {"inf", "nan", "0x10", "-Infinity"}) {
    const std::string token = token_text;
    WriteBytes(path, head + "0 " + token + " 0\n");
    EXPECT_EQ(MeshError(path),
              path.string() + ": element vertex: expected a decimal number, got \"" + token + "\"")
        << token;
  }
  WriteBytes(path, head + "0 1e309 0\n");
  EXPECT_TRUE(Contains(MeshError(path), "number out of range (too large for a double): \"1e309\""));
}

// A real-valued colour that is not finite (a binary NaN) is refused, not cast.
TEST(Ply, NonFiniteColoursAreRejected) {
  TempDir dir;
  const auto path = dir / "nan_colour.ply";
  for (const float value :
       {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    std::string bytes =
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
        "property float y\nproperty float z\nproperty float red\nproperty float green\n"
        "property float blue\nend_header\n";
    for (const float v : {0.0f, 1.0f, 2.0f, 0.5f, value, 0.5f}) Put(v, false, &bytes);
    WriteBytes(path, bytes);
    EXPECT_TRUE(Contains(MeshError(path),
                         path.string() + ": element vertex: vertex 0: expected a finite colour"))
        << value << ": " << MeshError(path);
  }
}

TEST(Ply, AsciiIntegersMustFitTheirType) {
  TempDir dir;
  const auto path = dir / "ints.ply";
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
      "0 0 0\n1 0 0\n0 1 0\n";
  for (const char* face_text :
       {"3 0 1 2.5", "256 0 1 2", "3 0 1 1e300", "3 0 1 4294967296", "-1 0 1 2", "3 0 1 0x2"}) {
    const std::string face = face_text;
    WriteBytes(path, head + face + "\n");
    EXPECT_TRUE(
        Contains(MeshError(path), path.string() + ": element face: expected an integer of type "))
        << face;
  }
  // A list longer than what is left of the file is truncated data, found before reading it.
  WriteBytes(path, head.substr(0, head.find("uchar int")) +
                       "uint int vertex_indices\nend_header\n" +
                       "0 0 0\n1 0 0\n0 1 0\n4000000000 0 1 2\n");
  EXPECT_TRUE(Contains(MeshError(path), "element face: truncated data"));
}

TEST(Ply, MissingFile) {
  TempDir dir;
  EXPECT_EQ(MeshError(dir / "none.ply"), (dir / "none.ply").string() + ": cannot open");
}

}  // namespace
}  // namespace omni
