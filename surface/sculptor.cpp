#include "surface/sculptor.h"

#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <Eigen/Geometry>
#include <atomic>
#include <chrono>
#include <cmath>
#include <queue>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include "surface/internal/cgal_delaunay.h"

namespace omni {

using internal::CellHandle;
using internal::Point;
using internal::ToCgal;
using internal::ToEigen;
using internal::VertexHandle;

std::string SculptorOptions::Check() const {
  if (!(scale >= 0.0) || !std::isfinite(scale)) return "scale must be >= 0 (0: measured)";
  if (!(steiner_step_factor > 0.0)) return "steiner_step_factor must be > 0";
  if (!(max_ray_length_factor > 0.0)) return "max_ray_length_factor must be > 0";
  if (!(below_ground_factor >= 0.0)) return "below_ground_factor must be >= 0";
  if (!(min_aperture_deg >= 0.0 && min_aperture_deg < 180.0)) {
    return "min_aperture_deg must be in [0, 180)";
  }
  if (!(up.norm() > 0.5 && up.norm() < 2.0) || !up.allFinite()) return "up must be a unit vector";
  if (init_keyframes < 2 && scale == 0.0) {
    return "init_keyframes must be >= 2 to measure the scale s";
  }
  if (init_keyframes < 1) return "init_keyframes must be >= 1";
  if (max_vertex_passes < 0) return "max_vertex_passes must be >= 0";
  if (enclosing_margin < 0) return "enclosing_margin must be >= 0";
  return "";
}

std::string KeyframeStatsCsvHeader() {
  return "keyframe,batch,points_in,points_filtered,points_added,points_rejected,"
         "points_duplicate,steiner_added,rays_new,rays_old,cells_e,cells_n,o_left_in_e,cells_t,"
         "cells_f,cells_o,triangles,ms_steiner,ms_enclose,ms_shrink,ms_insert,ms_rays,ms_grow,"
         "ms_total";
}

std::string KeyframeStatsCsvRow(const KeyframeStats& s) {
  std::ostringstream o;
  o << s.keyframe.value << ',' << (s.batch ? 1 : 0) << ',' << s.points_in << ','
    << s.points_filtered << ',' << s.points_added << ',' << s.points_rejected << ','
    << s.points_duplicate << ',' << s.steiner_added << ',' << s.rays_new << ',' << s.rays_old << ','
    << s.cells_e << ',' << s.cells_n << ',' << s.o_left_in_e << ',' << s.cells_t << ',' << s.cells_f
    << ',' << s.cells_o << ',' << s.triangles << ',' << s.ms_steiner << ',' << s.ms_enclose << ','
    << s.ms_shrink << ',' << s.ms_insert << ',' << s.ms_rays << ',' << s.ms_grow << ','
    << s.ms_total;
  return o.str();
}

namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// Whether the segment a→b meets the box; *exit (*entry): the largest (smallest) parameter
// (a + t (b − a)) inside.
bool SegmentHitsBox(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                    const Eigen::AlignedBox3d& box, double* exit = nullptr,
                    double* entry = nullptr) {
  double lo = 0.0, hi = 1.0;
  const Eigen::Vector3d d = b - a;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-300) {
      if (a[k] < box.min()[k] || a[k] > box.max()[k]) return false;
      continue;
    }
    double t0 = (box.min()[k] - a[k]) / d[k], t1 = (box.max()[k] - a[k]) / d[k];
    if (t0 > t1) std::swap(t0, t1);
    lo = std::max(lo, t0);
    hi = std::min(hi, t1);
    if (lo > hi) return false;
  }
  if (exit) *exit = hi;
  if (entry) *entry = lo;
  return true;
}

// Boxes (of the new cells N) in a hash grid, to find the old rays that can cross N (§4.4, with
// one box per new cell instead of the single X_N). Conservative: boxes are registered in the
// voxels they overlap grown by one voxel, and a segment is sampled every half voxel.
class BoxIndex {
 public:
  explicit BoxIndex(double voxel) : voxel_(voxel) {}

  void Add(const Eigen::AlignedBox3d& box) {
    const int id = static_cast<int>(boxes_.size());
    boxes_.push_back(box);
    bounds_.extend(box);
    const Eigen::Vector3i lo = Voxel(box.min()) - Eigen::Vector3i::Ones();
    const Eigen::Vector3i hi = Voxel(box.max()) + Eigen::Vector3i::Ones();
    if ((hi - lo).maxCoeff() > kMaxSpan) {
      large_.push_back(id);
      return;
    }
    for (int i = lo.x(); i <= hi.x(); ++i) {
      for (int j = lo.y(); j <= hi.y(); ++j) {
        for (int k = lo.z(); k <= hi.z(); ++k) grid_[Key(Eigen::Vector3i(i, j, k))].push_back(id);
      }
    }
  }
  const Eigen::AlignedBox3d& bounds() const { return bounds_; }

