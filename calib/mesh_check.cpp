#include "calib/mesh_check.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cstdint>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>

#include "calib/error.h"

namespace omni {
namespace {

class UnionFind {
 public:
  explicit UnionFind(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  int Find(int x) {
    while (parent_[x] != x) {
      parent_[x] = parent_[parent_[x]];
      x = parent_[x];
    }
    return x;
  }
  void Union(int a, int b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<int> parent_;
};

uint64_t EdgeKey(int a, int b) {
  const auto lo = static_cast<uint64_t>(std::min(a, b));
  const auto hi = static_cast<uint64_t>(std::max(a, b));
  return (lo << 32) | hi;
}

enum class LinkShape { kCycle, kPath, kOther };

// The link of a vertex: the edges opposite to it in its triangles. One cycle for an interior
// manifold vertex, one path for a boundary one.
LinkShape ClassifyLink(std::vector<std::pair<int, int>>& link_edges) {
  std::vector<int> ends;
  ends.reserve(2 * link_edges.size());
  for (const auto& [a, b] : link_edges) {
    ends.push_back(a);
    ends.push_back(b);
  }
  std::sort(ends.begin(), ends.end());
  std::vector<int> ids = ends;
  ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
  auto local = [&ids](int v) {
    return static_cast<int>(std::lower_bound(ids.begin(), ids.end(), v) - ids.begin());
  };
  std::vector<int> degree(ids.size(), 0);
  for (int v : ends) ++degree[local(v)];
  int ones = 0;
  for (int d : degree) {
    if (d == 1) {
      ++ones;
    } else if (d != 2) {
      return LinkShape::kOther;
    }
  }
  UnionFind link_components(ids.size());
  for (const auto& [a, b] : link_edges) link_components.Union(local(a), local(b));
  for (size_t i = 1; i < ids.size(); ++i) {
    if (link_components.Find(static_cast<int>(i)) != link_components.Find(0)) {
      return LinkShape::kOther;
    }
  }
  if (ones == 0) return LinkShape::kCycle;
  if (ones == 2) return LinkShape::kPath;
  return LinkShape::kOther;
}

}  // namespace

std::string MeshCheckOptions::Check() const {
  if (!(degenerate_area_ratio >= 0.0)) return "degenerate_area_ratio: must be >= 0";
  if (max_listed_components < 0) return "max_listed_components: must be >= 0";
  return {};
}

MeshCheckReport CheckMesh(const TriangleMesh& mesh, const MeshCheckOptions& options) {
  MeshCheckReport report;
  const int num_vertices = static_cast<int>(mesh.vertices.size());
  report.vertices = num_vertices;
  report.triangles = static_cast<long>(mesh.triangles.size());

  // Triangles that enter the topology: distinct indices (zero-area ones stay, they are still
  // faces of the complex).
  std::vector<int> topo_triangles;
  topo_triangles.reserve(mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    for (int k = 0; k < 3; ++k) {
      if (tri[k] < 0 || tri[k] >= num_vertices) {
        throw InputError("", "triangles",
                         "triangle " + std::to_string(t) + " indexes vertex " +
                             std::to_string(tri[k]) + " of " + std::to_string(num_vertices));
      }
    }
    if (tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2]) {
      ++report.repeated_index_triangles;
      ++report.degenerate_triangles;
      continue;
    }
    const Eigen::Vector3d& p0 = mesh.vertices[tri[0]];
    const Eigen::Vector3d& p1 = mesh.vertices[tri[1]];
    const Eigen::Vector3d& p2 = mesh.vertices[tri[2]];
    const double area = 0.5 * (p1 - p0).cross(p2 - p0).norm();
    const double longest =
        std::max({(p1 - p0).squaredNorm(), (p2 - p1).squaredNorm(), (p0 - p2).squaredNorm()});
    if (area <= options.degenerate_area_ratio * longest) ++report.degenerate_triangles;
    topo_triangles.push_back(static_cast<int>(t));
  }

  // Duplicate triangles (same vertex set).
  {
    std::vector<std::array<int, 3>> sorted;
    sorted.reserve(topo_triangles.size());
    for (int t : topo_triangles) {
      std::array<int, 3> s = {mesh.triangles[t][0], mesh.triangles[t][1], mesh.triangles[t][2]};
      std::sort(s.begin(), s.end());
      sorted.push_back(s);
    }
    std::sort(sorted.begin(), sorted.end());
    for (size_t i = 1; i < sorted.size(); ++i) {
      if (sorted[i] == sorted[i - 1]) ++report.duplicate_triangles;
    }
  }

