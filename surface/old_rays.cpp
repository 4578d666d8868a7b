#include "surface/internal/old_rays.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

namespace omni::internal {

namespace {
// Bound of the relative rounding of the plane side tests in doubles (a few ulps in fact).
constexpr double kRelativeTolerance = 1e-9;
}  // namespace

void RayGrid::Add(uint32_t ray, const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  grid_.ForEachVoxelOnSegment(a, b, [&](uint64_t key) {
    std::vector<uint32_t>& rays = rays_[key];
    // The straight-to-the-end fallback of the DDA may repeat a voxel.
    if (rays.empty() || rays.back() != ray) {
      rays.push_back(ray);
      ++entries_;
    }
  });
}

NewCellBorder::NewCellBorder(const Delaunay& tri, const std::vector<CellHandle>& n_cells,
                             uint32_t date, const VoxelGrid& grid)
    : tri_(tri), grid_(grid) {
  const double step = grid.step();
  // Voxels within this distance of a facet are registered too, far above the rounding of the
  // DDA of RayGrid (which may skip a voxel that a segment grazes at an edge or a corner).
  const double pad = 1e-6 * step;
  std::vector<std::pair<uint64_t, uint32_t>> registered;  // (voxel key, facet id)
  for (const CellHandle& c : n_cells) {
    for (int k = 0; k < 4; ++k) {
      const CellHandle nb = c->neighbor(k);
      if (nb->info().date == date || tri.is_infinite(nb)) continue;
      FacetOf of;
      of.cell = c;
      of.index = k;
      Eigen::Vector3d corner[3];
      for (int j = 0; j < 3; ++j) {
        of.vertex[j] = c->vertex((k + 1 + j) & 3);
        corner[j] = ToEigen(of.vertex[j]->point());
      }
      const Eigen::Vector3d &a = corner[0], &b = corner[1], &d = corner[2];
      Facet facet;
      facet.normal = (b - a).cross(d - a);
      facet.offset = facet.normal.dot(a);
      facet.extent = std::max(
          {a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff(), d.cwiseAbs().maxCoeff(), 1.0});
      facet.norm = facet.normal.norm();
      facet.tolerance = kRelativeTolerance * facet.norm;
      for (int e = 0; e < 3; ++e) {
        const Eigen::Vector3d edge = corner[(e + 1) % 3] - corner[e];
        // normal · (edge × (x − p)) = (normal × edge) · (x − p), p = corner[e].
        facet.edge_normal[e] = facet.normal.cross(edge);
        facet.edge_offset[e] = facet.edge_normal[e].dot(corner[e]);
        facet.edge_slack[e] = 1e-7 * facet.norm * edge.norm();
      }
      const uint32_t id = static_cast<uint32_t>(facets_.size());
      facets_.push_back(facet);
      facet_of_.push_back(of);
      Eigen::AlignedBox3d box(a);
      box.extend(b);
      box.extend(d);
      const Eigen::Vector3i lo = grid.VoxelOf(box.min() - Eigen::Vector3d::Constant(pad));
      const Eigen::Vector3i hi = grid.VoxelOf(box.max() + Eigen::Vector3d::Constant(pad));
      const Eigen::Vector3d n = facet.normal;
      const double half = 0.5 * step + pad;
      const double reach =
          half * n.cwiseAbs().sum() +
          facet.tolerance * std::max(facet.extent, (box.max().cwiseAbs().maxCoeff() + step));
      for (int i = lo.x(); i <= hi.x(); ++i) {
        for (int j = lo.y(); j <= hi.y(); ++j) {
          for (int m = lo.z(); m <= hi.z(); ++m) {
            // Skip voxels (grown by pad) wholly on one side of the facet's plane.
            const Eigen::Vector3d centre = (Eigen::Vector3d(i, j, m).array() + 0.5) * step;
            if (std::abs(n.dot(centre) - facet.offset) > reach) continue;
            registered.emplace_back(VoxelGrid::Key(Eigen::Vector3i(i, j, m)), id);
          }
        }
      }
    }
  }
  // Facet ids grouped by voxel (ids ascending within a voxel).
  std::sort(registered.begin(), registered.end());
  ids_.reserve(registered.size());
  for (size_t r = 0; r < registered.size(); ++r) {
    if (r == 0 || registered[r].first != registered[r - 1].first) {
      keys_.push_back(registered[r].first);
      first_.push_back(static_cast<uint32_t>(ids_.size()));
    }
    ids_.push_back(registered[r].second);
  }
  first_.push_back(static_cast<uint32_t>(ids_.size()));
  voxel_index_.reserve(keys_.size());
  for (size_t i = 0; i < keys_.size(); ++i)
    voxel_index_.emplace(keys_[i], static_cast<uint32_t>(i));
}

namespace {

enum class Crossing { kNone, kEnters, kDegenerate };

// Whether the segment from→target enters cell c through its facet k (paper §4.4 walk): cleanly,
// not at all, or touching the closed facet in a degenerate way. `from_vertex`: from is a vertex
// of T, so it lies in no closed facet but its own.
Crossing FacetEntry(const Point& from, const Point& target, CellHandle c, int k) {
  std::array<const Point*, 4> q = {&c->vertex(0)->point(), &c->vertex(1)->point(),
                                   &c->vertex(2)->point(), &c->vertex(3)->point()};
  const std::array<const Point*, 4> v = q;
  q[k] = &from;
  const CGAL::Orientation of = CGAL::orientation(*q[0], *q[1], *q[2], *q[3]);
  if (of == CGAL::POSITIVE) return Crossing::kNone;  // from on c's side: it cannot enter there
  q[k] = &target;
  const CGAL::Orientation ot = CGAL::orientation(*q[0], *q[1], *q[2], *q[3]);
  if (of == CGAL::ZERO) {
    // from on the plane: the segment lies in it (degenerate) or meets it only at from, which
    // is a vertex of this facet (a start in c, which the walk from the point's vertex handles)
    // or outside the closed facet (a vertex of T lies in no other closed facet).
    return ot == CGAL::ZERO ? Crossing::kDegenerate : Crossing::kNone;
  }
  if (ot == CGAL::NEGATIVE) return Crossing::kNone;  // both strictly beyond the facet
  const int a = (k + 1) & 3, b = (k + 2) & 3, d = (k + 3) & 3;
  const CGAL::Orientation o1 = CGAL::orientation(from, target, *v[a], *v[b]);
  const CGAL::Orientation o2 = CGAL::orientation(from, target, *v[b], *v[d]);
  const CGAL::Orientation o3 = CGAL::orientation(from, target, *v[d], *v[a]);
  const bool has_pos = o1 == CGAL::POSITIVE || o2 == CGAL::POSITIVE || o3 == CGAL::POSITIVE;
  const bool has_neg = o1 == CGAL::NEGATIVE || o2 == CGAL::NEGATIVE || o3 == CGAL::NEGATIVE;
  if (has_pos && has_neg) return Crossing::kNone;      // the line misses the closed facet
  if (ot == CGAL::ZERO) return Crossing::kDegenerate;  // the segment ends on the facet
  if (o1 != CGAL::ZERO && o1 == o2 && o2 == o3) return Crossing::kEnters;
  return Crossing::kDegenerate;  // through an edge or a vertex of the facet
}

}  // namespace

bool NewCellBorder::Entries(VertexHandle from_vertex, const Point& target,
                            std::vector<CellFacet>* entries) const {
  entries->clear();
  if (facets_.empty()) return true;
  thread_local std::vector<uint32_t> tested;  // per facet: the query that tested it
  thread_local uint32_t query = 0;
  thread_local const NewCellBorder* owner = nullptr;
  if (owner != this || tested.size() != facets_.size() || query == 0xffffffffu) {
    owner = this;
    tested.assign(facets_.size(), 0);
    query = 0;
  }
  ++query;
  uint32_t* const tested_by = tested.data();  // the thread_local looked up once
  const uint32_t this_query = query;
  const Point& from = from_vertex->point();
  const Eigen::Vector3d a = ToEigen(from), b = ToEigen(target);
  const Eigen::Vector3d ab = b - a;
  const double length = ab.norm();
  const double extent = std::max(a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff());
  bool clean = true;
  grid_.ForEachVoxelOnSegment(a, b, [&](uint64_t key) {
    if (!clean) return;
    const auto it = voxel_index_.find(key);
    if (it == voxel_index_.end()) return;
    const uint32_t* id_end = ids_.data() + first_[it->second + 1];
    for (const uint32_t* pid = ids_.data() + first_[it->second]; pid != id_end; ++pid) {
      const uint32_t id = *pid;
      if (tested_by[id] == this_query) continue;
      tested_by[id] = this_query;
      const Facet& f = facets_[id];
      const double sa = f.normal.dot(a) - f.offset, sb = f.normal.dot(b) - f.offset;
      const double scale = std::max(f.extent, extent);
      const double tol = f.tolerance * scale;
      if ((sa > tol && sb > tol) || (sa < -tol && sb < -tol)) {
        continue;  // both ends strictly on one side of the facet's plane
      }
      if ((sa > tol && sb < -tol) || (sa < -tol && sb > tol)) {
        // A clear crossing of the plane, not too grazing: the crossing point is accurate, so
        // a point clearly out of the facet (beyond one edge's line) meets nothing.
        if (std::abs(sa - sb) > 1e-3 * f.norm * length) {
          const Eigen::Vector3d x = a + (sa / (sa - sb)) * ab;
          bool outside = false;
          for (int e = 0; e < 3 && !outside; ++e) {
            if (f.edge_normal[e].dot(x) - f.edge_offset[e] < -f.edge_slack[e] * scale) {
              outside = true;
            }
          }
          if (outside) continue;
        }
      }
      const FacetOf& of = facet_of_[id];
      if (of.vertex[0] == from_vertex || of.vertex[1] == from_vertex ||
          of.vertex[2] == from_vertex) {
        // from is a corner of the facet, so exactly on its plane (FacetEntry's first predicate
        // is ZERO, which only exact arithmetic would certify): the segment enters nowhere through
        // it unless it lies in the plane (a predicate the static filter settles when target is
        // clearly off the plane).
        if (CGAL::orientation(of.vertex[0]->point(), of.vertex[1]->point(), of.vertex[2]->point(),
                              target) != CGAL::ZERO) {
          continue;
        }
        clean = false;  // the segment lies in the facet's plane (FacetEntry: kDegenerate)
        return;
      }
      switch (FacetEntry(from, target, of.cell, of.index)) {
        case Crossing::kNone:
          break;
        case Crossing::kEnters:
          entries->emplace_back(of.cell, of.index);
          break;
        case Crossing::kDegenerate:
          clean = false;
          return;
      }
    }
  });
  return clean;
}

}  // namespace omni::internal