  // An upper bound of the parameter t (a + t (b − a)) beyond which the segment is in no box,
  // or −1 when it meets none. Scans the samples from b: a box met by the segment ending at t_e
  // has a sample within half a voxel of t_e in one of its (grown) voxels, so the first sample
  // from b with a hit is at t_f ≥ t_e − voxel/length.
  double LastHit(const Eigen::Vector3d& a, const Eigen::Vector3d& b) const {
    if (!SegmentHitsBox(a, b, bounds_)) return -1.0;
    double last = -1.0, exit;
    for (int id : large_) {
      if (SegmentHitsBox(a, b, boxes_[id], &exit)) last = std::max(last, exit);
    }
    const double length = (b - a).norm();
    const int samples = static_cast<int>(std::ceil(length / (0.5 * voxel_))) + 1;
    uint64_t previous = ~uint64_t{0};
    for (int n = samples; n >= 0; --n) {
      const double t = static_cast<double>(n) / samples;
      const uint64_t key = Key(Voxel(a + (b - a) * t));
      if (key == previous) continue;
      previous = key;
      const auto it = grid_.find(key);
      if (it == grid_.end()) continue;
      bool found = false;
      for (int id : it->second) {
        if (SegmentHitsBox(a, b, boxes_[id], &exit)) {
          found = true;
          last = std::max(last, exit);
        }
      }
      if (found) return std::max(last, std::min(1.0, t + voxel_ / std::max(length, 1e-300)));
    }
    return last;
  }

  // Bounds [*first, *last] of the parameters (a + t (b − a)) where the segment a→b can be in a
  // box: false when it meets none. *box: a box met at the voxel of *first (a hint). Scans the
  // samples from a, then from b, each scan stopping at the first voxel with a box met: a box met
  // from t_e on has a sample within half a voxel of t_e in one of its (grown) voxels, so the
  // first sample from a with a hit is at t_f ≤ t_e + voxel/length (mirrored from b). Each box
  // is tested at most once per scan however many voxels it was registered in.
  bool HitRange(const Eigen::Vector3d& a, const Eigen::Vector3d& b, double* first, double* last,
                int* box) const {
    *first = 2.0;
    *last = -1.0;
    *box = -1;
    if (!SegmentHitsBox(a, b, bounds_)) return false;
    thread_local std::vector<uint32_t> tested;  // per box: the scan stamp that tested it
    thread_local uint32_t scan = 0;
    thread_local const BoxIndex* owner = nullptr;
    if (owner != this || tested.size() != boxes_.size() || scan > 0xfffffff0u) {
      owner = this;
      tested.assign(boxes_.size(), 0);
      scan = 0;
    }
    const double length = (b - a).norm();
    const double slack = voxel_ / std::max(length, 1e-300);
    const int samples = static_cast<int>(std::ceil(length / (0.5 * voxel_))) + 1;
    double entry, exit;
    for (int direction = 0; direction < 2; ++direction) {
      const bool forward = direction == 0;
      ++scan;
      bool found = false;
      auto consider = [&](int id) {
        if (tested[id] == scan) return;
        tested[id] = scan;
        if (!SegmentHitsBox(a, b, boxes_[id], &exit, &entry)) return;
        found = true;
        if (forward && entry < *first) *first = entry, *box = id;
        if (!forward) *last = std::max(*last, exit);
      };
      for (int id : large_) consider(id);
      uint64_t previous = ~uint64_t{0};
      for (int n = 0; n <= samples; ++n) {
        const double t = static_cast<double>(forward ? n : samples - n) / samples;
        const uint64_t key = Key(Voxel(a + (b - a) * t));
        if (key == previous) continue;
        previous = key;
        const auto it = grid_.find(key);
        if (it == grid_.end()) continue;
        for (int id : it->second) consider(id);
        if (found) {
          if (forward) *first = std::min(*first, std::max(0.0, t - slack));
          if (!forward) *last = std::max(*last, std::min(1.0, t + slack));
          break;
        }
      }
      if (!found) return false;
    }
    return true;
  }

 private:
  static constexpr int kMaxSpan = 8;
  Eigen::Vector3i Voxel(const Eigen::Vector3d& p) const {
    return (p / voxel_).array().floor().cast<int>();
  }
  static uint64_t Key(const Eigen::Vector3i& v) {
    constexpr int64_t kOff = 1 << 20;
    return (static_cast<uint64_t>(v.x() + kOff) << 42) |
           (static_cast<uint64_t>(v.y() + kOff) << 21) | static_cast<uint64_t>(v.z() + kOff);
  }
  double voxel_;
  std::vector<Eigen::AlignedBox3d> boxes_;
  std::vector<int> large_;
  Eigen::AlignedBox3d bounds_;
  std::unordered_map<uint64_t, std::vector<int>> grid_;
};

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

struct PointRecord {
  VertexHandle vertex;
  std::vector<Eigen::Vector3d> origins;
};

struct KeyframeRecord {
  KeyframeId id;
  Eigen::Vector3d centre;
  Eigen::AlignedBox3d ray_box;  // X_t of §4.4: bounding box of the rays of its points
  std::vector<int> points;      // indices in Impl::points
};

struct RayTask {
  RayTask(VertexHandle v, const Point& p) : from(v), target(p) {}
  VertexHandle from;
  Point target;
  double stop = 2.0;  // the walk may stop once past this parameter along from→target
  // The walk may start at the cell holding from + start (target − from), located from `hint`
  // (0: from the vertex). Only for rays that count the new cells alone (§4.4).
  double start = 0.0;
  CellHandle hint;
};

