// Step 6 of paper §4.6, second part: incremental smoothing of δO (Yu and Lhuillier, 3DIMPVT
// 2012, built here from first principles). T keeps the SfM positions; only the output surface's
// vertices get smoothed positions, kept by vertex index. Per keyframe, the δO vertices of the
// keyframe's cells inside the enclosing ball whose umbrella (their δO triangles) changed, and
// their δO neighbours in the ball, are recomputed from their own positions: peak removal, then
// Taubin λ|μ steps (uniform umbrella Laplacian), the vertices outside this set held fixed. Every
// move is checked: no incident triangle may turn against its free side (its normal at the
// Delaunay positions, which faces O) or become near-degenerate; after the steps, the triangles
// around each moved vertex are tested against the δO triangles of the Delaunay neighbourhood
// (exact predicates) and a vertex whose triangles meet one goes back to its previous position,
// then to its own point.
//
// Cost: positions, umbrella hashes and the scratch of a call are dense arrays by vertex
// index (no hash map in the inner loops); the δO facets around a vertex are gathered once per
// call and shared by the checks of all its neighbours; a pair of triangles whose boxes miss, or
// one certainly on one side of the other's plane (a filter in doubles with a wide error bound),
// skips the exact tests. The first intersection check of every moved vertex runs in parallel
// (TBB) on the positions after the Taubin steps; the sequential revert pass keeps a result while
// no vertex it reads (the vertex, its ring and their neighbours in T) was reverted, and checks
// again otherwise, so the outcome is that of the sequential checks. The reference path
// (SmoothingOptions::reference_checks) gathers anew and tests every pair:
// tests/surface/smoothing_test.cpp checks that both give the same positions.

#include <CGAL/intersections.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <initializer_list>

#include "surface/internal/step6.h"

