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
                             uint32_t date, const VoxelGrid& grid, int subdivision)
    : NewCellBorder(tri, grid, subdivision) {
  Build(n_cells, date);
}

NewCellBorder::NewCellBorder(const Delaunay& tri, const VoxelGrid& grid, int subdivision)
    : tri_(tri), grid_(grid), subdivision_asked_(subdivision) {}

void NewCellBorder::Build(const std::vector<CellHandle>& n_cells, uint32_t date,
                          bool only_crossed) {
  Collect(n_cells, date, only_crossed);
  Index();
}

void NewCellBorder::Collect(const std::vector<CellHandle>& n_cells, uint32_t date,
                            bool only_crossed) {
  const Delaunay& tri = tri_;
  // Every buffer is cleared, its memory kept for the next keyframe (fresh large allocations
  // cost page faults).
  facets_.clear();
  facet_of_.clear();
  keys_.clear();
  uncrossed_ = 0;
  first_.clear();
  ids_.clear();
  block_first_.clear();
  block_ids_.clear();
  num_blocks_ = 0;
  size_.setZero();
  std::vector<Eigen::AlignedBox3d>& boxes = scratch_.boxes;
  boxes.clear();
  Eigen::AlignedBox3d& all = scratch_.all;
  all.setEmpty();
  for (const CellHandle& c : n_cells) {
    for (int k = 0; k < 4; ++k) {
      const CellHandle nb = c->neighbor(k);
      if (nb->info().date == date || tri.is_infinite(nb)) continue;
      if (only_crossed && nb->info().counter == 0) {
        ++uncrossed_;
        continue;
      }
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
      // A finite cell is positively oriented: orientation(v0, v1, v2, v3) > 0, and the facet's
      // vertices (a, b, d) = (v_k+1, v_k+2, v_k+3) followed by v_k are an even permutation of
      // them for odd k, an odd one for even k.
      facet.inner = (k & 1) ? 1.0 : -1.0;
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
      facets_.push_back(facet);
      facet_of_.push_back(of);
      Eigen::AlignedBox3d box(a);
      box.extend(b);
      box.extend(d);
      boxes.push_back(box);
      all.extend(box);
    }
  }
}

