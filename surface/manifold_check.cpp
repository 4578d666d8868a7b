#include "surface/manifold_check.h"

#include <algorithm>
#include <array>
#include <map>
#include <numeric>
#include <set>
#include <sstream>
#include <unordered_map>
#include <vector>

namespace omni {
namespace {

struct UnionFind {
  std::vector<int> parent;
  explicit UnionFind(size_t n) : parent(n) { std::iota(parent.begin(), parent.end(), 0); }
  int Find(int a) { return parent[a] == a ? a : parent[a] = Find(parent[a]); }
  void Unite(int a, int b) { parent[Find(a)] = Find(b); }
};

}  // namespace

std::string ManifoldReport::Summary() const {
  std::ostringstream s;
  s << "V=" << vertices << " E=" << edges << " F=" << triangles << " chi=" << euler_characteristic
    << " components=" << components << " degenerate=" << degenerate_triangles
    << " duplicate=" << duplicate_triangles << " edges_not_in_two=" << edges_not_in_two
    << " vertices_not_one_cycle=" << vertices_not_one_cycle
    << " misoriented_edges=" << misoriented_edges;
  return s.str();
}

ManifoldReport CheckManifold(const TriangleMesh& mesh) {
  ManifoldReport r;
  r.triangles = mesh.triangles.size();
  const int n = static_cast<int>(mesh.vertices.size());
  // Undirected edge -> (count, directed uses a->b with a<b minus b->a).
  std::map<std::pair<int, int>, std::pair<int, int>> edges;
  std::set<std::array<int, 3>> seen;
  std::vector<std::vector<std::pair<int, int>>> link(n);  // per vertex: v-opposite edges
  UnionFind components(n);
  std::vector<bool> used(n, false);
  for (const Eigen::Vector3i& t : mesh.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) {
      ++r.degenerate_triangles;
      continue;
    }
    std::array<int, 3> key = {t[0], t[1], t[2]};
    std::sort(key.begin(), key.end());
    if (!seen.insert(key).second) ++r.duplicate_triangles;
    for (int i = 0; i < 3; ++i) {
      const int a = t[i], b = t[(i + 1) % 3], c = t[(i + 2) % 3];
      used[a] = true;
      auto& e = edges[{std::min(a, b), std::max(a, b)}];
      ++e.first;
      e.second += a < b ? 1 : -1;
      link[a].emplace_back(b, c);
      components.Unite(a, b);
    }
  }
  r.edges = edges.size();
  for (const auto& [key, e] : edges) {
    if (e.first != 2) ++r.edges_not_in_two;
    if (e.first == 2 && e.second != 0) ++r.misoriented_edges;
  }
  std::set<int> roots;
  for (int v = 0; v < n; ++v) {
    if (!used[v]) continue;
    ++r.vertices;
    roots.insert(components.Find(v));
    // The link graph: its vertices must all have degree 2 and it must be connected.
    std::unordered_map<int, std::vector<int>> adjacency;
    for (const auto& [a, b] : link[v]) {
      adjacency[a].push_back(b);
      adjacency[b].push_back(a);
    }
    bool one_cycle = true;
    for (const auto& [w, next] : adjacency) {
      if (next.size() != 2) one_cycle = false;
    }
    if (one_cycle) {
      // Walk around the cycle from any link vertex and count the vertices met.
      const int start = adjacency.begin()->first;
      int prev = -1, at = start;
      size_t steps = 0;
      do {
        const auto& next = adjacency[at];
        const int to = next[0] != prev ? next[0] : next[1];
        prev = at;
        at = to;
        ++steps;
      } while (at != start && steps <= adjacency.size());
      one_cycle = steps == adjacency.size() && link[v].size() == adjacency.size();
    }
    if (!one_cycle) ++r.vertices_not_one_cycle;
  }
  r.components = roots.size();
  r.euler_characteristic =
      static_cast<long>(r.vertices) - static_cast<long>(r.edges) + static_cast<long>(r.triangles);
  return r;
}

}  // namespace omni
