#pragma once
// INTERNAL to surface/*.cpp: the CGAL types behind DelaunayMesh. Never include this from a
// public header (docs/design.md §2: CGAL types stay out of public headers).

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Delaunay_triangulation_cell_base_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Triangulation_cell_base_with_info_3.h>
#include <CGAL/Triangulation_vertex_base_with_info_3.h>

#include <Eigen/Core>
#include <algorithm>
#include <array>
#include <cstdint>
#include <limits>
#include <queue>
#include <type_traits>
#include <vector>

#include "surface/delaunay.h"

namespace omni::internal {

struct VertexInfo {
  int index = -1;        // DelaunayMesh vertex index (position in Impl::vertices)
  int32_t point = -1;    // caller's point index; -1 for Steiner vertices
  bool steiner = false;  // a vertex of the Steiner grid (paper §3.3)
  uint32_t touched = 0;  // equal to DelaunayMesh::Impl::touch_stamp when recorded in `touched`
  // DelaunayMesh::Impl::change_clock when a cell of the star last changed side (SetInO): the
  // manifold tests at and around the vertex give what they gave before while it is unchanged.
  uint32_t changed = 0;
  // Cells of O incident to the vertex (kept by SetInO) and all cells incident to it (0: to be
  // counted again, see DelaunayMesh::Impl::UpdateDegrees): the vertex is on δO iff
  // 0 < o_cells < degree (VertexOnSurface).
  uint32_t o_cells = 0;
  uint32_t degree = 0;
  // The star as DelaunayMesh::Impl::IncidentCells found it last, cells star_first ..
  // star_first + degree − 1 of Impl::star_pool, while the star is unchanged (kNoStar: none).
  uint32_t star_first = kNoStar;
  static constexpr uint32_t kNoStar = 0xffffffffu;
};

struct CellInfo {
  uint32_t counter = 0;    // ray intersection counter (paper §4.4); > 0 means the cell is in F
  uint32_t date = 0;       // creation date: the stamp of the keyframe that created it (§4.3)
  uint32_t e_stamp = 0;    // equal to the current stamp when the cell is in E (§4.1)
  uint32_t ray_stamp = 0;  // equal to the current stamp when a new ray crossed the cell
  uint32_t d_stamp = 0;    // equal to the current stamp when the cell is in a conflict zone D
  uint32_t mark = 0;       // scratch visit mark of searches (DelaunayMesh::Impl::NewMark)
  bool in_o = false;       // the cell is in O (free space carved so far, O ⊆ F)
  bool queued = false;     // scratch flag of the priority-queue passes
  // The change_clock value at which SingleCellTest last failed on this cell (0: never): it fails
  // again while no vertex of the cell has changed since (VertexInfo::changed).
  uint32_t single_test_failed = 0;
};

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Vb = CGAL::Triangulation_vertex_base_with_info_3<VertexInfo, Kernel>;
using Cb0 = CGAL::Delaunay_triangulation_cell_base_3<Kernel>;
using Cb = CGAL::Triangulation_cell_base_with_info_3<CellInfo, Kernel, Cb0>;
using Tds = CGAL::Triangulation_data_structure_3<Vb, Cb>;
using Delaunay = CGAL::Delaunay_triangulation_3<Kernel, Tds>;
using VertexHandle = Delaunay::Vertex_handle;
using CellHandle = Delaunay::Cell_handle;

inline Point ToCgal(const Eigen::Vector3d& p) { return Point(p.x(), p.y(), p.z()); }
inline Eigen::Vector3d ToEigen(const Point& p) { return Eigen::Vector3d(p.x(), p.y(), p.z()); }

// Calls visit(cell, k, a, b) for each δO triangle around v among the cells [begin, end) (v's
// star, or part of it): facet k of a cell of O incident to v whose neighbour across it is outside
// O; a and b are the facet's vertices other than v (its v-opposite edge), in the cell's vertex
// order.
template <class Visit>
void ForEachBorderTriangleIn(const CellHandle* begin, const CellHandle* end, VertexHandle v,
                             Visit&& visit) {
  for (const CellHandle* it = begin; it != end; ++it) {
    const CellHandle& c = *it;
    if (!c->info().in_o) continue;
    const int i = c->index(v);
    for (int k = 0; k < 4; ++k) {
      if (k == i || c->neighbor(k)->info().in_o) continue;
      VertexHandle e[2];
      int n = 0;
      for (int m = 0; m < 4; ++m) {
        if (m != i && m != k) e[n++] = c->vertex(m);
      }
      visit(c, k, e[0], e[1]);
    }
  }
}
// The same among the cells of `star`.
template <class Visit>
void ForEachBorderTriangleIn(const std::vector<CellHandle>& star, VertexHandle v, Visit&& visit) {
  ForEachBorderTriangleIn(star.data(), star.data() + star.size(), v, std::forward<Visit>(visit));
}

// The same around v, its star found by CGAL (DelaunayMesh::Impl::IncidentCells finds it without
// allocations where the Impl is at hand).
template <class Visit>
void ForEachBorderTriangleAround(const Delaunay& tri, VertexHandle v, Visit&& visit) {
  thread_local std::vector<CellHandle> star;
  star.clear();
  tri.incident_cells(v, std::back_inserter(star));
  ForEachBorderTriangleIn(star, v, std::forward<Visit>(visit));
}

}  // namespace omni::internal

