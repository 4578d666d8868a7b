// Step 6 of paper §4.6, first part: genus refinement ("handle removal", Yu and Lhuillier, ICPR
// 2012) of O in the cells of the keyframe, without Steiner points (T stays Delaunay).
//
// One-cell-at-once growing (§4.5) never changes the topology of δO, and the several-at-once
// growing of step 5 only adds whole vertex stars, so cells of F \ O can stay outside O where
// adding any one of them alone breaks the manifold: typically a thin slab of free cells across a
// tunnel of O, whose cells each touch O on two sides. Here whole groups are added at once and
// kept when the general test (§3.1) holds at every vertex of the group (the only vertices whose
// star changes): first the cells around an edge, then connected groups of F \ O grown from a
// seed by largest counter, of doubling size up to a bound. Seeds are the cells of F \ O touching
// δO, most crossed first (the most certain free space first).
//
// Cost: a group is tested before its local χ is counted (most groups fail), the vertex
// that failed last is tested first, and a group that failed since O last changed is not tested
// again (seeds of one small component grow the same group): the outcome is the same.

#include "surface/genus_refinement.h"

#include <algorithm>
#include <queue>
#include <set>
#include <unordered_set>

#include "surface/internal/step6.h"

namespace omni {

std::string GenusRefinementOptions::Check() const {
  if (max_group_cells < 0) return "genus.max_group_cells must be >= 0";
  return "";
}

namespace internal {
namespace {

bool HasSurfaceFacet(CellHandle c) {
  for (int i = 0; i < 4; ++i) {
    if (c->neighbor(i)->info().in_o != c->info().in_o) return true;
  }
  return false;
}

bool EdgeOnSurface(const Delaunay& tri, CellHandle c, int i, int j) {
  auto circ = tri.incident_cells(c, i, j);
  const auto done = circ;
  bool any_in = false, any_out = false;
  do {
    (circ->info().in_o ? any_in : any_out) = true;
    ++circ;
  } while (circ != done && !(any_in && any_out));
  return any_in && any_out;
}

class Refiner {
 public:
  Refiner(DelaunayMesh::Impl& t, const std::function<bool(CellHandle)>& in_region, bool reference)
      : t_(t), in_region_(in_region), reference_(reference) {}

  // A cell of F \ O in the region.
  bool Candidate(CellHandle c) const {
    return !c->info().in_o && c->info().counter > 0 && !t_.tri.is_infinite(c) && in_region_(c);
  }

  // Adds the group to O if δO stays a 2-manifold, then grows one cell at once from it.
  // `remember`: a failure is kept in the memo of failed groups (the edge stars are each tried
  // once per call and seldom met again: they skip the memo and its allocations).
  bool TryGroup(const std::vector<CellHandle>& group, bool remember = true) {
    // The outcome depends only on the group's cells and on O: a group that failed since the
    // last change of O fails again.
    std::vector<CellHandle> key;
    if (remember && !reference_) {
      key = group;
      std::sort(key.begin(), key.end());
      if (failed_.count(key)) return false;
    }
    const std::vector<VertexHandle> vertices = VerticesOf(group);
    for (const CellHandle& c : group) t_.SetInO(c, true);
    // All must pass, so the order does not matter: the vertex that failed last (often in the
    // next, larger group of the same seed) first.
    const bool retest = !reference_ && last_failed_ != VertexHandle() &&
                        std::find(vertices.begin(), vertices.end(), last_failed_) != vertices.end();
    bool passed = !retest || t_.GeneralTest(last_failed_);
    for (size_t i = 0; passed && i < vertices.size(); ++i) {
      if (retest && vertices[i] == last_failed_) continue;
      if (!t_.GeneralTest(vertices[i])) {
        passed = false;
        last_failed_ = vertices[i];
      }
    }
    if (!passed) {
      for (const CellHandle& c : group) t_.SetInO(c, false);
      if (remember && !reference_) failed_.insert(std::move(key));
      return false;
    }
    // Accepted (most groups are not): the local χ before and after.
    for (const CellHandle& c : group) t_.SetInO(c, false);
    const long before = LocalEuler(group, vertices);
    for (const CellHandle& c : group) t_.SetInO(c, true);
    euler_change_ += LocalEuler(group, vertices) - before;
    ++groups_;
    failed_.clear();
    std::vector<CellHandle> next;
    for (const CellHandle& c : group) {
      for (int i = 0; i < 4; ++i) next.push_back(c->neighbor(i));
    }
    GrowOneAtOnce(next);
    return true;
  }