namespace omni {

std::string SmoothingOptions::Check() const {
  if (taubin_steps < 0) return "smoothing.taubin_steps must be >= 0";
  if (!(lambda > 0.0 && lambda < 1.0)) return "smoothing.lambda must be in (0, 1)";
  if (!(mu < -lambda && mu > -1.0)) return "smoothing.mu must be in (-1, -lambda)";
  if (!(peak_factor > 0.0)) return "smoothing.peak_factor must be > 0";
  if (!(feature_sigma > 0.0)) return "smoothing.feature_sigma must be > 0";
  if (!(crease_angle_deg > 0.0 && crease_angle_deg <= 180.0)) {
    return "smoothing.crease_angle_deg must be in (0, 180]";
  }
  if (!(min_triangle_shape >= 0.0 && min_triangle_shape < 0.4)) {
    return "smoothing.min_triangle_shape must be in [0, 0.4)";
  }
  return "";
}

namespace internal {
namespace {

// A δO triangle (v, a, b) of the umbrella of v, counter-clockwise seen from O.
struct UmbrellaTriangle {
  VertexHandle a, b;
};

// The δO triangles around v among the cells of its star [begin, end); empty when v is not on
// δO.
void UmbrellaOf(VertexHandle v, const CellHandle* begin, const CellHandle* end,
                std::vector<UmbrellaTriangle>& out) {
  out.clear();
  ForEachBorderTriangleIn(
      begin, end, v, [&](const CellHandle& c, int k, VertexHandle a, VertexHandle b) {
        // Counter-clockwise seen from O: the cell's vertex k (on O's side)
        // above (v, a, b).
        if (CGAL::orientation(v->point(), a->point(), b->point(), c->vertex(k)->point()) ==
            CGAL::NEGATIVE) {
          std::swap(a, b);
        }
        out.push_back({a, b});
      });
}

uint64_t UmbrellaHash(const std::vector<UmbrellaTriangle>& umbrella) {
  thread_local std::vector<uint64_t> keys;
  keys.clear();
  for (const UmbrellaTriangle& t : umbrella) {
    keys.push_back((static_cast<uint64_t>(t.a->info().index) << 32) |
                   static_cast<uint32_t>(t.b->info().index));
  }
  std::sort(keys.begin(), keys.end());
  uint64_t h = 1469598103934665603ull;  // FNV-1a over the sorted keys
  for (uint64_t k : keys) {
    h ^= k;
    h *= 1099511628211ull;
    h ^= h >> 29;
  }
  return h;
}

// The plane of a triangle (p0, p1, p2) for a filter in doubles: Side(q) is +1 or -1 when certain
// (then the sign of CGAL::orientation(p0, p1, p2, q)), 0 when q is too near the plane to tell in
// doubles. The bound is over 100 times the rounding error of the determinant (CGAL's static
// filter for orientation_3 uses 5.1e-15 for the same product of coordinate ranges). The normal
// and the ranges of the edges are computed once per triangle, not per point.
struct PlaneFilter {
  PlaneFilter() = default;
  PlaneFilter(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, const Eigen::Vector3d& p2)
      : origin(p0) {
    const Eigen::Vector3d a = p1 - p0, b = p2 - p0;
    normal = a.cross(b);
    edge_range = a.cwiseAbs().cwiseMax(b.cwiseAbs());
  }
  int Side(const Eigen::Vector3d& q) const {
    const Eigen::Vector3d c = q - origin;
    const double det = normal.dot(c);
    const Eigen::Vector3d range = edge_range.cwiseMax(c.cwiseAbs());
    const double bound = 1e-12 * range.x() * range.y() * range.z();
    return det > bound ? 1 : det < -bound ? -1 : 0;
  }
  // Whether the points are all certainly on one side of the plane.
  bool Aside(std::initializer_list<Eigen::Vector3d> points) const {
    int first = 0;
    for (const Eigen::Vector3d& q : points) {
      const int side = Side(q);
      if (side == 0 || (first != 0 && side != first)) return false;
      first = side;
    }
    return true;
  }
  Eigen::Vector3d origin, normal, edge_range;
};

}  // namespace

void SurfaceSmoother::Grow(const DelaunayMesh::Impl& t) {
  const size_t n = t.vertices.size();
  for (size_t i = out_.size(); i < n; ++i) out_.push_back(ToEigen(t.vertices[i]->point()));
  moved_.resize(n, 0);
  has_umbrella_.resize(n, 0);
  umbrella_.resize(n, 0);
  slot_stamp_.resize(n, 0);
  star_stamp_.resize(n, 0);
  star_cells_stamp_.resize(n, 0);
  star_cells_range_.resize(n);
  dirty_stamp_.resize(n, 0);
  slot_.resize(n, -1);
  star_.resize(n);
  if (++call_ == 0) {  // wrap-around: every stamp is stale
    std::fill(slot_stamp_.begin(), slot_stamp_.end(), 0);
    std::fill(star_stamp_.begin(), star_stamp_.end(), 0);
    std::fill(star_cells_stamp_.begin(), star_cells_stamp_.end(), 0);
    std::fill(dirty_stamp_.begin(), dirty_stamp_.end(), 0);
    call_ = 1;
  }
}

Eigen::Vector3d SurfaceSmoother::Position(VertexHandle v) const {
  const size_t index = static_cast<size_t>(v->info().index);
  return index < out_.size() ? out_[index] : ToEigen(v->point());
}

std::pair<uint32_t, uint32_t> SurfaceSmoother::Star(const DelaunayMesh::Impl& t, int index) {
  if (star_cells_stamp_[index] == call_) return star_cells_range_[index];
  const uint32_t begin = static_cast<uint32_t>(star_cells_.size());
  t.IncidentCells(t.vertices[index], star_cells_);  // appends, in CGAL's incident_cells order
  star_cells_stamp_[index] = call_;
  return star_cells_range_[index] = {begin, static_cast<uint32_t>(star_cells_.size())};
}

void SurfaceSmoother::GatherStarFacets(const DelaunayMesh::Impl& t, const Local& local) {
  StarFacets(t, local.index);
  for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) StarFacets(t, ring_[i]);
}

std::pair<uint32_t, uint32_t> SurfaceSmoother::StarFacets(const DelaunayMesh::Impl& t, int index) {
  if (star_stamp_[index] == call_) return star_[index];
  const auto [star_begin, star_end] = Star(t, index);
  const uint32_t begin = static_cast<uint32_t>(facets_.size());
  for (uint32_t s = star_begin; s < star_end; ++s) {
    const CellHandle c = star_cells_[s];
    if (!c->info().in_o) continue;  // cells of O are finite
    for (int k = 0; k < 4; ++k) {
      if (c->neighbor(k)->info().in_o) continue;
      facets_.push_back({c->vertex((k + 1) & 3)->info().index, c->vertex((k + 2) & 3)->info().index,
                         c->vertex((k + 3) & 3)->info().index, c->vertex(k)->info().index});
    }
  }
  star_stamp_[index] = call_;
  return star_[index] = {begin, static_cast<uint32_t>(facets_.size())};
}

bool SurfaceSmoother::MeetsNearby(const DelaunayMesh::Impl& t, const Local& local, bool reference,
                                  std::vector<Facet>& candidates) const {
  // The umbrella at the current positions and its bounding box: a triangle whose box misses it
  // cannot meet it.
  const Eigen::Vector3d& x = out_[local.index];
  Eigen::AlignedBox3d umbrella_box(x);
  for (uint32_t i = local.triangles_begin; i < local.triangles_end; ++i) {
    umbrella_box.extend(out_[triangles_[i].a]);
    umbrella_box.extend(out_[triangles_[i].b]);
  }
  const double pad =
      1e-9 * (1.0 + umbrella_box.diagonal().norm() + umbrella_box.max().cwiseAbs().maxCoeff());
  umbrella_box.extend(umbrella_box.max() + Eigen::Vector3d::Constant(pad));
  umbrella_box.extend(umbrella_box.min() - Eigen::Vector3d::Constant(pad));

  // The δO facets of the cells of O around v and its ring whose box meets the umbrella's, each
  // once (a δO facet has one cell in O, so its vertices name it).
  candidates.clear();
  auto consider = [&](const Facet& f) {
    Eigen::AlignedBox3d box(out_[f[0]]);
    box.extend(out_[f[1]]);
    box.extend(out_[f[2]]);
    if (!box.intersects(umbrella_box)) return;
    Facet key = f;
    if (key[0] > key[1]) std::swap(key[0], key[1]);
    if (key[1] > key[2]) std::swap(key[1], key[2]);
    if (key[0] > key[1]) std::swap(key[0], key[1]);
    candidates.push_back(key);
  };
  if (reference) {
    // Gathered anew: the cells around v and its ring, then their δO facets.
    thread_local std::vector<CellHandle> star, cells;
    cells.clear();
    auto add_star = [&](VertexHandle w) {
      star.clear();
      t.tri.incident_cells(w, std::back_inserter(star));
      for (const CellHandle& c : star) {
        if (c->info().in_o) cells.push_back(c);
      }
    };
    add_star(local.v);
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) add_star(t.vertices[ring_[i]]);
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    for (const CellHandle& c : cells) {
      for (int k = 0; k < 4; ++k) {
        if (c->neighbor(k)->info().in_o) continue;
        consider({c->vertex((k + 1) & 3)->info().index, c->vertex((k + 2) & 3)->info().index,
                  c->vertex((k + 3) & 3)->info().index});
      }
    }
    std::sort(candidates.begin(), candidates.end(), [](const Facet& a, const Facet& b) {
      return a[0] != b[0] ? a[0] < b[0] : a[1] != b[1] ? a[1] < b[1] : a[2] < b[2];
    });
    candidates.erase(std::unique(candidates.begin(), candidates.end()), candidates.end());
  } else {
    // The stars of S = (v, its ring...) in that order. A δO facet is listed in the star of each
    // vertex of its cell (of O, one per facet), so it is taken from the first star of S that
    // lists it: the one of the first vertex of S among its cell's four, none earlier (no sort).
    thread_local std::vector<uint32_t> order_stamp;
    thread_local std::vector<uint32_t> order_of;
    thread_local uint32_t order_query = 0;
    if (order_stamp.size() < out_.size() || order_query == 0xffffffffu) {
      order_stamp.assign(out_.size(), 0);
      order_of.resize(out_.size());
      order_query = 0;
    }
    const uint32_t query = ++order_query;
    auto first_in_s = [&](int index, uint32_t order) {
      return !(order_stamp[index] == query && order_of[index] < order);
    };
    auto consider_star = [&](int index, uint32_t order) {
      if (order_stamp[index] == query) return;  // a repeated vertex of S
      order_stamp[index] = query;
      order_of[index] = order;
      const auto [begin, end] = star_[index];  // gathered by GatherStarFacets
      for (uint32_t i = begin; i < end; ++i) {
        const StarFacet& f = facets_[i];
        if (first_in_s(f[0], order) && first_in_s(f[1], order) && first_in_s(f[2], order) &&
            first_in_s(f[3], order)) {
          consider({f[0], f[1], f[2]});
        }
      }
    };
    uint32_t order = 0;
    consider_star(local.index, order++);
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) consider_star(ring_[i], order++);
  }
  if (candidates.empty()) return false;

  // The umbrella's triangles: vertices, CGAL points and boxes.
  struct Mine {
    int id[3];
    Eigen::Vector3d x[3];
    Point p[3];
    Eigen::AlignedBox3d box;
    PlaneFilter plane;
  };
  thread_local std::vector<Mine> mine;
  mine.clear();
  for (uint32_t i = local.triangles_begin; i < local.triangles_end; ++i) {
    const Triangle& tr = triangles_[i];
    Mine m{{local.index, tr.a, tr.b},
           {x, out_[tr.a], out_[tr.b]},
           {ToCgal(x), ToCgal(out_[tr.a]), ToCgal(out_[tr.b])},
           Eigen::AlignedBox3d(x),
           PlaneFilter()};
    m.box.extend(out_[tr.a]);
    m.box.extend(out_[tr.b]);
    if (!reference) m.plane = PlaneFilter(m.x[0], m.x[1], m.x[2]);
    mine.push_back(m);
  }
  for (const Facet& f : candidates) {
    const Eigen::Vector3d e[3] = {out_[f[0]], out_[f[1]], out_[f[2]]};
    Eigen::AlignedBox3d box(e[0]);
    box.extend(e[1]);
    box.extend(e[2]);
    const Point q[3] = {ToCgal(e[0]), ToCgal(e[1]), ToCgal(e[2])};
    const Kernel::Triangle_3 other_triangle(q[0], q[1], q[2]);
    PlaneFilter other_plane;
    bool other_plane_made = false;
    for (const Mine& m : mine) {
      // Closed triangles that meet have meeting boxes (the same doubles): exact to skip.
      if (!reference && !m.box.intersects(box)) continue;
      int shared = 0, shared_mine = -1, shared_other = -1;
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) {
          if (m.id[i] == f[j]) ++shared, shared_mine = i, shared_other = j;
        }
      }
      if (shared >= 2) continue;  // neighbours across an edge: the flip test's business
      if (!reference) {
        // Filter in doubles before the exact tests: a triangle or an edge certainly on one side
        // of the other triangle's plane misses it.
        if (!other_plane_made) {
          other_plane = PlaneFilter(e[0], e[1], e[2]);
          other_plane_made = true;
        }
        if (shared == 0) {
          if (m.plane.Aside({e[0], e[1], e[2]}) || other_plane.Aside({m.x[0], m.x[1], m.x[2]})) {
            continue;
          }
        } else if (m.plane.Aside({e[(shared_other + 1) % 3], e[(shared_other + 2) % 3]}) &&
                   other_plane.Aside({m.x[(shared_mine + 1) % 3], m.x[(shared_mine + 2) % 3]})) {
          continue;
        }
      }
      const Kernel::Triangle_3 triangle(m.p[0], m.p[1], m.p[2]);
      if (shared == 0) {
        if (CGAL::do_intersect(triangle, other_triangle)) return true;
        continue;
      }
      // One shared vertex: the far edge of each triangle must miss the other.
      const Kernel::Segment_3 far_other(q[(shared_other + 1) % 3], q[(shared_other + 2) % 3]);
      const Kernel::Segment_3 far_mine(m.p[(shared_mine + 1) % 3], m.p[(shared_mine + 2) % 3]);
      if (CGAL::do_intersect(far_other, triangle) || CGAL::do_intersect(far_mine, other_triangle)) {
        return true;
      }
    }
  }
  return false;
}