// The kept points of a keyframe with their CGAL positions, in CGAL's spatial sort order, so
// that each insertion is located from the previous one.
std::vector<std::pair<Point, const SurfacePoint*>> SpatiallySorted(
    const std::vector<const SurfacePoint*>& points) {
  std::vector<std::pair<Point, const SurfacePoint*>> sorted;
  for (const SurfacePoint* p : points) sorted.emplace_back(ToCgal(p->position), p);
  using PairMap = CGAL::First_of_pair_property_map<std::pair<Point, const SurfacePoint*>>;
  CGAL::spatial_sort(sorted.begin(), sorted.end(),
                     CGAL::Spatial_sort_traits_adapter_3<internal::Kernel, PairMap>());
  return sorted;
}

}  // namespace

struct IncrementalSculptor::Impl {
  SculptorOptions options;
  DelaunayMesh mesh;
  DelaunayMesh::Impl& t;  // T and O bookkeeping
  std::vector<SurfaceKeyframe> buffered;
  double s = 0.0;           // scale of §5.1
  double step = 0.0;        // Steiner grid step
  double r = 0.0, l = 0.0;  // §3.3 bounds
  Eigen::Vector3d grid_origin = Eigen::Vector3d::Zero();
  std::unordered_set<uint64_t> grid_done;  // materialised grid points
  std::vector<PointRecord> points;
  std::vector<KeyframeRecord> keyframes;
  uint32_t stamp = 0;  // processing index of the current keyframe (the creation date)
  std::vector<VertexHandle> new_vertices;  // inserted during the current keyframe

  explicit Impl(const SculptorOptions& o) : options(o), t(*mesh.impl()) {}

  bool Active(CellHandle c) const {
    const internal::CellInfo& i = c->info();
    return !t.tri.is_infinite(c) && (i.e_stamp == stamp || i.date == stamp || i.ray_stamp == stamp);
  }
  bool HasSurfaceFacet(CellHandle c) const {
    for (int i = 0; i < 4; ++i) {
      if (c->neighbor(i)->info().in_o != c->info().in_o) return true;
    }
    return false;
  }

  void SetScale(const std::vector<SurfaceKeyframe>& first) {
    s = options.scale;
    if (s == 0.0) {
      double sum = 0.0;
      for (size_t i = 1; i < first.size(); ++i)
        sum += (first[i].centre - first[i - 1].centre).norm();
      s = first.size() > 1 ? sum / static_cast<double>(first.size() - 1) : 0.0;
    }
    if (!(s > 0.0)) {
      spdlog::warn("surface: keyframe centres do not move (s = 0); nothing to sculpt");
      return;
    }
    step = options.steiner_step_factor * s;
    l = step * std::sqrt(3.0);
    r = options.max_ray_length_factor * s;
    // Shift the grid off round coordinates so that grid planes do not contain the (often
    // axis-aligned) points and centres of synthetic scenes.
    grid_origin = first.front().centre + step * Eigen::Vector3d(0.3183, 0.2718, 0.1414);
  }

  // The §5.1 filters; returns the points kept.
  std::vector<const SurfacePoint*> Filter(const SurfaceKeyframe& kf, KeyframeStats& st) const {
    std::vector<const SurfacePoint*> kept;
    const double cos_min = std::cos(options.min_aperture_deg * M_PI / 180.0);
    const Eigen::Vector3d up = options.up.normalized();
    for (const SurfacePoint& p : kf.points) {
      bool ok = p.position.allFinite() && !p.rays.empty();
      if (ok && options.filter_points) {
        const Eigen::Vector3d d = p.position - kf.centre;
        if (d.dot(up) < -options.below_ground_factor * s) ok = false;
        if (d.norm() > r) ok = false;
        bool aperture = false;
        for (size_t i = 0; i < p.rays.size() && !aperture; ++i) {
          const Eigen::Vector3d a = (p.rays[i].origin - p.position).normalized();
          for (size_t j = i + 1; j < p.rays.size() && !aperture; ++j) {
            const Eigen::Vector3d b = (p.rays[j].origin - p.position).normalized();
            if (a.dot(b) < cos_min) aperture = true;
          }
        }
        if (!aperture) ok = false;
      }
      if (ok) {
        kept.push_back(&p);
      } else {
        ++st.points_filtered;
      }
    }
    return kept;
  }