  // The F \ O cells around the edge (i, j) of c, when every cell around it is in O or a
  // candidate and at least one is in O; empty otherwise.
  std::vector<CellHandle> EdgeStar(CellHandle c, int i, int j) const {
    std::vector<CellHandle> star;
    bool any_in = false;
    auto circ = t_.tri.incident_cells(c, i, j);
    const auto done = circ;
    do {
      const CellHandle k = circ;
      if (k->info().in_o) {
        any_in = true;
      } else if (Candidate(k)) {
        star.push_back(k);
      } else {
        return {};
      }
      ++circ;
    } while (circ != done);
    if (!any_in) return {};
    return star;
  }

  // The one-cell-at-once growing of §4.5 (addition test), inside the region. Of the allowed
  // triplets only (4,6,4), closing a tetrahedral bubble, changes χ (by −2, with one component
  // fewer); the others replace a disc of δO by a disc.
  void GrowOneAtOnce(const std::vector<CellHandle>& seeds) {
    CellQueue q(/*largest_first=*/true);
    for (const CellHandle& c : seeds) {
      if (Candidate(c)) q.Push(c);
    }
    while (!q.Empty()) {
      const CellHandle c = q.Pop();
      if (c->info().in_o || !HasSurfaceFacet(c) || !t_.SingleCellTest(c)) continue;
      int facets_in_o = 0;
      for (int i = 0; i < 4; ++i) facets_in_o += c->neighbor(i)->info().in_o ? 1 : 0;
      if (facets_in_o == 4) euler_change_ -= 2;
      t_.SetInO(c, true);
      for (int i = 0; i < 4; ++i) {
        if (Candidate(c->neighbor(i))) q.Push(c->neighbor(i));
      }
    }
  }

  long euler_change() const { return euler_change_; }
  size_t groups() const { return groups_; }

 private:
  std::vector<VertexHandle> VerticesOf(const std::vector<CellHandle>& cells) const {
    std::vector<VertexHandle> vs;
    for (const CellHandle& c : cells) {
      for (int i = 0; i < 4; ++i) vs.push_back(c->vertex(i));
    }
    std::sort(vs.begin(), vs.end(),
              [](VertexHandle a, VertexHandle b) { return a->info().index < b->info().index; });
    vs.erase(std::unique(vs.begin(), vs.end()), vs.end());
    return vs;
  }

  // χ = V − E + F of δO restricted to the faces of the group's cells: the only faces whose
  // membership of δO changes when the group changes side.
  long LocalEuler(const std::vector<CellHandle>& group,
                  const std::vector<VertexHandle>& vertices) const {
    long chi = 0;
    for (const VertexHandle& v : vertices) chi += t_.VertexOnSurface(v) ? 1 : 0;
    auto in_group = [&](CellHandle c) {
      return std::find(group.begin(), group.end(), c) != group.end();
    };
    std::vector<std::pair<int, int>> edges;
    for (const CellHandle& c : group) {
      for (int i = 0; i < 4; ++i) {
        // A facet shared by two cells of the group is counted from the first one.
        const CellHandle n = c->neighbor(i);
        if (in_group(n) &&
            std::find(group.begin(), group.end(), n) < std::find(group.begin(), group.end(), c)) {
          continue;
        }
        if (n->info().in_o != c->info().in_o) ++chi;
      }
      for (int i = 0; i < 4; ++i) {
        for (int j = i + 1; j < 4; ++j) {
          int a = c->vertex(i)->info().index, b = c->vertex(j)->info().index;
          if (a > b) std::swap(a, b);
          if (std::find(edges.begin(), edges.end(), std::make_pair(a, b)) != edges.end()) continue;
          edges.emplace_back(a, b);
          if (EdgeOnSurface(t_.tri, c, i, j)) --chi;
        }
      }
    }
    return chi;
  }