namespace omni {

// The state behind DelaunayMesh; surface/*.cpp that need CGAL reach it through
// DelaunayMesh::impl().
struct DelaunayMesh::Impl {
  internal::Delaunay tri;
  std::vector<internal::VertexHandle> vertices;  // by DelaunayMesh vertex index
  size_t num_o = 0;                              // cells in O
  size_t num_f = 0;                              // finite cells with counter > 0
  size_t num_triangles = 0;                      // triangles of δO
  // Scratch marks: a search takes a fresh value and compares CellInfo::mark with it (no set).
  // A search that relies on its marks must not run another one meanwhile (VertexOnSurface,
  // hence the manifold tests, mark cells too).
  // (On wrap-around every mark is cleared.) Not thread-safe.
  mutable uint32_t mark_counter = 0;
  uint32_t NewMark() const {
    if (++mark_counter == 0) {
      for (auto c : const_cast<internal::Delaunay&>(tri).all_cell_handles()) c->info().mark = 0;
      mark_counter = 1;
    }
    return mark_counter;
  }
  // When set, SetInO appends the (finite) vertices of every cell it flips, once per touch_stamp:
  // the vertices whose δO umbrella may have changed (step 6 smoothing works on them).
  std::vector<internal::VertexHandle>* touched = nullptr;
  uint32_t touch_stamp = 0;

  // Counts the changes of side of cells (SetInO), stamped on their vertices (VertexInfo::changed)
  // for the memos of failed manifold tests. On wrap-around every stamp and memo is cleared and
  // change_epoch advances (memos kept elsewhere compare it).
  uint32_t change_clock = 0;
  uint32_t change_epoch = 0;
  uint32_t NextChange();
  // The cells incident to v (v finite, dimension 3) in the order of CGAL's incident_cells,
  // without its allocations (a scratch mark per cell, see NewMark). Appended to `cells`.
  // While the degrees are kept (degrees_valid), a star found is kept in star_pool until an
  // insertion changes it (StarsChanged): the manifold tests of a keyframe's steps ask for the
  // same stars again and again (about four times each on the demo drive), and T changes only
  // when points are inserted. The pool holds at most star_pool_cells cells (2 MiB); when full
  // it is emptied.
  void IncidentCells(internal::VertexHandle v, std::vector<internal::CellHandle>& cells) const;
  size_t star_pool_cells = size_t{1} << 18;
  mutable std::vector<internal::CellHandle> star_pool;
  mutable std::vector<int> star_pool_vertices;  // the vertex indices whose star is in the pool
  void ForgetStars() const;
  // VertexInfo::degree after insertions: the degrees of the vertices of the cells incident to
  // the `inserted` vertices (an insertion changes only those stars) are to be counted again
  // (lazily, by Degree), or those of all vertices when they were not kept. Whoever inserts into
  // `tri` calls it (or StarsChanged with all the new cells) before the next manifold test; in
  // dimension < 3 VertexOnSurface searches the star.
  bool degrees_valid = false;
  bool count_surface_vertices = true;  // false: VertexOnSurface always searches (test reference)
  void UpdateDegrees(const std::vector<internal::VertexHandle>& inserted);
  void StarsChanged(const std::vector<internal::CellHandle>& new_cells);
  uint32_t Degree(internal::VertexHandle v) const;

