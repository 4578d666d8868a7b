#include "eval/primitives.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <utility>

namespace omni {

TriangleMesh MakeBox(const Eigen::Vector3d& min_corner, const Eigen::Vector3d& max_corner) {
  TriangleMesh mesh;
  for (int i = 0; i < 8; ++i) {
    mesh.vertices.emplace_back((i & 1) ? max_corner.x() : min_corner.x(),
                               (i & 2) ? max_corner.y() : min_corner.y(),
                               (i & 4) ? max_corner.z() : min_corner.z());
  }
  // Quads counter-clockwise from outside: -x, +x, -y, +y, -z, +z.
  const int quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& q : quads) {
    mesh.triangles.emplace_back(q[0], q[1], q[2]);
    mesh.triangles.emplace_back(q[0], q[2], q[3]);
  }
  return mesh;
}

TriangleMesh MakeIcosphere(const Eigen::Vector3d& center, double radius, int subdivisions) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> unit = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                                       {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                                       {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& v : unit) v.normalize();
  std::vector<Eigen::Vector3i> faces = {
      {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> midpoint;
    auto mid = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      unit.push_back((unit[a] + unit[b]).normalized());
      const int index = static_cast<int>(unit.size()) - 1;
      midpoint.emplace(key, index);
      return index;
    };
    std::vector<Eigen::Vector3i> finer;
    for (const auto& f : faces) {
      const int ab = mid(f[0], f[1]), bc = mid(f[1], f[2]), ca = mid(f[2], f[0]);
      finer.emplace_back(f[0], ab, ca);
      finer.emplace_back(f[1], bc, ab);
      finer.emplace_back(f[2], ca, bc);
      finer.emplace_back(ab, bc, ca);
    }
    faces = std::move(finer);
  }
  TriangleMesh mesh;
  for (const auto& v : unit) mesh.vertices.push_back(center + radius * v);
  mesh.triangles = std::move(faces);
  return mesh;
}

TriangleMesh MakeTorus(double major_radius, double minor_radius, int major_steps, int minor_steps) {
  TriangleMesh mesh;
  for (int i = 0; i < major_steps; ++i) {
    const double u = 2.0 * M_PI * i / major_steps;
    for (int j = 0; j < minor_steps; ++j) {
      const double v = 2.0 * M_PI * j / minor_steps;
      const double ring = major_radius + minor_radius * std::cos(v);
      mesh.vertices.emplace_back(ring * std::cos(u), ring * std::sin(u),
                                 minor_radius * std::sin(v));
    }
  }
  auto index = [&](int i, int j) { return (i % major_steps) * minor_steps + (j % minor_steps); };
  for (int i = 0; i < major_steps; ++i) {
    for (int j = 0; j < minor_steps; ++j) {
      const int a = index(i, j), b = index(i + 1, j), c = index(i + 1, j + 1), d = index(i, j + 1);
      mesh.triangles.emplace_back(a, b, c);
      mesh.triangles.emplace_back(a, c, d);
    }
  }
  return mesh;
}

void AppendMesh(const TriangleMesh& part, TriangleMesh* mesh) {
  // Labels stay one per triangle: appended when both have them, else none.
  if (mesh->triangles.empty()) {
    mesh->labels = part.labels;
  } else if (!mesh->labels.empty() && !part.labels.empty()) {
    mesh->labels.insert(mesh->labels.end(), part.labels.begin(), part.labels.end());
  } else {
    mesh->labels.clear();
  }
  const int offset = static_cast<int>(mesh->vertices.size());
  mesh->vertices.insert(mesh->vertices.end(), part.vertices.begin(), part.vertices.end());
  for (const auto& tri : part.triangles) {
    mesh->triangles.push_back(tri + Eigen::Vector3i::Constant(offset));
  }
}

TriangleMesh WeldVertices(const TriangleMesh& mesh) {
  auto less = [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
    return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
  };
  std::map<Eigen::Vector3d, int, decltype(less)> index_of(less);
  TriangleMesh welded;
  std::vector<int> new_index(mesh.vertices.size());
  for (size_t v = 0; v < mesh.vertices.size(); ++v) {
    auto [it, inserted] =
        index_of.emplace(mesh.vertices[v], static_cast<int>(welded.vertices.size()));
    if (inserted) welded.vertices.push_back(mesh.vertices[v]);
    new_index[v] = it->second;
  }
  for (const auto& tri : mesh.triangles) {
    welded.triangles.emplace_back(new_index[tri[0]], new_index[tri[1]], new_index[tri[2]]);
  }
  welded.labels = mesh.labels;
  return welded;
}

TriangleMesh FlipOrientation(const TriangleMesh& mesh) {
  TriangleMesh flipped = mesh;
  for (auto& tri : flipped.triangles) std::swap(tri[1], tri[2]);
  return flipped;
}

double SignedVolume(const TriangleMesh& mesh) {
  double volume = 0.0;
  for (const auto& tri : mesh.triangles) {
    volume += mesh.vertices[tri[0]].dot(mesh.vertices[tri[1]].cross(mesh.vertices[tri[2]]));
  }
  return volume / 6.0;
}

TriangleMesh OffsetAlongNormals(const TriangleMesh& mesh, double distance) {
  std::vector<Eigen::Vector3d> normals(mesh.vertices.size(), Eigen::Vector3d::Zero());
  for (const auto& tri : mesh.triangles) {
    const Eigen::Vector3d n = (mesh.vertices[tri[1]] - mesh.vertices[tri[0]])
                                  .cross(mesh.vertices[tri[2]] - mesh.vertices[tri[0]]);
    for (int k = 0; k < 3; ++k) normals[tri[k]] += n;
  }
  TriangleMesh moved = mesh;
  for (size_t v = 0; v < moved.vertices.size(); ++v) {
    if (normals[v].squaredNorm() > 0.0) {
      moved.vertices[v] += distance * normals[v].normalized();
    }
  }
  return moved;
}

}  // namespace omni
