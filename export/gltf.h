#pragma once
// Mesh files for other programs: binary glTF 2.0 (.glb) and Wavefront OBJ, written by hand.
//
// The .glb holds one scene with a root node "world" whose rotation turns the reconstruction's
// z-up world into glTF's y-up (the vertices are stored in world coordinates, unchanged), and
// under it up to two meshes: "surface" (one TRIANGLES primitive: POSITION float VEC3 with
// min/max, COLOR_0 normalised unsigned byte VEC4 when the mesh has colours, indices unsigned
// int) and "points" (one POINTS primitive: POSITION, COLOR_0 when the cloud has colours). Every
// bufferView starts on a 4-byte boundary; the JSON chunk is padded with spaces, the BIN chunk
// with zeros (glTF 2.0 §4.4).

#include <cstdint>
#include <filesystem>
#include <string>

#include "calib/ply.h"

namespace omni {

// The .glb bytes. An empty mesh or cloud makes no mesh of that name; throws
// std::invalid_argument when both are empty, when colours do not match the vertices in number,
// or when a triangle's index is out of range.
std::string EncodeGlb(const TriangleMesh& mesh, const PointCloud& points);
// EncodeGlb written atomically.
void WriteGlb(const TriangleMesh& mesh, const PointCloud& points,
              const std::filesystem::path& path);

// OBJ: "v x y z" (with " r g b" in [0, 1] when the mesh has colours, as MeshLab and Blender
// read them) and "f a b c" (1-based), written atomically. std::invalid_argument as above.
void WriteObj(const TriangleMesh& mesh, const std::filesystem::path& path);

}  // namespace omni