  internal::VertexHandle AddVertex(internal::VertexHandle v, int32_t point, bool steiner);

  // O bookkeeping with the counts above kept up to date. Never called on an infinite cell.
  void SetInO(internal::CellHandle c, bool in_o);
  bool InO(internal::CellHandle c) const { return c->info().in_o; }

  // Number of (vertices, edges, triangles) of cell c in |δO| (paper §3.1).
  ManifoldCounts Counts(internal::CellHandle c) const;
  // The subtraction test (c in O) or addition test (c not in O): Counts(c) is allowed.
  bool SingleCellTest(internal::CellHandle c) const;
  // The general test at v: the v-opposite edges of the δO triangles around v form one cycle
  // (or there is no such triangle).
  bool GeneralTest(internal::VertexHandle v) const;
  bool VertexOnSurface(internal::VertexHandle v) const;

  // The walk of a ray from vertex `from` to `target` (paper §4.4): calls visit(cell) on every
  // cell crossed, in order (a visit that returns bool ends the walk by returning false). Stops at
  // the cell containing target or at an infinite cell (which is not visited), or after a cell lying
  // wholly beyond the parameter `stop` along from→target (every vertex projects beyond it).
  // Thread-safe on a triangulation that is not being modified.
  template <typename Visit>
  void Walk(internal::VertexHandle from, const internal::Point& target, double stop,
            Visit&& visit) const;
  // The same walk of the segment `from`→`target` continued from cell `start`, which the segment
  // must enter through its facet `entry` (see EntryFacet): visits the same cells as Walk from
  // `start` on. Thread-safe like Walk.
  template <typename Visit>
  void WalkFrom(const internal::Point& from, const internal::Point& target,
                internal::CellHandle start, int entry, double stop, Visit&& visit) const;
  // The walk of the segment from→target from the finite cell `start` that contains `from`
  // (strictly inside, or on its border), as Walk: visits start, then the cells the segment
  // crosses. Returns without a visit when the segment leaves start through no facet cleanly
  // (it runs along a facet or an edge from the start). Thread-safe like Walk.
  template <typename Visit>
  void WalkFromInside(const internal::Point& from, const internal::Point& target,
                      internal::CellHandle start, double stop, Visit&& visit) const;
  // The facet of finite cell c through which the segment from→target enters c, when it does so
  // without degeneracy: `from` strictly beyond the facet's plane, `target` strictly inside and
  // the line through the open triangle. -1 otherwise (then use Walk). Exact predicates.
  int EntryFacet(const internal::Point& from, const internal::Point& target,
                 internal::CellHandle c) const;

  // The walk loop shared by Walk and WalkFrom (first: `cell` is the start vertex's cell and
  // `entry` the index of that vertex).
  template <typename Visit>
  void WalkLoop(const internal::Point& p, const internal::Point& target, internal::CellHandle cell,
                int entry, bool first, double stop, Visit& visit) const;

