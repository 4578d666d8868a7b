#pragma once
// PLY meshes and point clouds: read ascii and binary (little and big endian), write binary
// little endian (float coordinates, uchar colours, int vertex indices).

#include <Eigen/Core>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace omni {

using Rgb8 = Eigen::Matrix<uint8_t, 3, 1>;  // red, green, blue

struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Vector3i> triangles;  // counter-clockwise seen from the side it faces
  std::vector<Rgb8> colors;                // empty, or one per vertex
  // Empty, or one per triangle: what the triangle belongs to (synth's ground truth labels its
  // triangles by kind of surface; the names are the drive's, gt/scene.json "mesh_labels").
  std::vector<uint8_t> labels;
};

struct PointCloud {
  std::vector<Eigen::Vector3d> points;
  std::vector<Rgb8> colors;  // empty, or one per point
};

// Throws InputError naming the file on malformed input: a header that does not describe the
// data exactly (the file must end after the last element's rows: no missing and no trailing
// bytes; ascii may end in white space), a vertex coordinate that is not finite, an ascii value
// that is not a decimal number of its type (no hexadecimal, inf or nan; integers in the type's
// range), a face index out of range. Faces with more than three vertices are split into fans.
// A scalar integer face property `label` gives TriangleMesh::labels, the face's label on each
// triangle of its fan, when every value is from 0 to 255 (otherwise the mesh has no labels).
TriangleMesh ReadPlyMesh(const std::filesystem::path& path);
PointCloud ReadPlyPoints(const std::filesystem::path& path);
// The same on the bytes of a file in memory; `source` names it in the errors.
TriangleMesh ParsePlyMesh(const std::string& data, const std::filesystem::path& source);
PointCloud ParsePlyPoints(const std::string& data, const std::filesystem::path& source);
// Written atomically, with red/green/blue uchar vertex properties when the mesh or the cloud
// has colours (std::invalid_argument when their number is not that of the vertices), and a
// uchar face property `label` when the mesh has labels (std::invalid_argument when their number
// is not that of the triangles).
void WritePlyMesh(const TriangleMesh& mesh, const std::filesystem::path& path);
void WritePlyPoints(const PointCloud& cloud, const std::filesystem::path& path);

}  // namespace omni