SmoothingResult SurfaceSmoother::Update(const DelaunayMesh::Impl& t,
                                        const std::vector<CellHandle>& region,
                                        const Eigen::Vector3d& centre, double radius,
                                        const SmoothingOptions& options) {
  // The vertices of the region.
  std::vector<VertexHandle> vertices;
  for (const CellHandle& c : region) {
    for (int i = 0; i < 4; ++i) {
      if (!t.tri.is_infinite(c->vertex(i))) vertices.push_back(c->vertex(i));
    }
  }
  std::sort(vertices.begin(), vertices.end());
  vertices.erase(std::unique(vertices.begin(), vertices.end()), vertices.end());
  return UpdateVertices(t, std::move(vertices), centre, radius, options);
}

SmoothingResult SurfaceSmoother::UpdateVertices(const DelaunayMesh::Impl& t,
                                                std::vector<VertexHandle> vertices,
                                                const Eigen::Vector3d& centre, double radius,
                                                const SmoothingOptions& options) {
  SmoothingResult result;
  Grow(t);
  locals_.clear();
  triangles_.clear();
  ring_.clear();
  facets_.clear();
  star_cells_.clear();
  const double radius2 = radius * radius;
  auto in_ball = [&](VertexHandle v) {
    return (ToEigen(v->point()) - centre).squaredNorm() < radius2;
  };
  // By index, so that runs are reproducible (addresses are not).
  std::sort(vertices.begin(), vertices.end(),
            [](VertexHandle a, VertexHandle b) { return a->info().index < b->info().index; });

  // The vertices recomputed (locals_, their slot by index), in a reproducible order. A vertex
  // in the set starts at its own point: out_ holds the current position of every vertex.
  auto in_set = [&](int index) { return slot_stamp_[index] == call_; };
  auto make_local = [&](VertexHandle v, const std::vector<UmbrellaTriangle>& umbrella,
                        bool ring_of_a_only) {
    Local local;
    local.v = v;
    local.index = v->info().index;
    local.own = ToEigen(v->point());
    local.previous = out_[local.index];
    local.triangles_begin = static_cast<uint32_t>(triangles_.size());
    for (const UmbrellaTriangle& tr : umbrella) {
      const Eigen::Vector3d a0 = ToEigen(tr.a->point()), b0 = ToEigen(tr.b->point());
      triangles_.push_back(
          {tr.a->info().index, tr.b->info().index, (a0 - local.own).cross(b0 - local.own)});
    }
    local.triangles_end = static_cast<uint32_t>(triangles_.size());
    local.ring_begin = static_cast<uint32_t>(ring_.size());
    for (const UmbrellaTriangle& tr : umbrella) {
      for (int w : {tr.a->info().index, tr.b->info().index}) {
        if (ring_of_a_only && w != tr.a->info().index) continue;
        if (!ring_of_a_only &&
            std::find(ring_.begin() + local.ring_begin, ring_.end(), w) != ring_.end()) {
          continue;
        }
        ring_.push_back(w);
      }
    }
    local.ring_end = static_cast<uint32_t>(ring_.size());
    locals_.push_back(local);
  };
  std::vector<UmbrellaTriangle> umbrella;
  auto umbrella_of = [&](VertexHandle v) {  // its star kept for StarFacets
    const auto [begin, end] = Star(t, v->info().index);
    UmbrellaOf(v, star_cells_.data() + begin, star_cells_.data() + end, umbrella);
  };
  auto add = [&](VertexHandle v, bool known) {
    const int index = v->info().index;
    if (in_set(index)) return;
    if (!known) umbrella_of(v);
    slot_stamp_[index] = call_;
    slot_[index] = static_cast<int>(locals_.size());
    make_local(v, umbrella, false);
    out_[index] = locals_.back().own;
  };
  std::vector<VertexHandle> changed_outside;  // umbrella changed, outside the ball
  std::vector<int> changed;                   // slots of the vertices whose umbrella changed
  for (const VertexHandle& v : vertices) {
    const int index = v->info().index;
    umbrella_of(v);
    if (umbrella.empty()) {
      out_[index] = ToEigen(v->point());
      moved_[index] = 0;
      has_umbrella_[index] = 0;
      continue;
    }
    const uint64_t h = UmbrellaHash(umbrella);
    if (has_umbrella_[index] && umbrella_[index] == h) continue;
    has_umbrella_[index] = 1;
    umbrella_[index] = h;
    if (!in_ball(v)) {
      if (moved_[index]) changed_outside.push_back(v);
      continue;
    }
    changed.push_back(static_cast<int>(locals_.size()));
    add(v, true);
  }
  for (int k : changed) {
    for (uint32_t i = locals_[k].ring_begin; i < locals_[k].ring_end; ++i) {
      const VertexHandle w = t.vertices[ring_[i]];
      if (in_ball(w)) add(w, false);
    }
  }
  const size_t num_set = locals_.size();
  result.vertices = num_set;

  // Whether v at x leaves every triangle of its umbrella facing O and not degenerate.
  auto valid = [&](const Local& local, const Eigen::Vector3d& x) {
    for (uint32_t i = local.triangles_begin; i < local.triangles_end; ++i) {
      const Triangle& tr = triangles_[i];
      const Eigen::Vector3d& a = out_[tr.a];
      const Eigen::Vector3d& b = out_[tr.b];
      const Eigen::Vector3d n = (a - x).cross(b - x);
      if (!(n.dot(tr.normal) > 0.0)) return false;
      const double longest =
          std::max({(a - x).squaredNorm(), (b - x).squaredNorm(), (b - a).squaredNorm()});
      if (n.norm() <= options.min_triangle_shape * longest) return false;
    }
    return true;
  };
  auto try_move = [&](const Local& local, const Eigen::Vector3d& x) {
    if (valid(local, x)) {
      out_[local.index] = x;
    } else {
      ++result.rejected;
    }
  };

  // Peak removal: a vertex far out of the plane of its umbrella (Newell normal of its link
  // polygon through the centroid of its neighbours) goes to that centroid.
  for (size_t k = 0; k < num_set; ++k) {
    const Local& local = locals_[k];
    if (local.ring_begin == local.ring_end) continue;
    const double ring_size = static_cast<double>(local.ring_end - local.ring_begin);
    const Eigen::Vector3d& x = out_[local.index];
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) m += out_[ring_[i]];
    m /= ring_size;
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    double edge = 0.0;
    for (uint32_t i = local.triangles_begin; i < local.triangles_end; ++i) {
      normal += (out_[triangles_[i].a] - m).cross(out_[triangles_[i].b] - m);
    }
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) {
      edge += (out_[ring_[i]] - x).norm();
    }
    edge /= ring_size;
    if (normal.norm() == 0.0) continue;
    const double height = std::abs((x - m).dot(normal.normalized()));
    if (height > options.peak_factor * edge) try_move(local, m);
  }
  // Taubin λ|μ steps: Laplacians of the whole set, then moves one by one, each checked against
  // the current positions, so that the last change of every triangle was checked. The Laplacian
  // is taken along the umbrella normal only (no drift along the surface) and weighs each
  // neighbour by its height over the tangent plane (bilateral, Fleishman et al. 2003), so that
  // the neighbours across a crease (a wall meeting the ground) barely pull.
  std::vector<Eigen::Vector3d> laplacian(num_set);
  const double cos_crease = std::cos(options.crease_angle_deg * M_PI / 180.0);
  auto normal_laplacian = [&](const Local& local) -> Eigen::Vector3d {
    if (local.ring_begin == local.ring_end) return Eigen::Vector3d::Zero();
    const Eigen::Vector3d& x = out_[local.index];
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    for (uint32_t i = local.triangles_begin; i < local.triangles_end; ++i) {
      normal += (out_[triangles_[i].a] - x).cross(out_[triangles_[i].b] - x);
    }
    if (normal.norm() == 0.0) return Eigen::Vector3d::Zero();
    normal.normalize();
    // A crease or a corner (a triangle turned far from the umbrella normal) is a feature: kept.
    for (uint32_t i = local.triangles_begin; i < local.triangles_end; ++i) {
      const Eigen::Vector3d n = (out_[triangles_[i].a] - x).cross(out_[triangles_[i].b] - x);
      if (n.dot(normal) < cos_crease * n.norm()) return Eigen::Vector3d::Zero();
    }
    double edge = 0.0;
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) {
      edge += (out_[ring_[i]] - x).norm();
    }
    const double sigma =
        options.feature_sigma * edge / static_cast<double>(local.ring_end - local.ring_begin);
    double sum = 0.0, weights = 0.0;
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) {
      const double h = (out_[ring_[i]] - x).dot(normal);
      const double weight = std::exp(-0.5 * h * h / (sigma * sigma));
      sum += weight * h;
      weights += weight;
    }
    return weights > 0.0 ? Eigen::Vector3d(normal * (sum / weights)) : Eigen::Vector3d::Zero();
  };
  for (int step = 0; step < 2 * options.taubin_steps; ++step) {
    const double factor = step % 2 == 0 ? options.lambda : options.mu;
    for (size_t k = 0; k < num_set; ++k) laplacian[k] = normal_laplacian(locals_[k]);
    for (size_t k = 0; k < num_set; ++k) {
      const Local& local = locals_[k];
      try_move(local, out_[local.index] + factor * laplacian[k]);
    }
  }

  // Local intersections: the triangles around each vertex that moved against the δO triangles
  // of the cells around it and its neighbours.
  std::vector<int> work;
  for (size_t k = 0; k < num_set; ++k) {
    if (out_[locals_[k].index] != locals_[k].previous) work.push_back(static_cast<int>(k));
  }
  for (const VertexHandle& v : changed_outside) {
    // Outside the ball a vertex keeps its position, unless its new umbrella meets something
    // there (then it goes back to its own point, like a vertex new to δO).
    umbrella_of(v);
    make_local(v, umbrella, /*ring_of_a_only=*/true);
    const Local& local = locals_.back();
    if (!options.reference_checks) GatherStarFacets(t, local);
    if (!valid(local, out_[local.index]) ||
        MeetsNearby(t, local, options.reference_checks, candidates_)) {
      out_[local.index] = local.own;
      moved_[local.index] = 0;
      ++result.rejected;
    }
  }
  // The first check of every vertex in work reads the positions as they are now: those checks
  // run in parallel first (the δO facets around the vertices gathered before, the only part
  // that writes), and the sequential pass below takes a vertex's result from there when no
  // position it reads has changed since. A check of k reads the positions of k, of its ring and
  // of the δO facets around them, all vertices of T adjacent to k or to its ring: a revert of j
  // marks j and its neighbours in T (dirty_stamp_), and k's first result stands while neither k
  // nor a vertex of its ring is marked. Same outcome as checking each vertex when popped.
  const bool prechecked = !options.reference_checks && work.size() >= 2;
  if (prechecked) {
    for (int k : work) GatherStarFacets(t, locals_[k]);
    first_check_.assign(num_set, 0);  // 0: none, 1: misses, 2: meets
    result.prechecked = work.size();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, work.size(), 32),
                      [&](const tbb::blocked_range<size_t>& range) {
                        thread_local std::vector<Facet> candidates;
                        for (size_t i = range.begin(); i != range.end(); ++i) {
                          const Local& local = locals_[work[i]];
                          first_check_[work[i]] = MeetsNearby(t, local, false, candidates) ? 2 : 1;
                        }
                      });
  }
  auto dirty = [&](int index) { return dirty_stamp_[index] == call_; };
  auto first_check_stands = [&](const Local& local) {
    if (dirty(local.index)) return false;
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) {
      if (dirty(ring_[i])) return false;
    }
    return true;
  };
  std::vector<VertexHandle> neighbours;
  while (!work.empty()) {
    const int k = work.back();
    work.pop_back();
    Local& local = locals_[k];
    if (local.reverts >= 2) continue;
    bool meets;
    if (prechecked && first_check_[k] != 0) {
      if (first_check_stands(local)) {
        meets = first_check_[k] == 2;
      } else {
        meets = MeetsNearby(t, local, false, candidates_);
        ++result.rechecked;
      }
      first_check_[k] = 0;
    } else {
      if (!options.reference_checks) GatherStarFacets(t, local);
      meets = MeetsNearby(t, local, options.reference_checks, candidates_);
    }
    if (!meets) continue;
    ++result.rejected;
    out_[local.index] = ++local.reverts == 1 ? local.previous : local.own;
    if (prechecked) {
      dirty_stamp_[local.index] = call_;
      neighbours.clear();
      t.tri.finite_adjacent_vertices(local.v, std::back_inserter(neighbours));
      for (const VertexHandle& w : neighbours) dirty_stamp_[w->info().index] = call_;
    }
    work.push_back(k);
    for (uint32_t i = local.ring_begin; i < local.ring_end; ++i) {
      if (in_set(ring_[i])) work.push_back(slot_[ring_[i]]);
    }
  }

  for (size_t k = 0; k < num_set; ++k) {
    const Local& local = locals_[k];
    moved_[local.index] = out_[local.index] != local.own ? 1 : 0;
  }
  return result;
}

TriangleMesh SurfaceSmoother::Extract(const DelaunayMesh::Impl& t) const {
  return ExtractBorderOfO(t, [this](VertexHandle v) { return Position(v); });
}

}  // namespace internal
}  // namespace omni