  // Inserts p unless its conflict zone meets O (§4.3). Returns the new vertex, or a null handle
  // (rejected) with *duplicate telling whether p is an existing vertex.
  VertexHandle InsertFree(const Point& p, CellHandle& hint, bool* duplicate) {
    *duplicate = false;
    if (t.tri.dimension() < 3) {  // no cell yet, so no O: plain insertion
      const size_t before = t.tri.number_of_vertices();
      const VertexHandle v = t.tri.insert(p, hint);
      if (t.tri.number_of_vertices() == before) {
        *duplicate = true;
        return VertexHandle();
      }
      hint = v->cell();
      new_vertices.push_back(v);
      return v;
    }
    internal::Delaunay::Locate_type lt;
    int li, lj;
    const CellHandle c = t.tri.locate(p, lt, li, lj, hint);
    if (lt == internal::Delaunay::VERTEX) {
      *duplicate = true;
      return VertexHandle();
    }
    thread_local std::vector<CellHandle> conflicts;
    conflicts.clear();
    internal::Delaunay::Facet facet;
    t.tri.find_conflicts(p, c, CGAL::Oneset_iterator<internal::Delaunay::Facet>(facet),
                         std::back_inserter(conflicts));
    size_t in_f = 0;
    for (const CellHandle& k : conflicts) {
      if (k->info().in_o) return VertexHandle();
      if (k->info().counter > 0 && !t.tri.is_infinite(k)) ++in_f;
    }
    t.num_f -= in_f;  // F ← F \ D(p)
    const VertexHandle v =
        t.tri.insert_in_hole(p, conflicts.begin(), conflicts.end(), facet.first, facet.second);
    hint = v->cell();
    new_vertices.push_back(v);
    return v;
  }

  static uint64_t GridKey(long i, long j, long k) {
    constexpr long kOff = 1 << 20;
    return (static_cast<uint64_t>(i + kOff) << 42) | (static_cast<uint64_t>(j + kOff) << 21) |
           static_cast<uint64_t>(k + kOff);
  }

  // Materialises the Steiner grid points within r + 2l of c, so that the cells meeting
  // B_{r+l}(c) are cells of the grid region (§3.3).
  size_t MaterialiseGrid(const Eigen::Vector3d& c) {
    const double radius = r + 2.0 * l;
    const Eigen::Vector3d rel = (c - grid_origin) / step;
    const long span = static_cast<long>(std::ceil(radius / step)) + 1;
    std::vector<Point> todo;
    for (long i = std::lround(rel.x()) - span; i <= std::lround(rel.x()) + span; ++i) {
      for (long j = std::lround(rel.y()) - span; j <= std::lround(rel.y()) + span; ++j) {
        for (long k = std::lround(rel.z()) - span; k <= std::lround(rel.z()) + span; ++k) {
          const Eigen::Vector3d g = grid_origin + step * Eigen::Vector3d(i, j, k);
          if ((g - c).norm() > radius) continue;
          if (!grid_done.insert(GridKey(i, j, k)).second) continue;
          todo.push_back(ToCgal(g));
        }
      }
    }
    size_t added = 0;
    CellHandle hint = t.vertices.empty() ? CellHandle() : t.vertices.back()->cell();
    for (const Point& g : todo) {
      bool duplicate;
      const VertexHandle v = InsertFree(g, hint, &duplicate);
      if (v != VertexHandle()) {
        t.AddVertex(v, -1, true);
        ++added;
      }
    }
    return added;
  }

  // Cells included in the ball (all four vertices inside), found by a search from the cell
  // holding the centre through cells that meet the ball. Marks them with e_stamp.
  std::vector<CellHandle> CellsInBall(const Eigen::Vector3d& centre, double radius) {
    std::vector<CellHandle> inside;
    const Point pc = ToCgal(centre);
    const CellHandle start = t.tri.locate(pc);
    const double r2 = radius * radius;
    auto vertex_in = [&](VertexHandle v) {
      return !t.tri.is_infinite(v) && CGAL::squared_distance(v->point(), pc) <= r2;
    };
    std::vector<CellHandle> stack = {start};
    std::unordered_set<CellHandle, std::hash<CellHandle>> seen = {start};
    while (!stack.empty()) {
      const CellHandle c = stack.back();
      stack.pop_back();
      if (t.tri.is_infinite(c)) continue;
      int n_in = 0;
      for (int i = 0; i < 4; ++i) n_in += vertex_in(c->vertex(i)) ? 1 : 0;
      if (n_in == 4) {
        c->info().e_stamp = stamp;
        inside.push_back(c);
      }
      if (n_in == 0 && c != start) continue;
      for (int i = 0; i < 4; ++i) {
        const CellHandle nb = c->neighbor(i);
        if (seen.insert(nb).second) stack.push_back(nb);
      }
    }
    return inside;
  }

  // E as the union of the conflict zones of the points (without inserting them) plus `margin`
  // rings of neighbours. Marks them with e_stamp.
  std::vector<CellHandle> CellsInConflictZones(const std::vector<Point>& pts, int margin) {
    std::vector<CellHandle> cells, zone;
    if (t.tri.dimension() < 3) return cells;
    auto add = [&](CellHandle c) {
      if (t.tri.is_infinite(c) || c->info().e_stamp == stamp) return;
      c->info().e_stamp = stamp;
      cells.push_back(c);
    };
    CellHandle hint;
    for (const Point& p : pts) {
      internal::Delaunay::Locate_type lt;
      int li, lj;
      const CellHandle c = t.tri.locate(p, lt, li, lj, hint);
      hint = c;
      if (lt == internal::Delaunay::VERTEX) continue;
      zone.clear();
      t.tri.find_conflicts(p, c, CGAL::Emptyset_iterator(), std::back_inserter(zone));
      for (const CellHandle& k : zone) add(k);
    }
    size_t ring_begin = 0;
    for (int ring = 0; ring < margin; ++ring) {
      const size_t ring_end = cells.size();
      for (size_t i = ring_begin; i < ring_end; ++i) {
        for (int k = 0; k < 4; ++k) add(cells[i]->neighbor(k));
      }
      ring_begin = ring_end;
    }
    return cells;
  }

