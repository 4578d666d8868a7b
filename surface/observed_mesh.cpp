#include "surface/observed_mesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <unordered_map>

#include "calib/error.h"

namespace omni {
namespace {

// Vertex -> the triangles incident to it (indices in `triangles`), as offsets into one array.
struct Incidence {
  std::vector<int> first, triangles;
  Incidence(const std::vector<Eigen::Vector3i>& mesh, size_t num_vertices)
      : first(num_vertices + 1, 0) {
    for (const Eigen::Vector3i& t : mesh) {
      for (int k = 0; k < 3; ++k) ++first[t[k] + 1];
    }
    std::partial_sum(first.begin(), first.end(), first.begin());
    triangles.resize(first.back());
    std::vector<int> fill(first.begin(), first.end() - 1);
    for (size_t i = 0; i < mesh.size(); ++i) {
      for (int k = 0; k < 3; ++k) triangles[fill[mesh[i][k]]++] = static_cast<int>(i);
    }
  }
};

int Find(std::vector<int>& parent, int x) {
  while (parent[x] != x) {
    parent[x] = parent[parent[x]];
    x = parent[x];
  }
  return x;
}

// The length that subtends `angle` at the distance from the centroid of triangle t to the
// nearest optical centre of its vertices' rays (the chord of the angle at that distance).
double EdgeLengthWithinAngle(const std::vector<Eigen::Vector3d>& p, const Eigen::Vector3i& t,
                             const std::vector<ObservedVertex>& vertices, double angle) {
  const Eigen::Vector3d centroid = (p[t[0]] + p[t[1]] + p[t[2]]) / 3.0;
  double nearest_squared = std::numeric_limits<double>::infinity();
  for (int k = 0; k < 3; ++k) {
    for (const Eigen::Vector3d& origin : *vertices[t[k]].origins) {
      nearest_squared = std::min(nearest_squared, (origin - centroid).squaredNorm());
    }
  }
  return 2.0 * std::sqrt(nearest_squared) * std::sin(0.5 * angle);
}

enum TriangleState : char { kDropped, kKept, kCandidate };

Eigen::Vector3d TriangleNormal(const std::vector<Eigen::Vector3d>& p, const Eigen::Vector3i& t) {
  return (p[t[1]] - p[t[0]]).cross(p[t[2]] - p[t[0]]).normalized();
}

// Turns into kKept every kCandidate reached from a kKept triangle through shared edges between
// triangles whose normals are within max_normal_angle; returns how many.
size_t GrowAcrossEdges(const std::vector<Eigen::Vector3i>& triangles,
                       const std::vector<Eigen::Vector3d>& p, double max_normal_angle,
                       std::vector<char>* state) {
  std::vector<char>& s = *state;
  auto key = [](int from, int to) {
    return (static_cast<uint64_t>(static_cast<uint32_t>(from)) << 32) | static_cast<uint32_t>(to);
  };
  // A candidate's directed edges: the triangle across edge a -> b holds b -> a.
  std::unordered_map<uint64_t, int> candidate_with_edge;
  for (size_t i = 0; i < triangles.size(); ++i) {
    if (s[i] != kCandidate) continue;
    for (int k = 0; k < 3; ++k)
      candidate_with_edge[key(triangles[i][k], triangles[i][(k + 1) % 3])] = static_cast<int>(i);
  }
  if (candidate_with_edge.empty()) return 0;
  const double min_cosine = std::cos(max_normal_angle);
  std::vector<int> queue;
  for (size_t i = 0; i < triangles.size(); ++i) {
    if (s[i] == kKept) queue.push_back(static_cast<int>(i));
  }
  size_t grown = 0;
  while (!queue.empty()) {
    const int i = queue.back();
    queue.pop_back();
    const Eigen::Vector3i& t = triangles[i];
    const Eigen::Vector3d normal = TriangleNormal(p, t);
    for (int k = 0; k < 3; ++k) {
      const auto across = candidate_with_edge.find(key(t[(k + 1) % 3], t[k]));
      if (across == candidate_with_edge.end() || s[across->second] != kCandidate) continue;
      if (normal.dot(TriangleNormal(p, triangles[across->second])) < min_cosine) continue;
      s[across->second] = kKept;
      ++grown;
      queue.push_back(across->second);
    }
  }
  return grown;
}

}  // namespace

std::string ObservedMeshOptions::Check() const {
  if (!(max_edge_factor >= 0.0) || !std::isfinite(max_edge_factor)) {
    return "observed.max_edge_factor must be >= 0 (0: no bound)";
  }
  if (!(max_edge_angle >= 0.0 && max_edge_angle < M_PI)) {
    return "observed.max_edge_angle must be in [0, pi) (0: off)";
  }
  if (!(max_spacing_factor >= 0.0) || !std::isfinite(max_spacing_factor)) {
    return "observed.max_spacing_factor must be >= 0 (0: no bound)";
  }
  if (!(min_view_cosine >= -1.0 && min_view_cosine < 1.0)) {
    return "observed.min_view_cosine must be in [-1, 1)";
  }
  if (min_component_triangles < 0) return "observed.min_component_triangles must be >= 0";
  if (!(grow_max_edge_factor >= 0.0) || !std::isfinite(grow_max_edge_factor)) {
    return "observed.grow_max_edge_factor must be >= 0 (0: off)";
  }
  if (!(grow_max_normal_angle > 0.0 && grow_max_normal_angle < M_PI)) {
    return "observed.grow_max_normal_angle must be in (0, pi)";
  }
  return "";
}

size_t RepairTouchingBoundaries(std::vector<Eigen::Vector3i>* triangles, size_t num_vertices) {
  std::vector<Eigen::Vector3i>& mesh = *triangles;
  const Incidence incidence(mesh, num_vertices);
  std::vector<char> dropped(mesh.size(), 0), queued(num_vertices, 1);
  std::vector<int> queue(num_vertices);
  std::iota(queue.begin(), queue.end(), 0);
  // The link of v: for each triangle (v, b, c) counter-clockwise, the directed edge b -> c. On a
  // subset of a closed oriented 2-manifold each link vertex has at most one edge in and one out,
  // so the link is its whole cycle or paths (fans of triangles).
  struct LinkEdge {
    int from, to, triangle;
  };
  std::vector<LinkEdge> link;
  std::vector<int> fan_of, fan_size;
  size_t num_dropped = 0;
  while (!queue.empty()) {
    const int v = queue.back();
    queue.pop_back();
    queued[v] = 0;
    link.clear();
    for (int i = incidence.first[v]; i < incidence.first[v + 1]; ++i) {
      const int t = incidence.triangles[i];
      if (dropped[t]) continue;
      const Eigen::Vector3i& tri = mesh[t];
      const int k = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
      link.push_back({tri[(k + 1) % 3], tri[(k + 2) % 3], t});
    }
    if (link.size() < 2) continue;
    // Fans: follow each path from an edge that no other edge enters.
    auto edge_from = [&link](int vertex) {
      for (size_t e = 0; e < link.size(); ++e) {
        if (link[e].from == vertex) return static_cast<int>(e);
      }
      return -1;
    };
    auto entered = [&link](int vertex) {
      for (const LinkEdge& e : link) {
        if (e.to == vertex) return true;
      }
      return false;
    };
    fan_of.assign(link.size(), -1);
    fan_size.clear();
    for (size_t e = 0; e < link.size(); ++e) {
      if (entered(link[e].from)) continue;
      const int fan = static_cast<int>(fan_size.size());
      fan_size.push_back(0);
      for (int f = static_cast<int>(e); f >= 0 && fan_of[f] < 0; f = edge_from(link[f].to)) {
        fan_of[f] = fan;
        ++fan_size[fan];
      }
    }
    if (fan_size.size() < 2) continue;  // one cycle (no fan start) or one path
    const int largest =
        static_cast<int>(std::max_element(fan_size.begin(), fan_size.end()) - fan_size.begin());
    for (size_t e = 0; e < link.size(); ++e) {
      if (fan_of[e] == largest) continue;
      dropped[link[e].triangle] = 1;
      ++num_dropped;
      for (int vertex : {link[e].from, link[e].to}) {
        if (!queued[vertex]) {
          queued[vertex] = 1;
          queue.push_back(vertex);
        }
      }
    }
  }
  size_t out = 0;
  for (size_t t = 0; t < mesh.size(); ++t) {
    if (!dropped[t]) mesh[out++] = mesh[t];
  }
  mesh.resize(out);
  return num_dropped;
}

TriangleMesh SelectObservedMesh(const TriangleMesh& closed,
                                const std::vector<ObservedVertex>& vertices, double scale,
                                const ObservedMeshOptions& options, std::vector<int>* kept_vertices,
                                ObservedMeshStats* stats) {
  ThrowIfInvalid(options.Check(), "ObservedMeshOptions");
  if (vertices.size() != closed.vertices.size()) {
    throw std::invalid_argument("SelectObservedMesh: " + std::to_string(vertices.size()) +
                                " vertex records for " + std::to_string(closed.vertices.size()) +
                                " vertices");
  }
  ObservedMeshStats st;
  st.closed_triangles = closed.triangles.size();
  const size_t n = closed.vertices.size();
  const auto& p = closed.vertices;

  // Local spacing: each point's shortest δO edge to another point.
  std::vector<double> spacing(n, std::numeric_limits<double>::infinity());
  if (options.max_spacing_factor > 0.0) {
    for (const Eigen::Vector3i& t : closed.triangles) {
      for (int k = 0; k < 3; ++k) {
        const int a = t[k], b = t[(k + 1) % 3];
        if (!vertices[a].origins || !vertices[b].origins) continue;
        const double length = (p[a] - p[b]).norm();
        spacing[a] = std::min(spacing[a], length);
        spacing[b] = std::min(spacing[b], length);
      }
    }
  }

  // Each triangle of δO: kept, a growth candidate (dropped for its edges alone), or dropped.
  std::vector<char> state(closed.triangles.size(), kDropped);
  const double max_edge = options.max_edge_factor > 0.0 ? options.max_edge_factor * scale
                                                        : std::numeric_limits<double>::infinity();
  const double grow_max_edge = options.grow_max_edge_factor * scale;
  for (size_t i = 0; i < closed.triangles.size(); ++i) {
    const Eigen::Vector3i& t = closed.triangles[i];
    if (!vertices[t[0]].origins || !vertices[t[1]].origins || !vertices[t[2]].origins) {
      ++st.steiner;
      continue;
    }
    const double longest = std::max(
        {(p[t[0]] - p[t[1]]).norm(), (p[t[1]] - p[t[2]]).norm(), (p[t[2]] - p[t[0]]).norm()});
    const bool small_in_view =
        options.max_edge_angle > 0.0 &&
        longest <= EdgeLengthWithinAngle(p, t, vertices, options.max_edge_angle);
    bool long_edges = false;
    if (longest > max_edge && !small_in_view) {
      if (!(longest <= grow_max_edge)) {
        ++st.long_edges;
        continue;
      }
      long_edges = true;
    }
    if (!long_edges && options.max_spacing_factor > 0.0 && !small_in_view) {
      const double local = std::max({spacing[t[0]], spacing[t[1]], spacing[t[2]]});
      if (longest > options.max_spacing_factor * local) {
        ++st.sparse;
        continue;
      }
    }
    if (options.require_seen) {
      const Eigen::Vector3d normal = TriangleNormal(p, t);
      const Eigen::Vector3d centroid = (p[t[0]] + p[t[1]] + p[t[2]]) / 3.0;
      bool seen = false;
      for (int k = 0; k < 3 && !seen; ++k) {
        for (const Eigen::Vector3d& origin : *vertices[t[k]].origins) {
          const Eigen::Vector3d to_origin = origin - centroid;
          if (normal.dot(to_origin) > options.min_view_cosine * to_origin.norm()) {
            seen = true;
            break;
          }
        }
      }
      if (!seen) {
        ++(long_edges ? st.long_edges : st.unseen);
        continue;
      }
    }
    state[i] = long_edges ? kCandidate : kKept;
  }

  if (grow_max_edge > 0.0) {
    st.grown = GrowAcrossEdges(closed.triangles, p, options.grow_max_normal_angle, &state);
  }

  std::vector<Eigen::Vector3i> kept;
  kept.reserve(closed.triangles.size());
  for (size_t i = 0; i < closed.triangles.size(); ++i) {
    if (state[i] == kKept) kept.push_back(closed.triangles[i]);
    if (state[i] == kCandidate) ++st.long_edges;
  }

  st.manifold_repair = RepairTouchingBoundaries(&kept, n);

  if (options.min_component_triangles > 1) {
    std::vector<int> parent(n);
    std::iota(parent.begin(), parent.end(), 0);
    for (const Eigen::Vector3i& t : kept) {
      for (int k = 0; k < 2; ++k) {
        const int a = Find(parent, t[k]), b = Find(parent, t[k + 1]);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    }
    std::vector<int> size(n, 0);
    for (const Eigen::Vector3i& t : kept) ++size[Find(parent, t[0])];
    size_t out = 0;
    for (const Eigen::Vector3i& t : kept) {
      if (size[Find(parent, t[0])] >= options.min_component_triangles) kept[out++] = t;
    }
    st.small_components = kept.size() - out;
    kept.resize(out);
  }

  // Compact the vertices, in their order in `closed`.
  std::vector<int> index(n, -1);
  for (const Eigen::Vector3i& t : kept) {
    for (int k = 0; k < 3; ++k) index[t[k]] = 0;
  }
  TriangleMesh mesh;
  std::vector<int> kept_list;
  const bool colored = closed.colors.size() == n;
  for (size_t v = 0; v < n; ++v) {
    if (index[v] < 0) continue;
    index[v] = static_cast<int>(mesh.vertices.size());
    mesh.vertices.push_back(p[v]);
    if (colored) mesh.colors.push_back(closed.colors[v]);
    kept_list.push_back(static_cast<int>(v));
  }
  mesh.triangles.reserve(kept.size());
  for (const Eigen::Vector3i& t : kept)
    mesh.triangles.emplace_back(index[t[0]], index[t[1]], index[t[2]]);
  st.triangles = mesh.triangles.size();
  if (kept_vertices) *kept_vertices = std::move(kept_list);
  if (stats) *stats = st;
  return mesh;
}

}  // namespace omni