  // Components through shared vertices.
  UnionFind vertex_sets(num_vertices);
  std::vector<char> referenced(num_vertices, 0);
  for (int t : topo_triangles) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    vertex_sets.Union(tri[0], tri[1]);
    vertex_sets.Union(tri[1], tri[2]);
    for (int k = 0; k < 3; ++k) referenced[tri[k]] = 1;
  }
  std::vector<int> component_of_root(num_vertices, -1);
  std::vector<MeshComponentReport> components;
  for (int v = 0; v < num_vertices; ++v) {
    if (!referenced[v]) {
      ++report.unreferenced_vertices;
      continue;
    }
    const int root = vertex_sets.Find(v);
    if (component_of_root[root] < 0) {
      component_of_root[root] = static_cast<int>(components.size());
      components.emplace_back();
      components.back().closed = components.back().manifold = components.back().oriented = true;
    }
    ++components[component_of_root[root]].vertices;
  }
  auto component_of = [&](int v) { return component_of_root[vertex_sets.Find(v)]; };
  for (int t : topo_triangles) ++components[component_of(mesh.triangles[t][0])].triangles;

  // Edges: each triangle uses its three edges in a direction; an interior edge of an oriented
  // manifold is used once in each direction.
  struct HalfEdge {
    uint64_t key;
    bool forward;  // used from the smaller index to the larger
  };
  std::vector<HalfEdge> half_edges;
  half_edges.reserve(3 * topo_triangles.size());
  for (int t : topo_triangles) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    for (int k = 0; k < 3; ++k) {
      const int a = tri[k];
      const int b = tri[(k + 1) % 3];
      half_edges.push_back({EdgeKey(a, b), a < b});
    }
  }
  std::sort(half_edges.begin(), half_edges.end(),
            [](const HalfEdge& x, const HalfEdge& y) { return x.key < y.key; });
  UnionFind boundary_sets(num_vertices);
  std::vector<char> on_boundary(num_vertices, 0);
  for (size_t i = 0; i < half_edges.size();) {
    size_t j = i;
    int forward = 0;
    while (j < half_edges.size() && half_edges[j].key == half_edges[i].key) {
      forward += half_edges[j].forward ? 1 : 0;
      ++j;
    }
    const size_t count = j - i;
    MeshComponentReport& component =
        components[component_of(static_cast<int>(half_edges[i].key >> 32))];
    ++report.edges;
    ++component.edges;
    if (count == 1) {
      ++report.boundary_edges;
      component.closed = false;
      const int a = static_cast<int>(half_edges[i].key >> 32);
      const int b = static_cast<int>(half_edges[i].key & 0xffffffffu);
      boundary_sets.Union(a, b);
      on_boundary[a] = on_boundary[b] = 1;
    } else if (count > 2) {
      ++report.nonmanifold_edges;
      component.closed = component.manifold = false;
    } else if (forward != 1) {
      ++report.misoriented_edges;
      component.oriented = false;
    }
    i = j;
  }

  // Boundary loops: the cycle rank of the boundary edges' graph.
  {
    long boundary_vertices = 0, boundary_components = 0;
    for (int v = 0; v < num_vertices; ++v) {
      if (!on_boundary[v]) continue;
      ++boundary_vertices;
      if (boundary_sets.Find(v) == v) ++boundary_components;
    }
    report.boundary_loops = report.boundary_edges - boundary_vertices + boundary_components;
  }

  // Vertex links, over a vertex -> triangles table.
  std::vector<int> first(num_vertices + 1, 0);
  for (int t : topo_triangles) {
    for (int k = 0; k < 3; ++k) ++first[mesh.triangles[t][k] + 1];
  }
  std::partial_sum(first.begin(), first.end(), first.begin());
  std::vector<int> incident(first.back());
  {
    std::vector<int> fill(first.begin(), first.end() - 1);
    for (int t : topo_triangles) {
      for (int k = 0; k < 3; ++k) incident[fill[mesh.triangles[t][k]]++] = t;
    }
  }
  std::vector<std::pair<int, int>> link_edges;
  for (int v = 0; v < num_vertices; ++v) {
    if (!referenced[v]) continue;
    link_edges.clear();
    for (int i = first[v]; i < first[v + 1]; ++i) {
      const Eigen::Vector3i& tri = mesh.triangles[incident[i]];
      const int k = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
      link_edges.emplace_back(tri[(k + 1) % 3], tri[(k + 2) % 3]);
    }
    const LinkShape shape = ClassifyLink(link_edges);
    if (shape != LinkShape::kCycle) ++report.vertices_link_not_cycle;
    if (shape == LinkShape::kOther) {
      ++report.nonmanifold_vertices;
      components[component_of(v)].manifold = false;
    }
  }