  // The cells where O may grow in this keyframe: E (what survived of it), N and the cells
  // crossed by new rays, found by a search from N and from the surviving cells of `seeds`.
  std::vector<CellHandle> ActiveCells(const std::vector<CellHandle>& n_cells,
                                      const std::vector<CellHandle>& seeds) {
    std::vector<CellHandle> active;
    std::unordered_set<CellHandle, std::hash<CellHandle>> seen;
    std::vector<CellHandle> stack;
    for (const CellHandle& c : n_cells) {
      if (seen.insert(c).second) stack.push_back(c);
    }
    for (const CellHandle& c : seeds) {
      if (Active(c) && seen.insert(c).second) stack.push_back(c);
    }
    while (!stack.empty()) {
      const CellHandle c = stack.back();
      stack.pop_back();
      active.push_back(c);
      for (int i = 0; i < 4; ++i) {
        const CellHandle nb = c->neighbor(i);
        if (Active(nb) && seen.insert(nb).second) stack.push_back(nb);
      }
    }
    return active;
  }

  // ---- Shrinking (§4.2, §4.7) ----
  void ShrinkOneAtOnce(std::vector<CellHandle> seeds) {
    CellQueue q(/*largest_first=*/false);
    for (const CellHandle& c : seeds) {
      if (c->info().in_o && c->info().e_stamp == stamp) q.Push(c);
    }
    while (!q.Empty()) {
      const CellHandle c = q.Pop();
      if (!c->info().in_o || !HasSurfaceFacet(c)) continue;
      if (!t.SingleCellTest(c)) continue;
      t.SetInO(c, false);
      for (int i = 0; i < 4; ++i) {
        const CellHandle nb = c->neighbor(i);
        if (nb->info().in_o && nb->info().e_stamp == stamp) q.Push(nb);
      }
    }
  }

  // Vertices of the cells, deduplicated.
  template <typename Cells>
  std::vector<VertexHandle> VerticesOf(const Cells& cells) const {
    std::vector<VertexHandle> vs;
    for (const CellHandle& c : cells) {
      for (int i = 0; i < 4; ++i) {
        if (!t.tri.is_infinite(c->vertex(i))) vs.push_back(c->vertex(i));
      }
    }
    // By vertex index, not address: the same input gives the same surface.
    std::sort(vs.begin(), vs.end(),
              [](VertexHandle a, VertexHandle b) { return a->info().index < b->info().index; });
    vs.erase(std::unique(vs.begin(), vs.end()), vs.end());
    return vs;
  }

  bool GeneralTestAll(const std::vector<VertexHandle>& vs) const {
    for (const VertexHandle& v : vs) {
      if (!t.GeneralTest(v)) return false;
    }
    return true;
  }

  void Shrink(const std::vector<CellHandle>& e_cells) {
    ShrinkOneAtOnce(e_cells);
    std::vector<CellHandle> star;
    for (int pass = 0; pass < options.max_vertex_passes; ++pass) {
      std::vector<CellHandle> left;
      for (const CellHandle& c : e_cells) {
        if (c->info().in_o) left.push_back(c);
      }
      if (left.empty()) return;
      bool progress = false;
      for (const VertexHandle& v : VerticesOf(left)) {
        if (!t.VertexOnSurface(v)) continue;
        star.clear();
        t.tri.incident_cells(v, std::back_inserter(star));
        std::vector<CellHandle> removed;
        for (const CellHandle& c : star) {
          if (c->info().in_o && c->info().e_stamp == stamp) removed.push_back(c);
        }
        if (removed.empty()) continue;
        for (const CellHandle& c : removed) t.SetInO(c, false);
        if (GeneralTestAll(VerticesOf(removed))) {
          progress = true;
          std::vector<CellHandle> next;
          for (const CellHandle& c : removed) {
            for (int i = 0; i < 4; ++i) next.push_back(c->neighbor(i));
          }
          ShrinkOneAtOnce(next);
        } else {
          for (const CellHandle& c : removed) t.SetInO(c, true);
        }
      }
      if (!progress) return;
    }
  }

  // ---- Growing (§4.5) ----
  void GrowOneAtOnce(const std::vector<CellHandle>& seeds, bool allow_isolated_seed) {
    CellQueue q(/*largest_first=*/true);
    for (const CellHandle& c : seeds) {
      if (!c->info().in_o && c->info().counter > 0 && !t.tri.is_infinite(c)) q.Push(c);
    }
    while (!q.Empty()) {
      const CellHandle c = q.Pop();
      if (c->info().in_o) continue;
      if (!HasSurfaceFacet(c) && !allow_isolated_seed) continue;
      if (!t.SingleCellTest(c)) continue;
      allow_isolated_seed = false;
      t.SetInO(c, true);
      for (int i = 0; i < 4; ++i) {
        const CellHandle nb = c->neighbor(i);
        if (!nb->info().in_o && nb->info().counter > 0 && !t.tri.is_infinite(nb)) {
          q.Push(nb);
        }
      }
    }
  }