  internal::CellHandle CellOf(const CellKey& key) const;
  CellKey KeyOf(internal::CellHandle c) const;
};

bool AllowedCounts(const ManifoldCounts& counts);

template <typename Visit>
void DelaunayMesh::Impl::Walk(internal::VertexHandle from, const internal::Point& target,
                              double stop, Visit&& visit) const {
  using internal::CellHandle;
  const internal::Point& p = from->point();
  if (p == target) return;
  // Start: an incident cell of `from` whose cone at `from` the segment enters, i.e. the target
  // is on the inner side of the three facets through `from`: the first facet through `from`
  // with the target strictly beyond it (-1: none, the segment enters c's cone).
  auto beyond = [&](CellHandle c, int i) {
    const std::array<const internal::Point*, 4> v = {&c->vertex(0)->point(), &c->vertex(1)->point(),
                                                     &c->vertex(2)->point(),
                                                     &c->vertex(3)->point()};
    for (int j = 0; j < 4; ++j) {
      if (j == i) continue;
      std::array<const internal::Point*, 4> q = v;
      q[j] = &target;
      if (CGAL::orientation(*q[0], *q[1], *q[2], *q[3]) == CGAL::NEGATIVE) return j;
    }
    return -1;
  };
  // A visibility walk in the star: across a facet through `from` with the target beyond it
  // (a few cells where a search of the whole star tests them all). Bounded, since a visibility
  // walk may cycle in a non-Delaunay star; then (or at an infinite cell) the search below.
  CellHandle cell;
  {
    constexpr int kMaxStarSteps = 64;
    CellHandle c = from->cell();
    for (int steps = 0; steps < kMaxStarSteps && !tri.is_infinite(c); ++steps) {
      const int j = beyond(c, c->index(from));
      if (j < 0) {
        cell = c;
        break;
      }
      c = c->neighbor(j);
    }
  }
  if (cell == CellHandle()) {
    // The star of `from` by a search over neighbours (CGAL's incident_cells marks cells of the
    // shared data structure, so it is not safe in parallel walks).
    thread_local std::vector<CellHandle> star;
    star.clear();
    star.push_back(from->cell());
    for (size_t s = 0; s < star.size(); ++s) {
      const CellHandle c = star[s];
      for (int k = 0; k < 4; ++k) {
        if (c->vertex(k) == from) continue;
        const CellHandle n = c->neighbor(k);
        if (std::find(star.begin(), star.end(), n) == star.end()) star.push_back(n);
      }
    }
    for (const CellHandle& c : star) {
      if (!tri.is_infinite(c) && beyond(c, c->index(from)) < 0) {
        cell = c;
        break;
      }
    }
  }
  if (cell == CellHandle()) return;  // only infinite cells ahead: the target is off the hull
  // The exit is the facet opposite `from`.
  WalkLoop(p, target, cell, cell->index(from), /*first=*/true, stop, visit);
}

inline int DelaunayMesh::Impl::EntryFacet(const internal::Point& from,
                                          const internal::Point& target,
                                          internal::CellHandle c) const {
  if (tri.is_infinite(c)) return -1;
  const std::array<const internal::Point*, 4> v = {&c->vertex(0)->point(), &c->vertex(1)->point(),
                                                   &c->vertex(2)->point(), &c->vertex(3)->point()};
  for (int k = 0; k < 4; ++k) {
    std::array<const internal::Point*, 4> q = v;
    q[k] = &from;
    if (CGAL::orientation(*q[0], *q[1], *q[2], *q[3]) != CGAL::NEGATIVE) continue;
    q[k] = &target;
    if (CGAL::orientation(*q[0], *q[1], *q[2], *q[3]) != CGAL::POSITIVE) return -1;
    const int a = (k + 1) & 3, b = (k + 2) & 3, d = (k + 3) & 3;
    const auto o1 = CGAL::orientation(from, target, *v[a], *v[b]);
    const auto o2 = CGAL::orientation(from, target, *v[b], *v[d]);
    const auto o3 = CGAL::orientation(from, target, *v[d], *v[a]);
    if (o1 != CGAL::ZERO && o1 == o2 && o2 == o3) return k;
    return -1;  // the line misses the open triangle (or touches its border)
  }
  return -1;
}

template <typename Visit>
void DelaunayMesh::Impl::WalkFrom(const internal::Point& from, const internal::Point& target,
                                  internal::CellHandle start, int entry, double stop,
                                  Visit&& visit) const {
  WalkLoop(from, target, start, entry, /*first=*/false, stop, visit);
}

template <typename Visit>
void DelaunayMesh::Impl::WalkFromInside(const internal::Point& from, const internal::Point& target,
                                        internal::CellHandle start, double stop,
                                        Visit&& visit) const {
  if (tri.is_infinite(start) || from == target) return;
  std::array<const internal::Point*, 4> v = {&start->vertex(0)->point(), &start->vertex(1)->point(),
                                             &start->vertex(2)->point(),
                                             &start->vertex(3)->point()};
  // The exit facet: target strictly beyond its plane and the line crossing the open triangle.
  int exit = -1;
  bool inside = true;
  for (int k = 0; k < 4 && exit < 0; ++k) {
    std::array<const internal::Point*, 4> q = v;
    q[k] = &target;
    if (CGAL::orientation(*q[0], *q[1], *q[2], *q[3]) != CGAL::NEGATIVE) continue;
    inside = false;
    const int a = (k + 1) & 3, b = (k + 2) & 3, d = (k + 3) & 3;
    const auto o1 = CGAL::orientation(from, target, *v[a], *v[b]);
    const auto o2 = CGAL::orientation(from, target, *v[b], *v[d]);
    const auto o3 = CGAL::orientation(from, target, *v[d], *v[a]);
    if (o1 != CGAL::ZERO && o1 == o2 && o2 == o3) exit = k;
  }
  if (inside) {  // the whole segment in start
    visit(start);
    return;
  }
  if (exit < 0) return;
  if constexpr (std::is_same_v<decltype(visit(start)), bool>) {
    if (!visit(start)) return;
  } else {
    visit(start);
  }
  const internal::CellHandle next = start->neighbor(exit);
  WalkLoop(from, target, next, next->index(start), /*first=*/false, stop, visit);
}

template <typename Visit>
void DelaunayMesh::Impl::WalkLoop(const internal::Point& p, const internal::Point& target,
                                  internal::CellHandle cell, int entry, bool first, double stop,
                                  Visit& visit) const {
  using internal::CellHandle;
  // Direction scaled so that the projection of a point is its parameter along from→target.
  double dir[3] = {target.x() - p.x(), target.y() - p.y(), target.z() - p.z()};
  const double norm2 = dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2];
  for (double& x : dir) x /= norm2;
  // A guard against degenerate cycling: a walk never visits more cells than T has.
  for (size_t steps = 0; steps <= tri.number_of_cells(); ++steps) {
    if (tri.is_infinite(cell)) return;
    // A visit that returns bool ends the walk by returning false.
    if constexpr (std::is_same_v<decltype(visit(cell)), bool>) {
      if (!visit(cell)) return;
    } else {
      visit(cell);
    }
    if (stop < 1.0) {
      double nearest = std::numeric_limits<double>::infinity();
      for (int i = 0; i < 4; ++i) {
        const internal::Point& w = cell->vertex(i)->point();
        nearest = std::min(nearest, (w.x() - p.x()) * dir[0] + (w.y() - p.y()) * dir[1] +
                                        (w.z() - p.z()) * dir[2]);
      }
      if (nearest > stop) return;
    }
    // Facets with the target strictly beyond their plane.
    std::array<const internal::Point*, 4> v = {&cell->vertex(0)->point(), &cell->vertex(1)->point(),
                                               &cell->vertex(2)->point(),
                                               &cell->vertex(3)->point()};
    int exit = -1;
    if (first) {
      const int i = entry;
      std::array<const internal::Point*, 4> q = v;
      q[i] = &target;
      if (CGAL::orientation(*q[0], *q[1], *q[2], *q[3]) == CGAL::NEGATIVE) exit = i;
      first = false;
    } else {
      // Seen along the line p→target, the line is a point L inside the entry triangle
      // (a, b, c); the exit is the face through the opposite vertex d whose projection holds L,
      // told apart by the side of L with respect to the planes (p, target, d, x), x = a, b, c
      // (the straight walk of Devillers, Pion and Teillaud): three predicates per cell.
      const int ia = (entry + 1) & 3, ib = (entry + 2) & 3, ic = (entry + 3) & 3;
      const internal::Point& d = *v[entry];
      const auto side = CGAL::orientation(p, target, *v[ia], *v[ib]);  // of L in (a, b, c)
      const auto ta = CGAL::orientation(p, target, d, *v[ia]);
      int candidate = -1;
      if (side != CGAL::ZERO && ta != CGAL::ZERO) {
        if (ta == side) {
          const auto tb = CGAL::orientation(p, target, d, *v[ib]);
          if (tb != CGAL::ZERO) candidate = tb == side ? ia : ic;  // face (b,c,d) or (a,b,d)
        } else {
          const auto tc = CGAL::orientation(p, target, d, *v[ic]);
          if (tc != CGAL::ZERO) candidate = tc == side ? ib : ia;  // face (c,a,d) or (b,c,d)
        }
      }
      if (candidate >= 0) {
        std::array<const internal::Point*, 4> q = v;
        q[candidate] = &target;
        // The target before the exit face: it is in this cell.
        if (CGAL::orientation(*q[0], *q[1], *q[2], *q[3]) == CGAL::NEGATIVE) exit = candidate;
        if (exit < 0) return;
      }
      // Degenerate (a zero predicate): test every face.
      for (int k = 0; k < 4 && exit < 0; ++k) {
        if (k == entry) continue;
        std::array<const internal::Point*, 4> q = v;
        q[k] = &target;
        if (CGAL::orientation(*q[0], *q[1], *q[2], *q[3]) != CGAL::NEGATIVE) continue;
        // The line p→target crosses triangle k: p and target on opposite sides of the three
        // planes (p, target, edge).
        const int a = (k + 1) & 3, b = (k + 2) & 3, d = (k + 3) & 3;
        const auto o1 = CGAL::orientation(p, target, *v[a], *v[b]);
        const auto o2 = CGAL::orientation(p, target, *v[b], *v[d]);
        const auto o3 = CGAL::orientation(p, target, *v[d], *v[a]);
        const bool has_pos = o1 == CGAL::POSITIVE || o2 == CGAL::POSITIVE || o3 == CGAL::POSITIVE;
        const bool has_neg = o1 == CGAL::NEGATIVE || o2 == CGAL::NEGATIVE || o3 == CGAL::NEGATIVE;
        if (!(has_pos && has_neg)) exit = k;
      }
    }
    if (exit < 0) return;  // the target is inside this cell
    const CellHandle next = cell->neighbor(exit);
    entry = next->index(cell);
    cell = next;
  }
}