void NewCellBorder::Index() {
  if (facets_.empty()) return;
  const VoxelGrid& grid = grid_;
  const std::vector<Eigen::AlignedBox3d>& boxes = scratch_.boxes;
  const Eigen::AlignedBox3d& all = scratch_.all;
  const double step = grid.step();
  // Voxels within this distance of a facet are registered too, far above the rounding of the
  // voxel walks (which may skip a voxel that a segment grazes at an edge or a corner). The same
  // absolute pad for the fine voxels: a voxel of `grid` that the walk of RayGrid passes within
  // the rounding of a crossing point then holds a registered fine voxel (the one of its points
  // nearest to the crossing), so its key is in voxels().
  const double pad = 1e-6 * step;

  // The blocks: one voxel of `grid` each, or several (and no subdivision) when the box of the
  // border would need too many.
  const Eigen::Vector3d pad3 = Eigen::Vector3d::Constant(pad);
  subdivision_ = std::max(1, subdivision_asked_);
  for (grid_per_block_ = 1;; ++grid_per_block_) {
    const double block_step = step * grid_per_block_;
    lo_ = ((all.min() - pad3) / block_step).array().floor().cast<int>();
    size_ = ((all.max() + pad3) / block_step).array().floor().cast<int>() - lo_.array() + 1;
    const double volume = static_cast<double>(size_.x()) * size_.y() * size_.z();
    if (volume <= static_cast<double>(kMaxBlocks)) break;
    subdivision_ = 1;
  }
  block_side_ = subdivision_ * grid_per_block_;
  fine_step_ = step / subdivision_;
  const int block_voxels = block_side_ * block_side_ * block_side_;
  block_.assign(static_cast<size_t>(size_.x()) * size_.y() * size_.z(), -1);
  for (int k = 0; k < 3; ++k) {
    const int stride_block = k == 0 ? 1 : (k == 1 ? size_.x() : size_.x() * size_.y());
    const int stride_voxel = k == 0 ? 1 : (k == 1 ? block_side_ : block_side_ * block_side_);
    const int n = size_[k] * block_side_;
    block_offset_[k].resize(n);
    voxel_offset_[k].resize(n);
    for (int r = 0; r < n; ++r) {
      block_offset_[k][r] = (r / block_side_) * stride_block;
      voxel_offset_[k][r] = (r % block_side_) * stride_voxel;
    }
  }

  // (fine voxel, facet id) and (block, facet id) pairs, by facet id; a fine voxel numbered
  // through its block.
  std::vector<std::pair<uint32_t, uint32_t>>& registered = scratch_.registered;
  std::vector<std::pair<uint32_t, uint32_t>>& registered_in_block = scratch_.registered_in_block;
  std::vector<uint32_t>& count = scratch_.count;
  registered.clear();
  registered_in_block.clear();
  count.clear();
  const Eigen::Vector3i fine_lo = lo_ * block_side_;  // the first fine voxel of the box
  // The number of block linear index `cell` (allocated on first use).
  auto number_of = [&](int32_t cell) {
    int32_t& number = block_[cell];
    if (number < 0) {
      number = static_cast<int32_t>(num_blocks_++);
      count.resize(count.size() + block_voxels, 0);
      const Eigen::Vector3i b = Eigen::Vector3i(cell % size_.x(), (cell / size_.x()) % size_.y(),
                                                cell / (size_.x() * size_.y())) +
                                lo_;
      for (int z = 0; z < grid_per_block_; ++z) {
        for (int y = 0; y < grid_per_block_; ++y) {
          for (int x = 0; x < grid_per_block_; ++x) {
            keys_.push_back(VoxelGrid::Key(b * grid_per_block_ + Eigen::Vector3i(x, y, z)));
          }
        }
      }
    }
    return number;
  };
  // Calls add(r) for every voxel r (index relative to the voxel origin, side h) within [lo, hi]
  // whose box grown by pad is not wholly on one side of the facet's plane: column by column
  // along the axis w where the normal is largest, the voxels passing the test are within the
  // range where the plane meets the column (widened by one voxel against rounding; the test
  // decides).
  auto for_each_voxel_near = [&](const Facet& facet, const Eigen::AlignedBox3d& box, double h,
                                 const Eigen::Vector3i& origin, auto&& add) {
    const Eigen::Vector3i lo =
        ((box.min() - pad3) / h).array().floor().cast<int>() - origin.array();
    const Eigen::Vector3i hi =
        ((box.max() + pad3) / h).array().floor().cast<int>() - origin.array();
    const Eigen::Vector3d& n = facet.normal;
    const double reach =
        (0.5 * h + pad) * n.cwiseAbs().sum() +
        facet.tolerance * std::max(facet.extent, (box.max().cwiseAbs().maxCoeff() + step + h));
    int w = 0;
    n.cwiseAbs().maxCoeff(&w);
    const int u = (w + 1) % 3, v = (w + 2) % 3;
    Eigen::Vector3i r;
    for (r[u] = lo[u]; r[u] <= hi[u]; ++r[u]) {
      for (r[v] = lo[v]; r[v] <= hi[v]; ++r[v]) {
        int first = lo[w], last = hi[w];
        if (n[w] != 0.0) {
          const double cu = (r[u] + origin[u] + 0.5) * h, cv = (r[v] + origin[v] + 0.5) * h;
          const double rest = facet.offset - n[u] * cu - n[v] * cv;  // n[w] · c_w = rest ± reach
          double c0 = (rest - reach) / n[w], c1 = (rest + reach) / n[w];
          if (c0 > c1) std::swap(c0, c1);
          // c_w = (r[w] + origin[w] + 0.5) · h.
          first = std::max(first, static_cast<int>(std::floor(c0 / h - 0.5)) - origin[w] - 1);
          last = std::min(last, static_cast<int>(std::ceil(c1 / h - 0.5)) - origin[w] + 1);
        }
        for (r[w] = first; r[w] <= last; ++r[w]) {
          const Eigen::Vector3d centre = ((r + origin).cast<double>().array() + 0.5) * h;
          if (std::abs(n.dot(centre) - facet.offset) <= reach) add(r);
        }
      }
    }
  };
  const double block_step = step * grid_per_block_;
  for (uint32_t id = 0; id < facets_.size(); ++id) {
    const Facet& facet = facets_[id];
    const Eigen::AlignedBox3d& box = boxes[id];
    if (subdivision_ > 1 && box.sizes().maxCoeff() <= kFineFacetSize * step) {
      for_each_voxel_near(facet, box, fine_step_, fine_lo, [&](const Eigen::Vector3i& r) {
        const int32_t number =
            number_of(block_offset_[0][r.x()] + block_offset_[1][r.y()] + block_offset_[2][r.z()]);
        const uint32_t v = static_cast<uint32_t>(number) * block_voxels + voxel_offset_[0][r.x()] +
                           voxel_offset_[1][r.y()] + voxel_offset_[2][r.z()];
        ++count[v];
        registered.emplace_back(v, id);
      });
    } else {
      for_each_voxel_near(facet, box, block_step, lo_, [&](const Eigen::Vector3i& b) {
        const int32_t number = number_of((b.z() * size_.y() + b.y()) * size_.x() + b.x());
        registered_in_block.emplace_back(static_cast<uint32_t>(number), id);
      });
    }
  }
  // Facet ids grouped by fine voxel and by block (counting sorts: ids ascending in each).
  auto group = [](const std::vector<std::pair<uint32_t, uint32_t>>& pairs,
                  std::vector<uint32_t>& count, std::vector<uint32_t>* first,
                  std::vector<uint32_t>* ids) {
    first->resize(count.size() + 1);
    uint32_t sum = 0;
    for (size_t v = 0; v < count.size(); ++v) {
      (*first)[v] = sum;
      sum += count[v];
      count[v] = (*first)[v];
    }
    (*first)[count.size()] = sum;
    ids->resize(pairs.size());
    for (const auto& [v, id] : pairs) (*ids)[count[v]++] = id;
  };
  group(registered, count, &first_, &ids_);
  std::vector<uint32_t>& block_count = scratch_.block_count;
  block_count.assign(num_blocks_, 0);
  for (const auto& pair : registered_in_block) ++block_count[pair.first];
  group(registered_in_block, block_count, &block_first_, &block_ids_);
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

struct NewCellBorder::Query {
  VertexHandle from_vertex;
  const Point* from;
  const Point* target;
  Eigen::Vector3d a, b, ab;  // from, target, target − from in doubles
  double length;             // ‖ab‖
  double extent;             // largest coordinate magnitude of a and b

  Query(VertexHandle from_vertex_, const Point& target_)
      : from_vertex(from_vertex_),
        from(&from_vertex_->point()),
        target(&target_),
        a(ToEigen(*from)),
        b(ToEigen(target_)),
        ab(b - a),
        length(ab.norm()),
        extent(std::max(a.cwiseAbs().maxCoeff(), b.cwiseAbs().maxCoeff())) {}
};

NewCellBorder::Test NewCellBorder::TestFacet(uint32_t id, const Query& q) const {
  const Facet& f = facets_[id];
  const double sa = f.normal.dot(q.a) - f.offset, sb = f.normal.dot(q.b) - f.offset;
  const double scale = std::max(f.extent, q.extent);
  const double tol = f.tolerance * scale;
  // from strictly on the N cell's side of the plane: the segment cannot enter there
  // (FacetEntry's first predicate is POSITIVE); both ends strictly on the other side: it misses.
  if (f.inner * sa > tol || (f.inner * sa < -tol && f.inner * sb < -tol)) {
    return Test::kMiss;
  }
  if ((sa > tol && sb < -tol) || (sa < -tol && sb > tol)) {
    // A clear crossing of the plane, not too grazing: the crossing point is accurate, so
    // a point clearly out of the facet (beyond one edge's line) meets nothing.
    if (std::abs(sa - sb) > 1e-3 * f.norm * q.length) {
      const Eigen::Vector3d x = q.a + (sa / (sa - sb)) * q.ab;
      for (int e = 0; e < 3; ++e) {
        if (f.edge_normal[e].dot(x) - f.edge_offset[e] < -f.edge_slack[e] * scale) {
          return Test::kMiss;
        }
      }
    }
  }
  const FacetOf& of = facet_of_[id];
  if (of.vertex[0] == q.from_vertex || of.vertex[1] == q.from_vertex ||
      of.vertex[2] == q.from_vertex) {
    // from is a corner of the facet, so exactly on its plane (FacetEntry's first predicate
    // is ZERO, which only exact arithmetic would certify): the segment enters nowhere through
    // it unless it lies in the plane (a predicate the static filter settles when target is
    // clearly off the plane).
    if (std::abs(sb) > tol) return Test::kMiss;  // target clearly off the plane
    if (CGAL::orientation(of.vertex[0]->point(), of.vertex[1]->point(), of.vertex[2]->point(),
                          *q.target) != CGAL::ZERO) {
      return Test::kMiss;
    }
    return Test::kDegenerate;  // the segment lies in the facet's plane (FacetEntry: kDegenerate)
  }
  switch (FacetEntry(*q.from, *q.target, of.cell, of.index)) {
    case Crossing::kNone:
      return Test::kMiss;
    case Crossing::kEnters:
      return Test::kEnters;
    case Crossing::kDegenerate:
      break;
  }
  return Test::kDegenerate;
}

bool NewCellBorder::Entries(VertexHandle from_vertex, const Point& target,
                            std::vector<CellFacet>* entries, EntriesWork* work) const {
  entries->clear();
  if (facets_.empty()) return true;
  EntriesWork counted;
  struct AddOnReturn {
    EntriesWork& counted;
    EntriesWork* work;
    ~AddOnReturn() {
      if (work != nullptr) *work += counted;
    }
  } add_on_return{counted, work};
  ++counted.queries;
  const Query q(from_vertex, target);

  // The part of the segment in the box of the blocks, grown by a fine voxel: a crossing point
  // lies in a facet's box, at least that far inside, far beyond the rounding of the clipping.
  const double block_step = fine_step_ * block_side_;
  const Eigen::Vector3d box_lo =
      lo_.cast<double>() * block_step - Eigen::Vector3d::Constant(fine_step_);
  const Eigen::Vector3d box_hi =
      (lo_ + size_).cast<double>() * block_step + Eigen::Vector3d::Constant(fine_step_);
  double t0 = 0.0, t1 = 1.0;
  for (int k = 0; k < 3; ++k) {
    if (q.ab[k] == 0.0) {
      if (q.a[k] < box_lo[k] || q.a[k] > box_hi[k]) return true;
      continue;
    }
    double u = (box_lo[k] - q.a[k]) / q.ab[k], w = (box_hi[k] - q.a[k]) / q.ab[k];
    if (u > w) std::swap(u, w);
    t0 = std::max(t0, u);
    t1 = std::min(t1, w);
  }
  if (t0 > t1) return true;  // the segment misses the box: it crosses no border facet
  const Eigen::Vector3d clip_a = t0 > 0.0 ? Eigen::Vector3d(q.a + t0 * q.ab) : q.a;
  const Eigen::Vector3d clip_b = t1 < 1.0 ? Eigen::Vector3d(q.a + t1 * q.ab) : q.b;

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
  const uint32_t* const first = first_.data();
  const uint32_t* const ids = ids_.data();
  const int32_t* const block = block_.data();
  const int32_t *const bx = block_offset_[0].data(), *const by = block_offset_[1].data(),
                       *const bz = block_offset_[2].data();
  const int32_t *const vx = voxel_offset_[0].data(), *const vy = voxel_offset_[1].data(),
                       *const vz = voxel_offset_[2].data();
  const Eigen::Vector3i fine_lo = lo_ * block_side_;
  const Eigen::Vector3i fine_size = size_ * block_side_;
  const uint32_t block_voxels = static_cast<uint32_t>(block_side_ * block_side_ * block_side_);
  const uint32_t* const block_first = block_first_.data();
  const uint32_t* const block_ids = block_ids_.data();
  int32_t last_block = -1;
  bool clean = true;
  // Tests facet id once per query; false when the crossing is degenerate (the walk stops).
  const Facet* const facets = facets_.data();
  auto test = [&](uint32_t id) {
    if (tested_by[id] == this_query) return true;
    tested_by[id] = this_query;
    ++counted.facets;
    {
      // TestFacet's plane test inline (most facets end there).
      const Facet& f = facets[id];
      const double sa = f.normal.dot(q.a) - f.offset, sb = f.normal.dot(q.b) - f.offset;
      const double tol = f.tolerance * std::max(f.extent, q.extent);
      if (f.inner * sa > tol || (f.inner * sa < -tol && f.inner * sb < -tol)) return true;
    }
    ++counted.plane_passes;
    switch (TestFacet(id, q)) {
      case Test::kMiss:
        return true;
      case Test::kEnters:
        entries->emplace_back(facet_of_[id].cell, facet_of_[id].index);
        return true;
      case Test::kDegenerate:
        break;
    }
    clean = false;
    return false;
  };
  ForEachVoxelIndexOnSegment(fine_step_, clip_a, clip_b, [&](const Eigen::Vector3i& global) {
    ++counted.voxels;
    const Eigen::Vector3i r = global - fine_lo;
    if ((r.array() < 0).any() || (r.array() >= fine_size.array()).any()) return true;
    const int32_t number = block[bx[r.x()] + by[r.y()] + bz[r.z()]];
    if (number < 0) return true;
    if (number != last_block) {
      // The facets of the block (the large ones), tested when the walk enters it.
      last_block = number;
      const uint32_t* const block_id_end = block_ids + block_first[number + 1];
      for (const uint32_t* pid = block_ids + block_first[number]; pid != block_id_end; ++pid) {
        if (!test(*pid)) return false;
      }
    }
    const uint32_t v =
        static_cast<uint32_t>(number) * block_voxels + vx[r.x()] + vy[r.y()] + vz[r.z()];
    const uint32_t* const id_end = ids + first[v + 1];
    for (const uint32_t* pid = ids + first[v]; pid != id_end; ++pid) {
      if (!test(*pid)) return false;
    }
    return true;
  });
  return clean;
}

bool NewCellBorder::EntriesBruteForce(VertexHandle from_vertex, const Point& target,
                                      std::vector<CellFacet>* entries) const {
  entries->clear();
  const Query q(from_vertex, target);
  for (uint32_t id = 0; id < facets_.size(); ++id) {
    switch (TestFacet(id, q)) {
      case Test::kMiss:
        break;
      case Test::kEnters:
        entries->emplace_back(facet_of_[id].cell, facet_of_[id].index);
        break;
      case Test::kDegenerate:
        return false;
    }
  }
  return true;
}

}  // namespace omni::internal