  void Grow(const std::vector<CellHandle>& active) {
    std::vector<CellHandle> seeds;
    CellHandle best;
    for (const CellHandle& c : active) {
      if (c->info().in_o || c->info().counter == 0) continue;
      if (HasSurfaceFacet(c)) seeds.push_back(c);
      if (best == CellHandle() || c->info().counter > best->info().counter) best = c;
    }
    if (seeds.empty() && best != CellHandle()) {
      GrowOneAtOnce({best}, true);  // no border to grow from: start a component (§4.5)
    } else {
      GrowOneAtOnce(seeds, false);
    }
    std::vector<CellHandle> star;
    for (int pass = 0; pass < options.max_vertex_passes; ++pass) {
      bool progress = false;
      for (const VertexHandle& v : VerticesOf(active)) {
        if (!t.VertexOnSurface(v)) continue;
        star.clear();
        t.tri.incident_cells(v, std::back_inserter(star));
        std::vector<CellHandle> added;
        bool all_free = true;
        for (const CellHandle& c : star) {
          if (t.tri.is_infinite(c) || c->info().counter == 0) {
            all_free = false;
            break;
          }
          if (!c->info().in_o) added.push_back(c);
        }
        if (!all_free || added.empty()) continue;
        for (const CellHandle& c : added) t.SetInO(c, true);
        if (GeneralTestAll(VerticesOf(added))) {
          progress = true;
          std::vector<CellHandle> next;
          for (const CellHandle& c : added) {
            for (int i = 0; i < 4; ++i) next.push_back(c->neighbor(i));
          }
          GrowOneAtOnce(next, false);
        } else {
          for (const CellHandle& c : added) t.SetInO(c, false);
        }
      }
      if (!progress) return;
    }
  }