namespace internal {

// Cells by ray counter (smallest or largest first), ties in push order so that runs are
// reproducible (cell addresses are not).
class CellQueue {
 public:
  explicit CellQueue(bool largest_first) : largest_first_(largest_first) {}
  void Push(CellHandle c) {
    const int64_t counter = c->info().counter;
    heap_.push({largest_first_ ? counter : -counter, -static_cast<int64_t>(next_++), c});
  }
  CellHandle Pop() {
    const CellHandle c = heap_.top().cell;
    heap_.pop();
    return c;
  }
  bool Empty() const { return heap_.empty(); }

 private:
  struct Entry {
    int64_t priority, order;
    CellHandle cell;
    bool operator<(const Entry& o) const {
      return priority != o.priority ? priority < o.priority : order < o.order;
    }
  };
  bool largest_first_;
  uint64_t next_ = 0;
  std::priority_queue<Entry> heap_;
};

// δO as a triangle mesh, triangles counter-clockwise seen from O (the free space): the facets
// between a cell of O and a cell outside it, each vertex placed at position_of(vertex).
template <typename PositionOf>
TriangleMesh ExtractBorderOfO(const DelaunayMesh::Impl& t, PositionOf position_of) {
  TriangleMesh mesh;
  std::vector<int> compact(t.vertices.size(), -1);
  auto index_of = [&](VertexHandle v) {
    int& k = compact[v->info().index];
    if (k < 0) {
      k = static_cast<int>(mesh.vertices.size());
      mesh.vertices.push_back(position_of(v));
    }
    return k;
  };
  for (auto c : t.tri.finite_cell_handles()) {
    if (!c->info().in_o) continue;
    for (int k = 0; k < 4; ++k) {
      if (c->neighbor(k)->info().in_o) continue;
      VertexHandle a = c->vertex((k + 1) & 3), b = c->vertex((k + 2) & 3),
                   d = c->vertex((k + 3) & 3);
      // Counter-clockwise seen from O: the cell's fourth vertex (inside O's side) on the
      // positive side of the oriented plane (a, b, d).
      if (CGAL::orientation(a->point(), b->point(), d->point(), c->vertex(k)->point()) ==
          CGAL::NEGATIVE) {
        std::swap(b, d);
      }
      mesh.triangles.emplace_back(index_of(a), index_of(b), index_of(d));
    }
  }
  return mesh;
}

}  // namespace internal
}  // namespace omni
