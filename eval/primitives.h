#pragma once
// Small closed meshes (boxes, spheres, tori) for the evaluation's tests and benchmarks.
// Triangles are counter-clockwise seen from outside.

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "calib/ply.h"

namespace omni {

// Axis-aligned box: 8 vertices, 12 triangles.
TriangleMesh MakeBox(const Eigen::Vector3d& min_corner, const Eigen::Vector3d& max_corner);
// Icosahedron subdivided `subdivisions` times, vertices on the sphere.
TriangleMesh MakeIcosphere(const Eigen::Vector3d& center, double radius, int subdivisions);
// Torus around the z axis: major radius R, minor radius r, n x m quads split in two.
TriangleMesh MakeTorus(double major_radius, double minor_radius, int major_steps, int minor_steps);
// Appends `part` to `mesh` (no vertex welding); the labels are appended when both meshes have
// them (or `mesh` has no triangle yet), else dropped.
void AppendMesh(const TriangleMesh& part, TriangleMesh* mesh);
// Merges vertices at exactly the same position (first one kept), renumbering triangles (their
// labels kept; the colours dropped).
TriangleMesh WeldVertices(const TriangleMesh& mesh);
// Reverses every triangle (the inside becomes the outside: a box becomes a room).
TriangleMesh FlipOrientation(const TriangleMesh& mesh);
// Signed volume enclosed (positive when triangles face outwards).
double SignedVolume(const TriangleMesh& mesh);
// Moves every vertex by `distance` along its vertex normal (area-weighted mean of the normals
// of its triangles; outward for the meshes above).
TriangleMesh OffsetAlongNormals(const TriangleMesh& mesh, double distance);

}  // namespace omni