  // ---- Ray tracing (§4.4) ----
  // Traces the tasks in parallel; only_new: increment only the cells created in this keyframe.
  void Trace(const std::vector<RayTask>& tasks, bool only_new) {
    std::atomic<size_t> became_free{0};
    const uint32_t date = stamp;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tasks.size(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                        size_t local = 0;
                        auto visit = [&](CellHandle c) {
                          if (only_new && c->info().date != date) return;
                          if (!only_new)
                            __atomic_store_n(&c->info().ray_stamp, date, __ATOMIC_RELAXED);
                          if (__atomic_fetch_add(&c->info().counter, 1u, __ATOMIC_RELAXED) == 0) {
                            ++local;
                          }
                        };
                        for (size_t i = range.begin(); i != range.end(); ++i) {
                          const RayTask& task = tasks[i];
                          if (task.start > 0.0 && only_new) {
                            // Start inside the segment, at the cell holding a point before
                            // every new cell it can meet; exact when the segment enters that
                            // cell cleanly (any walk of the segment then crosses it through
                            // the same facet), otherwise the whole walk.
                            const Point& a = task.from->point();
                            const Point q(a.x() + task.start * (task.target.x() - a.x()),
                                          a.y() + task.start * (task.target.y() - a.y()),
                                          a.z() + task.start * (task.target.z() - a.z()));
                            internal::Delaunay::Locate_type lt;
                            int li, lj;
                            const CellHandle c = t.tri.locate(q, lt, li, lj, task.hint);
                            const int entry = t.EntryFacet(a, task.target, c);
                            if (entry >= 0) {
                              t.WalkFrom(a, task.target, c, entry, task.stop, visit);
                              continue;
                            }
                          }
                          t.Walk(task.from, task.target, task.stop, visit);
                        }
                        became_free += local;
                      });
    t.num_f += became_free;
  }

  // The cells created in this keyframe: the stars of the vertices inserted in it.
  std::vector<CellHandle> NewCells() {
    std::vector<CellHandle> cells, star;
    for (const VertexHandle& v : new_vertices) {
      star.clear();
      t.tri.incident_cells(v, std::back_inserter(star));
      for (const CellHandle& c : star) {
        if (t.tri.is_infinite(c) || c->info().date == stamp) continue;
        c->info().date = stamp;
        cells.push_back(c);
      }
    }
    return cells;
  }

  void FinishStats(KeyframeStats& st) const {
    st.cells_t = t.tri.number_of_finite_cells();
    st.cells_f = t.num_f;
    st.cells_o = t.num_o;
    st.triangles = t.num_triangles;
  }

  int AddPoint(const SurfacePoint& p, VertexHandle v, KeyframeRecord& kf) {
    v = t.AddVertex(v, static_cast<int32_t>(points.size()), false);
    PointRecord rec;
    rec.vertex = v;
    for (const SurfaceRay& ray : p.rays) {
      rec.origins.push_back(ray.origin);
      kf.ray_box.extend(ray.origin);
    }
    kf.ray_box.extend(p.position);
    points.push_back(std::move(rec));
    kf.points.push_back(static_cast<int>(points.size()) - 1);
    return kf.points.back();
  }

  // ---- One keyframe, paper §4 steps 1–5 (step 6, handle removal and smoothing, is not here) ----
  KeyframeStats Incremental(const SurfaceKeyframe& kf) {
    const auto start = Clock::now();
    ++stamp;
    new_vertices.clear();
    KeyframeStats st;
    st.keyframe = kf.id;
    st.points_in = kf.points.size();
    const std::vector<const SurfacePoint*> kept = Filter(kf, st);

    auto tick = Clock::now();
    st.steiner_added = MaterialiseGrid(kf.centre);
    st.ms_steiner = MsSince(tick);

    // Step 1: E = cells in B_{r+l}(c_{t+1}).
    tick = Clock::now();
    std::vector<Point> kept_points;
    for (const SurfacePoint* p : kept) kept_points.push_back(ToCgal(p->position));
    const std::vector<CellHandle> e_cells =
        options.enclosing == EnclosingMode::kBall
            ? CellsInBall(kf.centre, r + l)
            : CellsInConflictZones(kept_points, options.enclosing_margin);
    st.cells_e = e_cells.size();
    st.ms_enclose = MsSince(tick);

    // Step 2: shrink O out of E.
    tick = Clock::now();
    Shrink(e_cells);
    for (const CellHandle& c : e_cells) st.o_left_in_e += c->info().in_o ? 1 : 0;
    st.ms_shrink = MsSince(tick);

    // Step 3: insert the points whose conflict zone misses O.
    tick = Clock::now();
    KeyframeRecord rec;
    rec.id = kf.id;
    rec.centre = kf.centre;
    const auto sorted = SpatiallySorted(kept);
    CellHandle hint = t.tri.locate(ToCgal(kf.centre));
    for (const auto& [pt, p] : sorted) {
      bool duplicate;
      const VertexHandle v = InsertFree(pt, hint, &duplicate);
      if (v == VertexHandle()) {
        ++(duplicate ? st.points_duplicate : st.points_rejected);
        continue;
      }
      AddPoint(*p, v, rec);
      ++st.points_added;
    }
    const std::vector<CellHandle> n_cells = NewCells();
    st.cells_n = n_cells.size();
    st.ms_insert = MsSince(tick);

    // Step 4: new rays fully, old rays over N.
    tick = Clock::now();
    std::vector<RayTask> tasks;
    for (int i : rec.points) {
      for (const Eigen::Vector3d& o : points[i].origins)
        tasks.emplace_back(points[i].vertex, ToCgal(o));
    }
    st.rays_new = tasks.size();
    Trace(tasks, false);
    tasks.clear();
    if (!n_cells.empty()) {
      BoxIndex index_n(2.0 * s);  // X_N, refined into one box per new cell (in n_cells order)
      for (const CellHandle& c : n_cells) {
        Eigen::AlignedBox3d box;
        for (int i = 0; i < 4; ++i) box.extend(ToEigen(c->vertex(i)->point()));
        index_n.Add(box);
      }
      std::vector<RayTask> candidates;
      for (const KeyframeRecord& old : keyframes) {
        if (!old.ray_box.intersects(index_n.bounds())) continue;
        for (int i : old.points) {
          for (const Eigen::Vector3d& o : points[i].origins) {
            candidates.emplace_back(points[i].vertex, ToCgal(o));
          }
        }
      }
      std::vector<double> last(candidates.size(), -1.0);
      const bool clip = options.clip_old_rays;
      const bool locate_start = clip && options.locate_old_ray_start;
      tbb::parallel_for(tbb::blocked_range<size_t>(0, candidates.size(), 256),
                        [&](const tbb::blocked_range<size_t>& range) {
                          for (size_t i = range.begin(); i != range.end(); ++i) {
                            RayTask& task = candidates[i];
                            const Eigen::Vector3d a = ToEigen(task.from->point());
                            const Eigen::Vector3d b = ToEigen(task.target);
                            last[i] = index_n.LastHit(a, b);
                            if (!clip || last[i] < 0.0) continue;
                            task.stop = last[i];
                            if (!locate_start) continue;
                            double first, exact_last;
                            int box;
                            if (!index_n.HitRange(a, b, &first, &exact_last, &box)) continue;
                            // Start a margin before the first box, far above the rounding of
                            // the located point.
                            first -= 1e-7;
                            if (first > 0.0) {
                              task.start = first;
                              task.hint = n_cells[box];
                            }
                          }
                        });
      for (size_t i = 0; i < candidates.size(); ++i) {
        if (last[i] >= 0.0) tasks.push_back(candidates[i]);
      }
    }
    st.rays_old = tasks.size();
    Trace(tasks, true);
    keyframes.push_back(std::move(rec));
    st.ms_rays = MsSince(tick);

    // Step 5: grow O in F, within E (recomputed: insertion replaced cells) and N.
    tick = Clock::now();
    std::vector<CellHandle> ball;
    if (options.enclosing == EnclosingMode::kBall) ball = CellsInBall(kf.centre, r + l);
    Grow(ActiveCells(n_cells, ball));
    st.ms_grow = MsSince(tick);

    FinishStats(st);
    st.ms_total = MsSince(start);
    return st;
  }

  // Paper §5.1: T, F and O of the first keyframes at once.
  KeyframeStats Batch(const std::vector<SurfaceKeyframe>& kfs) {
    const auto start = Clock::now();
    ++stamp;
    new_vertices.clear();
    KeyframeStats st;
    st.batch = true;
    st.keyframe = kfs.back().id;
    auto tick = Clock::now();
    for (const SurfaceKeyframe& kf : kfs) st.steiner_added += MaterialiseGrid(kf.centre);
    st.ms_steiner = MsSince(tick);
    tick = Clock::now();
    for (const SurfaceKeyframe& kf : kfs) {
      st.points_in += kf.points.size();
      KeyframeRecord rec;
      rec.id = kf.id;
      rec.centre = kf.centre;
      const auto kept = Filter(kf, st);
      const auto sorted = SpatiallySorted(kept);
      CellHandle hint = t.tri.locate(ToCgal(kf.centre));
      for (const auto& [pt, p] : sorted) {
        bool duplicate;
        const VertexHandle v = InsertFree(pt, hint, &duplicate);  // O is empty: never rejected
        if (v == VertexHandle()) {
          ++(duplicate ? st.points_duplicate : st.points_rejected);
          continue;
        }
        AddPoint(*p, v, rec);
        ++st.points_added;
      }
      keyframes.push_back(std::move(rec));
    }
    std::vector<CellHandle> all;
    for (auto c : t.tri.finite_cell_handles()) {
      c->info().date = stamp;
      c->info().e_stamp = stamp;
      all.push_back(c);
    }
    st.cells_e = st.cells_n = all.size();
    st.ms_insert = MsSince(tick);
    tick = Clock::now();
    std::vector<RayTask> tasks;
    for (const PointRecord& p : points) {
      for (const Eigen::Vector3d& o : p.origins) tasks.emplace_back(p.vertex, ToCgal(o));
    }
    st.rays_new = tasks.size();
    Trace(tasks, false);
    st.ms_rays = MsSince(tick);
    tick = Clock::now();
    Grow(all);
    st.ms_grow = MsSince(tick);
    FinishStats(st);
    st.ms_total = MsSince(start);
    return st;
  }

  std::vector<KeyframeStats> ProcessBuffered() {
    std::vector<KeyframeStats> out;
    if (buffered.empty()) return out;
    SetScale(buffered);
    if (!(s > 0.0)) {
      buffered.clear();
      return out;
    }
    if (options.batch_init) {
      out.push_back(Batch(buffered));
    } else {
      for (const SurfaceKeyframe& kf : buffered) out.push_back(Incremental(kf));
    }
    buffered.clear();
    return out;
  }
};

