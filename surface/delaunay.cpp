#include "surface/delaunay.h"

#include <algorithm>
#include <cassert>
#include <unordered_map>

#include "surface/internal/cgal_delaunay.h"

namespace omni {

using internal::CellHandle;
using internal::Point;
using internal::VertexHandle;

bool AllowedCounts(const ManifoldCounts& k) {
  // Paper §3.1: the subtraction and addition tests accept exactly these (v, e, t) triplets.
  static constexpr int kAllowed[5][3] = {{0, 0, 0}, {3, 3, 1}, {4, 5, 2}, {4, 6, 3}, {4, 6, 4}};
  for (const auto& a : kAllowed) {
    if (k.vertices == a[0] && k.edges == a[1] && k.triangles == a[2]) return true;
  }
  return false;
}

VertexHandle DelaunayMesh::Impl::AddVertex(VertexHandle v, int32_t point, bool steiner) {
  if (v->info().index < 0) {
    v->info().index = static_cast<int>(vertices.size());
    v->info().point = point;
    v->info().steiner = steiner;
    vertices.push_back(v);
  }
  return v;
}

uint32_t DelaunayMesh::Impl::NextChange() {
  if (++change_clock == 0) {
    for (auto v : tri.all_vertex_handles()) v->info().changed = 0;
    for (auto c : tri.all_cell_handles()) c->info().single_test_failed = 0;
    ++change_epoch;
    change_clock = 1;
  }
  return change_clock;
}

void DelaunayMesh::Impl::IncidentCells(VertexHandle v, std::vector<CellHandle>& cells) const {
  internal::VertexInfo& info = v->info();
  if (info.star_first != internal::VertexInfo::kNoStar) {
    const auto first = star_pool.begin() + info.star_first;
    cells.insert(cells.end(), first, first + info.degree);
    return;
  }
  const size_t found_from = cells.size();
  // CGAL's incident_cells_3: a depth-first search through the facets containing v, cells listed
  // when first met, with a scratch mark instead of the TDS flags, a std::stack and a copy.
  thread_local std::vector<CellHandle> stack;
  stack.clear();
  const uint32_t mark = NewMark();
  const CellHandle d = v->cell();
  d->info().mark = mark;
  stack.push_back(d);
  cells.push_back(d);
  while (!stack.empty()) {
    const CellHandle c = stack.back();
    stack.pop_back();
    for (int i = 0; i < 4; ++i) {
      if (c->vertex(i) == v) continue;
      const CellHandle next = c->neighbor(i);
      if (next->info().mark == mark) continue;
      next->info().mark = mark;
      stack.push_back(next);
      cells.push_back(next);
    }
  }
  if (!degrees_valid || info.index < 0) return;
  const size_t size = cells.size() - found_from;
  if (star_pool.size() + size > star_pool_cells) ForgetStars();
  info.star_first = static_cast<uint32_t>(star_pool.size());
  info.degree = static_cast<uint32_t>(size);
  star_pool.insert(star_pool.end(), cells.begin() + found_from, cells.end());
  star_pool_vertices.push_back(info.index);
}

void DelaunayMesh::Impl::ForgetStars() const {
  for (int index : star_pool_vertices) {
    if (index < static_cast<int>(vertices.size()))
      vertices[index]->info().star_first = internal::VertexInfo::kNoStar;
  }
  star_pool.clear();
  star_pool_vertices.clear();
}

void DelaunayMesh::Impl::SetInO(CellHandle c, bool in_o) {
  assert(!tri.is_infinite(c));
  if (c->info().in_o == in_o) return;
  const uint32_t now = NextChange();
  for (int i = 0; i < 4; ++i) {
    internal::VertexInfo& v = c->vertex(i)->info();
    v.changed = now;
    if (in_o) {
      ++v.o_cells;
    } else {
      --v.o_cells;
    }
  }
  for (int i = 0; i < 4; ++i) {
    const bool other = c->neighbor(i)->info().in_o;
    // The facet is in δO before the change iff other != old membership.
    if (other == in_o) {
      --num_triangles;
    } else {
      ++num_triangles;
    }
  }
  c->info().in_o = in_o;
  if (touched) {
    for (int i = 0; i < 4; ++i) {
      const VertexHandle v = c->vertex(i);
      if (v->info().touched == touch_stamp || tri.is_infinite(v)) continue;
      v->info().touched = touch_stamp;
      touched->push_back(v);
    }
  }
  if (in_o) {
    ++num_o;
  } else {
    --num_o;
  }
}

void DelaunayMesh::Impl::UpdateDegrees(const std::vector<VertexHandle>& inserted) {
  if (tri.dimension() < 3) {
    degrees_valid = false;
    return;
  }
  if (!degrees_valid) {
    for (auto w : tri.all_vertex_handles()) w->info().degree = 0;
    ForgetStars();
    degrees_valid = true;
    return;
  }
  // An insertion replaces the cells of its conflict zone by cells incident to the new vertex:
  // the stars that changed are those of the vertices of the new vertex's cells (when a later
  // insertion destroyed them, its own new cells hold those vertices again).
  // A vertex inserted earlier in the list (a Steiner vertex of step 1, listed again with the
  // points of step 3) may have had its star kept since: search them all afresh.
  for (const VertexHandle& v : inserted) v->info().star_first = internal::VertexInfo::kNoStar;
  thread_local std::vector<CellHandle> star;
  for (const VertexHandle& v : inserted) {
    star.clear();
    IncidentCells(v, star);
    StarsChanged(star);
  }
}

void DelaunayMesh::Impl::StarsChanged(const std::vector<CellHandle>& new_cells) {
  for (const CellHandle& c : new_cells) {
    for (int i = 0; i < 4; ++i) {
      internal::VertexInfo& info = c->vertex(i)->info();
      info.degree = 0;
      info.star_first = internal::VertexInfo::kNoStar;
    }
  }
}

uint32_t DelaunayMesh::Impl::Degree(VertexHandle v) const {
  internal::VertexInfo& info = v->info();
  if (info.degree == 0) {  // not counted since its star changed
    thread_local std::vector<CellHandle> star;
    star.clear();
    IncidentCells(v, star);
    info.degree = static_cast<uint32_t>(star.size());
  }
  return info.degree;
}

bool DelaunayMesh::Impl::VertexOnSurface(VertexHandle v) const {
  // From the counts of the star when they are kept (O ⊆ finite cells, so never the infinite
  // vertex), otherwise by a search.
  const internal::VertexInfo& info = v->info();
  if (count_surface_vertices) {
    if (info.o_cells == 0) return false;
    if (degrees_valid) return info.o_cells < Degree(v);
  }
  // A search of the star through the facets containing v that stops as soon as it has met a
  // cell of O and one outside (CGAL's incident_cells would collect the whole star first).
  // Visited cells carry a fresh mark (so this is not thread-safe, like any change of T).
  thread_local std::vector<CellHandle> star;
  star.clear();
  const uint32_t mark = NewMark();
  star.push_back(v->cell());
  v->cell()->info().mark = mark;
  bool any_in = false, any_out = false;
  for (size_t s = 0; s < star.size(); ++s) {
    const CellHandle c = star[s];
    (c->info().in_o ? any_in : any_out) = true;
    if (any_in && any_out) return true;
    const int i = c->index(v);
    for (int k = 0; k < 4; ++k) {
      if (k == i) continue;
      const CellHandle n = c->neighbor(k);
      if (n->info().mark == mark) continue;
      n->info().mark = mark;
      star.push_back(n);
    }
  }
  return false;
}

ManifoldCounts DelaunayMesh::Impl::Counts(CellHandle c) const {
  ManifoldCounts k;
  const bool in = c->info().in_o;
  for (int i = 0; i < 4; ++i) {
    if (c->neighbor(i)->info().in_o != in) ++k.triangles;
  }
  for (int i = 0; i < 4; ++i) {
    if (VertexOnSurface(c->vertex(i))) ++k.vertices;
  }
  for (int i = 0; i < 4; ++i) {
    for (int j = i + 1; j < 4; ++j) {
      // Vertices of the edge must both be on the surface for the edge to be.
      auto circ = tri.incident_cells(c, i, j);
      auto done = circ;
      bool any_in = false, any_out = false;
      do {
        if (circ->info().in_o) {
          any_in = true;
        } else {
          any_out = true;
        }
        ++circ;
      } while (circ != done && !(any_in && any_out));
      if (any_in && any_out) ++k.edges;
    }
  }
  return k;
}

bool DelaunayMesh::Impl::SingleCellTest(CellHandle c) const {
  // AllowedCounts(Counts(c)) without counting everything: the number t of facets of c in δO
  // fixes the only allowed triplet, and the facets already put their vertices and edges in
  // |δO|, so at most one more element needs a look.
  const bool in = c->info().in_o;
  int t = 0;
  int on[4];  // the facets of c in δO
  for (int i = 0; i < 4; ++i) {
    if (c->neighbor(i)->info().in_o != in) on[t++] = i;
  }
  switch (t) {
    case 0:  // (0,0,0): no vertex of c on the surface
      for (int i = 0; i < 4; ++i) {
        if (VertexOnSurface(c->vertex(i))) return false;
      }
      return true;
    case 1:  // (3,3,1): the vertex opposite the facet is off the surface
      return !VertexOnSurface(c->vertex(on[0]));
    case 2: {  // (4,5,2): the edge joining the vertices opposite the two facets (the only edge
               // of c in neither facet) is off the surface
      auto circ = tri.incident_cells(c, on[0], on[1]);
      auto done = circ;
      bool any_in = false, any_out = false;
      do {
        (circ->info().in_o ? any_in : any_out) = true;
        ++circ;
      } while (circ != done && !(any_in && any_out));
      return !(any_in && any_out);
    }
    default:  // (4,6,3) and (4,6,4): always allowed
      return true;
  }
}

bool DelaunayMesh::Impl::GeneralTest(VertexHandle v) const {
  // The v-opposite edges of the δO triangles around v, as pairs of vertex handles.
  thread_local std::vector<std::pair<VertexHandle, VertexHandle>> edges;
  thread_local std::vector<CellHandle> star;
  edges.clear();
  star.clear();
  IncidentCells(v, star);  // ForEachBorderTriangleAround without CGAL's allocations
  internal::ForEachBorderTriangleIn(
      star, v, [&](CellHandle, int, VertexHandle a, VertexHandle b) { edges.emplace_back(a, b); });
  if (edges.empty()) return true;
  // One cycle: every vertex of the graph has degree two and a walk along the edges from any
  // vertex comes back after using all of them.
  thread_local std::vector<std::pair<VertexHandle, std::array<int, 2>>> nodes;  // vertex, edges
  nodes.clear();
  auto node_of = [&](VertexHandle w) -> std::array<int, 2>* {
    for (auto& n : nodes) {
      if (n.first == w) return &n.second;
    }
    nodes.push_back({w, {-1, -1}});
    return &nodes.back().second;
  };
  for (int e = 0; e < static_cast<int>(edges.size()); ++e) {
    for (VertexHandle w : {edges[e].first, edges[e].second}) {
      std::array<int, 2>* slots = node_of(w);
      if ((*slots)[0] < 0) {
        (*slots)[0] = e;
      } else if ((*slots)[1] < 0) {
        (*slots)[1] = e;
      } else {
        return false;  // degree > 2
      }
    }
  }
  for (const auto& n : nodes) {
    if (n.second[1] < 0) return false;  // degree 1
  }
  // Follow the cycle from edge 0.
  size_t used = 0;
  int e = 0;
  VertexHandle at = edges[0].second;
  do {
    ++used;
    const std::array<int, 2>* slots = node_of(at);
    const int next = (*slots)[0] == e ? (*slots)[1] : (*slots)[0];
    at = edges[next].first == at ? edges[next].second : edges[next].first;
    e = next;
  } while (e != 0 && used <= edges.size());
  return used == edges.size();
}

CellHandle DelaunayMesh::Impl::CellOf(const CellKey& key) const {
  VertexHandle v[4];
  for (int i = 0; i < 4; ++i) {
    v[i] = key[i] < 0 ? tri.infinite_vertex() : vertices.at(key[i]);
  }
  CellHandle c;
  int i0, i1, i2, i3;
  if (!tri.is_cell(v[0], v[1], v[2], v[3], c, i0, i1, i2, i3)) return CellHandle();
  return c;
}

CellKey DelaunayMesh::Impl::KeyOf(CellHandle c) const {
  CellKey key;
  for (int i = 0; i < 4; ++i) {
    key[i] = tri.is_infinite(c->vertex(i)) ? -1 : c->vertex(i)->info().index;
  }
  std::sort(key.begin(), key.end());
  return key;
}

DelaunayMesh::DelaunayMesh() : impl_(std::make_unique<Impl>()) {}
DelaunayMesh::~DelaunayMesh() = default;
DelaunayMesh::DelaunayMesh(DelaunayMesh&&) noexcept = default;
DelaunayMesh& DelaunayMesh::operator=(DelaunayMesh&&) noexcept = default;

int DelaunayMesh::Insert(const Eigen::Vector3d& position, int point, bool steiner) {
  CellHandle hint;
  if (!impl_->vertices.empty()) hint = impl_->vertices.back()->cell();
  const VertexHandle v = impl_->tri.insert(internal::ToCgal(position), hint);
  impl_->UpdateDegrees({v});
  return impl_->AddVertex(v, point, steiner)->info().index;
}

size_t DelaunayMesh::NumVertices() const { return impl_->vertices.size(); }

Eigen::Vector3d DelaunayMesh::Position(int vertex) const {
  return internal::ToEigen(impl_->vertices.at(vertex)->point());
}

bool DelaunayMesh::IsValid() const { return impl_->tri.is_valid(false); }

TriangulationCounts DelaunayMesh::Counts() const {
  const auto& t = impl_->tri;
  TriangulationCounts k;
  k.vertices = t.number_of_vertices();
  k.edges = t.number_of_edges();
  k.facets = t.number_of_facets();
  k.cells = t.number_of_cells();
  k.finite_edges = t.number_of_finite_edges();
  k.finite_facets = t.number_of_finite_facets();
  k.finite_cells = t.number_of_finite_cells();
  return k;
}

std::vector<CellKey> DelaunayMesh::FiniteCells() const {
  std::vector<CellKey> cells;
  for (auto c : impl_->tri.finite_cell_handles()) cells.push_back(impl_->KeyOf(c));
  return cells;
}

std::vector<CellKey> DelaunayMesh::Walk(int from, const Eigen::Vector3d& target) const {
  std::vector<CellKey> cells;
  impl_->Walk(impl_->vertices.at(from), internal::ToCgal(target), 2.0,
              [&](CellHandle c) { cells.push_back(impl_->KeyOf(c)); });
  return cells;
}

void DelaunayMesh::TraceRay(int from, const Eigen::Vector3d& target) {
  impl_->Walk(impl_->vertices.at(from), internal::ToCgal(target), 2.0, [&](CellHandle c) {
    if (c->info().counter++ == 0) ++impl_->num_f;
  });
}

int DelaunayMesh::Counter(const CellKey& cell) const {
  const CellHandle c = impl_->CellOf(cell);
  assert(c != CellHandle());
  return static_cast<int>(c->info().counter);
}

void DelaunayMesh::SetInO(const CellKey& cell, bool in_o) {
  const CellHandle c = impl_->CellOf(cell);
  assert(c != CellHandle() && !impl_->tri.is_infinite(c));
  impl_->SetInO(c, in_o);
}

bool DelaunayMesh::InO(const CellKey& cell) const {
  const CellHandle c = impl_->CellOf(cell);
  return c != CellHandle() && c->info().in_o;
}

ManifoldCounts DelaunayMesh::CountsInSurface(const CellKey& cell) const {
  return impl_->Counts(impl_->CellOf(cell));
}

bool DelaunayMesh::SingleCellTest(const CellKey& cell) const {
  return impl_->SingleCellTest(impl_->CellOf(cell));
}

bool DelaunayMesh::GeneralTest(int vertex) const {
  return impl_->GeneralTest(impl_->vertices.at(vertex));
}

size_t DelaunayMesh::NumInO() const { return impl_->num_o; }
size_t DelaunayMesh::NumSurfaceTriangles() const { return impl_->num_triangles; }

TriangleMesh DelaunayMesh::ExtractSurface() const {
  return internal::ExtractBorderOfO(*impl_,
                                    [](VertexHandle v) { return internal::ToEigen(v->point()); });
}

}  // namespace omni