  DelaunayMesh::Impl& t_;
  const std::function<bool(CellHandle)>& in_region_;
  bool reference_;
  long euler_change_ = 0;
  size_t groups_ = 0;
  std::set<std::vector<CellHandle>> failed_;  // groups (sorted) rejected since O last changed
  VertexHandle last_failed_;                  // the vertex whose general test failed last
};

}  // namespace

GenusRefinementResult RefineGenus(DelaunayMesh::Impl& t, const std::vector<CellHandle>& region,
                                  const std::function<bool(CellHandle)>& in_region,
                                  const GenusRefinementOptions& options) {
  GenusRefinementResult result;
  Refiner refiner(t, in_region, options.reference);
  std::vector<CellHandle> seeds;
  for (const CellHandle& c : region) {
    if (!refiner.Candidate(c)) continue;
    ++result.free_before;
    if (HasSurfaceFacet(c)) seeds.push_back(c);
  }
  if (!options.enabled) {
    result.free_after = result.free_before;
    return result;
  }
  std::stable_sort(seeds.begin(), seeds.end(), [](CellHandle a, CellHandle b) {
    return a->info().counter > b->info().counter;
  });

  if (options.edge_stars) {
    std::unordered_set<uint64_t> tried;  // edges by their vertex indices
    for (const CellHandle& c : seeds) {
      for (int i = 0; i < 4 && !c->info().in_o; ++i) {
        for (int j = i + 1; j < 4 && !c->info().in_o; ++j) {
          uint64_t a = static_cast<uint32_t>(c->vertex(i)->info().index);
          uint64_t b = static_cast<uint32_t>(c->vertex(j)->info().index);
          if (a > b) std::swap(a, b);
          if (!tried.insert((a << 32) | b).second) continue;
          const std::vector<CellHandle> star = refiner.EdgeStar(c, i, j);
          if (star.size() >= 2) refiner.TryGroup(star, /*remember=*/false);
        }
      }
    }
  }

  if (options.max_group_cells >= 2) {
    const size_t bound = static_cast<size_t>(options.max_group_cells);
    std::vector<CellHandle> group;
    std::unordered_set<CellHandle, std::hash<CellHandle>> seen;
    for (const CellHandle& seed : seeds) {
      if (seed->info().in_o) continue;
      group.clear();
      seen.clear();
      CellQueue q(/*largest_first=*/true);
      q.Push(seed);
      seen.insert(seed);
      size_t next_size = std::min<size_t>(4, bound);
      while (!q.Empty()) {
        const CellHandle c = q.Pop();
        group.push_back(c);
        for (int i = 0; i < 4; ++i) {
          const CellHandle n = c->neighbor(i);
          if (refiner.Candidate(n) && seen.insert(n).second) q.Push(n);
        }
        const bool last = q.Empty() || group.size() >= bound;
        if (group.size() < next_size && !last) continue;
        if (group.size() >= 2 && refiner.TryGroup(group)) break;
        if (last) break;
        next_size = std::min(2 * next_size, bound);
      }
    }
  }

  for (const CellHandle& c : region) result.free_after += refiner.Candidate(c) ? 1 : 0;
  result.groups = refiner.groups();
  result.euler_change = refiner.euler_change();
  return result;
}

}  // namespace internal

GenusRefinementStats RefineGenus(DelaunayMesh& mesh, const GenusRefinementOptions& options) {
  DelaunayMesh::Impl& t = *mesh.impl();
  std::vector<internal::CellHandle> cells;
  for (auto c : t.tri.finite_cell_handles()) cells.push_back(c);
  const internal::GenusRefinementResult r = internal::RefineGenus(
      t, cells, [&t](internal::CellHandle c) { return !t.tri.is_infinite(c); }, options);
  GenusRefinementStats stats;
  stats.free_before = r.free_before;
  stats.free_after = r.free_after;
  stats.groups = r.groups;
  stats.euler_change = r.euler_change;
  return stats;
}

}  // namespace omni