IncrementalSculptor::IncrementalSculptor(const SculptorOptions& options)
    : impl_(std::make_unique<Impl>(options)) {
  const std::string problem = options.Check();
  if (!problem.empty()) throw std::invalid_argument("SculptorOptions: " + problem);
}

IncrementalSculptor::~IncrementalSculptor() = default;

std::vector<KeyframeStats> IncrementalSculptor::AddKeyframe(const SurfaceKeyframe& keyframe) {
  Impl& m = *impl_;
  if (m.s > 0.0) return {m.Incremental(keyframe)};
  m.buffered.push_back(keyframe);
  const bool known = m.options.scale > 0.0;
  if (static_cast<int>(m.buffered.size()) >= m.options.init_keyframes || known) {
    return m.ProcessBuffered();
  }
  return {};
}

std::vector<KeyframeStats> IncrementalSculptor::Finish() { return impl_->ProcessBuffered(); }

TriangleMesh IncrementalSculptor::ExtractMesh() const { return impl_->mesh.ExtractSurface(); }
const DelaunayMesh& IncrementalSculptor::triangulation() const { return impl_->mesh; }
double IncrementalSculptor::scale() const { return impl_->s; }
size_t IncrementalSculptor::NumProcessedKeyframes() const { return impl_->keyframes.size(); }

std::string IncrementalSculptor::CheckInvariants(bool check_triangulation) const {
  const Impl& m = *impl_;
  const auto& tri = m.t.tri;
  std::ostringstream problems;
  if (check_triangulation && !tri.is_valid(false)) problems << "T is not a valid Delaunay; ";
  size_t o = 0, f = 0, triangles = 0, o_not_f = 0, infinite_in_o = 0;
  for (auto c : tri.all_cell_handles()) {
    if (tri.is_infinite(c)) {
      if (c->info().in_o) ++infinite_in_o;
      continue;
    }
    if (c->info().counter > 0) ++f;
    if (!c->info().in_o) continue;
    ++o;
    if (c->info().counter == 0) ++o_not_f;
    for (int i = 0; i < 4; ++i) triangles += c->neighbor(i)->info().in_o ? 0 : 1;
  }
  if (o_not_f) problems << o_not_f << " cells of O not in F; ";
  if (infinite_in_o) problems << infinite_in_o << " infinite cells in O; ";
  if (o != m.t.num_o) problems << "|O| " << m.t.num_o << " != recount " << o << "; ";
  if (f != m.t.num_f) problems << "|F| " << m.t.num_f << " != recount " << f << "; ";
  if (triangles != m.t.num_triangles) {
    problems << "|δO| " << m.t.num_triangles << " != recount " << triangles << "; ";
  }
  return problems.str();
}

}  // namespace omni
