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

#include <CGAL/intersections.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <unordered_set>

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

// The δO triangles around v; empty when v is not on δO.
void UmbrellaOf(const Delaunay& tri, VertexHandle v, std::vector<UmbrellaTriangle>& out) {
  out.clear();
  ForEachBorderTriangleAround(tri, v, [&](CellHandle c, int k, VertexHandle a, VertexHandle b) {
    // Counter-clockwise seen from O: the cell's vertex k (on O's side) above (v, a, b).
    if (CGAL::orientation(v->point(), a->point(), b->point(), c->vertex(k)->point()) ==
        CGAL::NEGATIVE) {
      std::swap(a, b);
    }
    out.push_back({a, b});
  });
}

uint64_t UmbrellaHash(const std::vector<UmbrellaTriangle>& umbrella) {
  std::vector<uint64_t> keys;
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

struct Local {
  VertexHandle v;
  Eigen::Vector3d x, previous, own;
  std::vector<UmbrellaTriangle> umbrella;
  std::vector<VertexHandle> ring;  // distinct neighbours on δO
  int reverts = 0;
};

}  // namespace

Eigen::Vector3d SurfaceSmoother::Position(VertexHandle v) const {
  const auto it = moved_.find(v->info().index);
  return it == moved_.end() ? ToEigen(v->point()) : it->second;
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
  const double radius2 = radius * radius;
  auto in_ball = [&](VertexHandle v) {
    return (ToEigen(v->point()) - centre).squaredNorm() < radius2;
  };
  // By index, so that runs are reproducible (addresses are not).
  std::sort(vertices.begin(), vertices.end(),
            [](VertexHandle a, VertexHandle b) { return a->info().index < b->info().index; });

  std::unordered_map<int, Local> set;  // the vertices recomputed, by index
  std::vector<int> order;              // their indices, in a reproducible order
  std::vector<UmbrellaTriangle> umbrella;
  std::vector<VertexHandle> changed_outside;  // umbrella changed, outside the ball
  auto add = [&](VertexHandle v, std::vector<UmbrellaTriangle>* known) {
    const int index = v->info().index;
    if (set.count(index)) return;
    Local& local = set[index];
    local.v = v;
    if (known) {
      local.umbrella = *known;
    } else {
      UmbrellaOf(t.tri, v, local.umbrella);
    }
    for (const UmbrellaTriangle& tr : local.umbrella) {
      for (VertexHandle w : {tr.a, tr.b}) {
        if (std::find(local.ring.begin(), local.ring.end(), w) == local.ring.end()) {
          local.ring.push_back(w);
        }
      }
    }
    local.own = ToEigen(v->point());
    local.previous = Position(v);
    local.x = local.own;
    order.push_back(index);
  };
  std::vector<VertexHandle> changed;
  for (const VertexHandle& v : vertices) {
    const int index = v->info().index;
    UmbrellaOf(t.tri, v, umbrella);
    if (umbrella.empty()) {
      moved_.erase(index);
      umbrella_.erase(index);
      continue;
    }
    const uint64_t h = UmbrellaHash(umbrella);
    auto it = umbrella_.find(index);
    if (it != umbrella_.end() && it->second == h) continue;
    umbrella_[index] = h;
    if (!in_ball(v)) {
      if (moved_.count(index)) changed_outside.push_back(v);
      continue;
    }
    changed.push_back(v);
    add(v, &umbrella);
  }
  for (const VertexHandle& v : changed) {
    const std::vector<VertexHandle> ring = set[v->info().index].ring;
    for (const VertexHandle& w : ring) {
      if (in_ball(w)) add(w, nullptr);
    }
  }
  result.vertices = order.size();

  auto position = [&](VertexHandle w) -> Eigen::Vector3d {
    const auto it = set.find(w->info().index);
    return it == set.end() ? Position(w) : it->second.x;
  };
  // Whether v at x leaves every triangle of its umbrella facing O and not degenerate.
  auto valid = [&](const Local& local, const Eigen::Vector3d& x) {
    for (const UmbrellaTriangle& tr : local.umbrella) {
      const Eigen::Vector3d a0 = ToEigen(tr.a->point()), b0 = ToEigen(tr.b->point());
      const Eigen::Vector3d n0 = (a0 - local.own).cross(b0 - local.own);
      const Eigen::Vector3d a = position(tr.a), b = position(tr.b);
      const Eigen::Vector3d n = (a - x).cross(b - x);
      if (!(n.dot(n0) > 0.0)) return false;
      const double longest =
          std::max({(a - x).squaredNorm(), (b - x).squaredNorm(), (b - a).squaredNorm()});
      if (n.norm() <= options.min_triangle_shape * longest) return false;
    }
    return true;
  };
  auto try_move = [&](Local& local, const Eigen::Vector3d& x) {
    if (valid(local, x)) {
      local.x = x;
    } else {
      ++result.rejected;
    }
  };

  // Peak removal: a vertex far out of the plane of its umbrella (Newell normal of its link
  // polygon through the centroid of its neighbours) goes to that centroid.
  for (int index : order) {
    Local& local = set[index];
    if (local.ring.empty()) continue;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (const VertexHandle& w : local.ring) m += position(w);
    m /= static_cast<double>(local.ring.size());
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    double edge = 0.0;
    for (const UmbrellaTriangle& tr : local.umbrella) {
      normal += (position(tr.a) - m).cross(position(tr.b) - m);
    }
    for (const VertexHandle& w : local.ring) edge += (position(w) - local.x).norm();
    edge /= static_cast<double>(local.ring.size());
    if (normal.norm() == 0.0) continue;
    const double height = std::abs((local.x - m).dot(normal.normalized()));
    if (height > options.peak_factor * edge) try_move(local, m);
  }
  // Taubin λ|μ steps: Laplacians of the whole set, then moves one by one, each checked against
  // the current positions, so that the last change of every triangle was checked. The Laplacian
  // is taken along the umbrella normal only (no drift along the surface) and weighs each
  // neighbour by its height over the tangent plane (bilateral, Fleishman et al. 2003), so that
  // the neighbours across a crease (a wall meeting the ground) barely pull.
  std::vector<Eigen::Vector3d> laplacian(order.size());
  const double cos_crease = std::cos(options.crease_angle_deg * M_PI / 180.0);
  auto normal_laplacian = [&](const Local& local) -> Eigen::Vector3d {
    if (local.ring.empty()) return Eigen::Vector3d::Zero();
    Eigen::Vector3d normal = Eigen::Vector3d::Zero();
    for (const UmbrellaTriangle& tr : local.umbrella) {
      normal += (position(tr.a) - local.x).cross(position(tr.b) - local.x);
    }
    if (normal.norm() == 0.0) return Eigen::Vector3d::Zero();
    normal.normalize();
    // A crease or a corner (a triangle turned far from the umbrella normal) is a feature: kept.
    for (const UmbrellaTriangle& tr : local.umbrella) {
      const Eigen::Vector3d n = (position(tr.a) - local.x).cross(position(tr.b) - local.x);
      if (n.dot(normal) < cos_crease * n.norm()) return Eigen::Vector3d::Zero();
    }
    double edge = 0.0;
    for (const VertexHandle& w : local.ring) edge += (position(w) - local.x).norm();
    const double sigma = options.feature_sigma * edge / static_cast<double>(local.ring.size());
    double sum = 0.0, weights = 0.0;
    for (const VertexHandle& w : local.ring) {
      const double h = (position(w) - local.x).dot(normal);
      const double weight = std::exp(-0.5 * h * h / (sigma * sigma));
      sum += weight * h;
      weights += weight;
    }
    return weights > 0.0 ? Eigen::Vector3d(normal * (sum / weights)) : Eigen::Vector3d::Zero();
  };
  for (int step = 0; step < 2 * options.taubin_steps; ++step) {
    const double factor = step % 2 == 0 ? options.lambda : options.mu;
    for (size_t k = 0; k < order.size(); ++k) laplacian[k] = normal_laplacian(set[order[k]]);
    for (size_t k = 0; k < order.size(); ++k) {
      Local& local = set[order[k]];
      try_move(local, local.x + factor * laplacian[k]);
    }
  }

  // Local intersections: the triangles around each vertex that moved against the δO triangles
  // of the cells around it and its neighbours.
  auto meets_nearby = [&](const Local& local) {
    // The cells around v and its ring, each once (sorted handles), then their δO facets: each
    // δO facet is seen once from its cell in O.
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
    for (const VertexHandle& w : local.ring) add_star(w);
    std::sort(cells.begin(), cells.end());
    cells.erase(std::unique(cells.begin(), cells.end()), cells.end());
    // The umbrella at the new positions and its bounding box: a triangle whose box misses it
    // cannot meet it.
    const Point x = ToCgal(local.x);
    Eigen::AlignedBox3d umbrella_box(local.x);
    for (const UmbrellaTriangle& tr : local.umbrella) {
      umbrella_box.extend(position(tr.a));
      umbrella_box.extend(position(tr.b));
    }
    const double pad =
        1e-9 * (1.0 + umbrella_box.diagonal().norm() + umbrella_box.max().cwiseAbs().maxCoeff());
    umbrella_box.extend(umbrella_box.max() + Eigen::Vector3d::Constant(pad));
    umbrella_box.extend(umbrella_box.min() - Eigen::Vector3d::Constant(pad));
    for (const CellHandle& c : cells) {
      for (int k = 0; k < 4; ++k) {
        if (c->neighbor(k)->info().in_o) continue;
        const VertexHandle other[3] = {c->vertex((k + 1) & 3), c->vertex((k + 2) & 3),
                                       c->vertex((k + 3) & 3)};
        const Eigen::Vector3d e[3] = {position(other[0]), position(other[1]), position(other[2])};
        Eigen::AlignedBox3d box(e[0]);
        box.extend(e[1]);
        box.extend(e[2]);
        if (!box.intersects(umbrella_box)) continue;
        const Point q[3] = {ToCgal(e[0]), ToCgal(e[1]), ToCgal(e[2])};
        const Kernel::Triangle_3 other_triangle(q[0], q[1], q[2]);
        for (const UmbrellaTriangle& tr : local.umbrella) {
          const VertexHandle mine[3] = {local.v, tr.a, tr.b};
          int shared = 0, shared_mine = -1, shared_other = -1;
          for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j) {
              if (mine[i] == other[j]) ++shared, shared_mine = i, shared_other = j;
            }
          }
          if (shared >= 2) continue;  // neighbours across an edge: the flip test's business
          const Point p[3] = {x, ToCgal(position(tr.a)), ToCgal(position(tr.b))};
          const Kernel::Triangle_3 triangle(p[0], p[1], p[2]);
          if (shared == 0) {
            if (CGAL::do_intersect(triangle, other_triangle)) return true;
            continue;
          }
          // One shared vertex: the far edge of each triangle must miss the other.
          const Kernel::Segment_3 far_other(q[(shared_other + 1) % 3], q[(shared_other + 2) % 3]);
          const Kernel::Segment_3 far_mine(p[(shared_mine + 1) % 3], p[(shared_mine + 2) % 3]);
          if (CGAL::do_intersect(far_other, triangle) ||
              CGAL::do_intersect(far_mine, other_triangle)) {
            return true;
          }
        }
      }
    }
    return false;
  };
  std::vector<int> work;
  for (int index : order) {
    if (set[index].x != set[index].previous) work.push_back(index);
  }
  for (const VertexHandle& v : changed_outside) {
    // Outside the ball a vertex keeps its position, unless its new umbrella meets something
    // there (then it goes back to its own point, like a vertex new to δO).
    const int index = v->info().index;
    Local local;
    local.v = v;
    UmbrellaOf(t.tri, v, local.umbrella);
    for (const UmbrellaTriangle& tr : local.umbrella) local.ring.push_back(tr.a);
    local.own = ToEigen(v->point());
    local.x = Position(v);
    if (!valid(local, local.x) || meets_nearby(local)) {
      moved_.erase(index);
      ++result.rejected;
    }
  }
  while (!work.empty()) {
    const int index = work.back();
    work.pop_back();
    Local& local = set[index];
    if (local.reverts >= 2 || !meets_nearby(local)) continue;
    ++result.rejected;
    local.x = ++local.reverts == 1 ? local.previous : local.own;
    work.push_back(index);
    for (const VertexHandle& w : local.ring) {
      if (set.count(w->info().index)) work.push_back(w->info().index);
    }
  }

  for (int index : order) {
    const Local& local = set[index];
    if (local.x == local.own) {
      moved_.erase(index);
    } else {
      moved_[index] = local.x;
    }
  }
  return result;
}

TriangleMesh SurfaceSmoother::Extract(const DelaunayMesh::Impl& t) const {
  return ExtractBorderOfO(t, [this](VertexHandle v) { return Position(v); });
}

}  // namespace internal
}  // namespace omni