  // Euler characteristic and genus, per component and in total.
  report.components = static_cast<long>(components.size());
  bool every_genus = !components.empty();
  report.genus = 0;
  for (MeshComponentReport& component : components) {
    component.euler_characteristic = component.vertices - component.edges + component.triangles;
    report.euler_characteristic += component.euler_characteristic;
    if (component.closed && component.manifold) ++report.closed_components;
    if (component.closed && component.manifold && component.oriented) {
      component.genus = static_cast<int>((2 - component.euler_characteristic) / 2);
      report.genus += component.genus;
    } else {
      every_genus = false;
    }
  }
  if (!every_genus) report.genus = -1;
  std::stable_sort(components.begin(), components.end(),
                   [](const MeshComponentReport& a, const MeshComponentReport& b) {
                     return a.triangles > b.triangles;
                   });
  if (static_cast<int>(components.size()) > options.max_listed_components) {
    components.resize(options.max_listed_components);
  }
  report.listed_components = std::move(components);

  const bool manifold = report.nonmanifold_edges == 0 && report.nonmanifold_vertices == 0;
  report.closed_manifold =
      manifold && report.boundary_edges == 0 && report.vertices_link_not_cycle == 0;
  report.oriented = report.misoriented_edges == 0;
  report.ok = (report.triangles > 0 || options.allow_empty) &&
              (report.closed_manifold || (options.allow_boundary && manifold)) && report.oriented &&
              report.degenerate_triangles == 0 && report.duplicate_triangles == 0;
  return report;
}

std::string MeshCheckReport::Summary() const {
  std::ostringstream out;
  out << "V=" << vertices - unreferenced_vertices << " E=" << edges << " F=" << triangles
      << " chi=" << euler_characteristic << " components=" << components
      << " degenerate=" << degenerate_triangles << " duplicate=" << duplicate_triangles
      << " boundary_edges=" << boundary_edges << " boundary_loops=" << boundary_loops
      << " nonmanifold_edges=" << nonmanifold_edges << " misoriented_edges=" << misoriented_edges
      << " vertices_link_not_cycle=" << vertices_link_not_cycle
      << " nonmanifold_vertices=" << nonmanifold_vertices << (ok ? " ok" : " NOT ok");
  return out.str();
}

std::string MeshCheckReport::ToText() const {
  std::ostringstream out;
  out << "vertices " << vertices << " (unreferenced " << unreferenced_vertices << ")\n"
      << "triangles " << triangles << " (degenerate " << degenerate_triangles << ", duplicate "
      << duplicate_triangles << ")\n"
      << "edges " << edges << " (boundary " << boundary_edges << ", in more than two triangles "
      << nonmanifold_edges << ", misoriented " << misoriented_edges << ")\n"
      << "boundary loops " << boundary_loops << "\n"
      << "vertices whose link is not one cycle " << vertices_link_not_cycle
      << " (neither cycle nor path " << nonmanifold_vertices << ")\n"
      << "components " << components << " (closed " << closed_components << ")\n"
      << "euler characteristic " << euler_characteristic << ", genus "
      << (genus >= 0 ? std::to_string(genus) : std::string("undefined")) << "\n"
      << "closed 2-manifold " << (closed_manifold ? "yes" : "no") << ", oriented "
      << (oriented ? "yes" : "no") << "\n"
      << (ok ? "OK" : "NOT OK") << "\n";
  return out.str();
}

std::string MeshCheckReport::ToJson() const {
  nlohmann::json json = {{"vertices", vertices},
                         {"unreferenced_vertices", unreferenced_vertices},
                         {"triangles", triangles},
                         {"degenerate_triangles", degenerate_triangles},
                         {"repeated_index_triangles", repeated_index_triangles},
                         {"duplicate_triangles", duplicate_triangles},
                         {"edges", edges},
                         {"boundary_edges", boundary_edges},
                         {"boundary_loops", boundary_loops},
                         {"nonmanifold_edges", nonmanifold_edges},
                         {"misoriented_edges", misoriented_edges},
                         {"vertices_link_not_cycle", vertices_link_not_cycle},
                         {"nonmanifold_vertices", nonmanifold_vertices},
                         {"components", components},
                         {"closed_components", closed_components},
                         {"euler_characteristic", euler_characteristic},
                         {"genus", genus},
                         {"closed_manifold", closed_manifold},
                         {"oriented", oriented},
                         {"ok", ok}};
  nlohmann::json listed = nlohmann::json::array();
  for (const MeshComponentReport& c : listed_components) {
    listed.push_back({{"vertices", c.vertices},
                      {"edges", c.edges},
                      {"triangles", c.triangles},
                      {"euler_characteristic", c.euler_characteristic},
                      {"closed", c.closed},
                      {"manifold", c.manifold},
                      {"oriented", c.oriented},
                      {"genus", c.genus}});
  }
  json["listed_components"] = listed;
  return json.dump(2);
}

}  // namespace omni
