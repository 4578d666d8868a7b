#include "surface/sculptor.h"

#include <CGAL/Spatial_sort_traits_adapter_3.h>
#include <CGAL/property_map.h>
#include <CGAL/spatial_sort.h>
#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>
#include <tbb/task_group.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <mutex>
#include <queue>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include "calib/error.h"
#include "surface/internal/cgal_delaunay.h"
#include "surface/internal/old_rays.h"
#include "surface/internal/step6.h"

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
  if (!(min_point_separation_factor >= 0.0 && min_point_separation_factor < 1.0)) {
    return "min_point_separation_factor must be in [0, 1)";
  }
  if (!(min_point_separation_pixels >= 0.0 && min_point_separation_pixels <= 100.0)) {
    return "min_point_separation_pixels must be in [0, 100]";
  }
  if (!(pixel_angle >= 0.0 && pixel_angle < 0.1)) return "pixel_angle must be in [0, 0.1)";
  if (!(below_ground_factor >= 0.0)) return "below_ground_factor must be >= 0";
  if (!(reach_quantile >= 0.0 && reach_quantile <= 1.0)) return "reach_quantile must be in [0, 1]";
  if (!(ground_quantile >= 0.0 && ground_quantile <= 1.0)) {
    return "ground_quantile must be in [0, 1]";
  }
  if (!(ground_margin_factor >= 0.0)) return "ground_margin_factor must be >= 0";
  if (!(min_aperture_deg >= 0.0 && min_aperture_deg < 180.0)) {
    return "min_aperture_deg must be in [0, 180)";
  }
  if (!(up.norm() > 0.5 && up.norm() < 2.0) || !up.allFinite()) return "up must be a unit vector";
  if (init_keyframes < 2 && scale == 0.0) {
    return "init_keyframes must be >= 2 to measure the scale s";
  }
  if (init_keyframes < 1) return "init_keyframes must be >= 1";
  if (keyframes_per_step < 1 || keyframes_per_step > 64)
    return "keyframes_per_step must be in [1, 64]";
  if (max_vertex_passes < 0) return "max_vertex_passes must be >= 0";
  if (enclosing_margin < 0) return "enclosing_margin must be >= 0";
  if (enclosing_rounds < 0) return "enclosing_rounds must be >= 0";
  if (enclosing_round_rings < 1) return "enclosing_round_rings must be >= 1";
  if (enclosing_star_rings < 1) return "enclosing_star_rings must be >= 1";
  if (grow_closure_rounds < 0) return "grow_closure_rounds must be >= 0";
  if (!(ray_grid_step_factor > 0.0)) return "ray_grid_step_factor must be > 0";
  if (enclosed_free_neighbours != 0 &&
      (enclosed_free_neighbours < 2 || enclosed_free_neighbours > 4)) {
    return "enclosed_free_neighbours must be 0 (off), 2, 3 or 4";
  }
  if (enclosed_free_rounds < 1) return "enclosed_free_rounds must be >= 1";
  if (!(free_ray_length_factor >= 0.0)) return "free_ray_length_factor must be >= 0";
  if (!(uncertain_ray_margin_deg >= 0.0)) return "uncertain_ray_margin_deg must be >= 0";
  if (!(uncertain_ray_min_fraction > 0.0 && uncertain_ray_min_fraction < 1.0))
    return "uncertain_ray_min_fraction must be in (0, 1)";
  // The parts' Check() name their fields with the prefix already ("genus.max_group_cells").
  for (const std::string& problem : {genus.Check(), smoothing.Check(), observed.Check()}) {
    if (!problem.empty()) return problem;
  }
  return "";
}

double MeanKeyframeSpacing(const std::vector<SurfaceKeyframe>& keyframes, size_t count) {
  const size_t n = std::min(count, keyframes.size());
  double sum = 0.0;
  for (size_t i = 1; i < n; ++i) sum += (keyframes[i].centre - keyframes[i - 1].centre).norm();
  return n > 1 ? sum / static_cast<double>(n - 1) : 0.0;
}

double MsPerKeyframe(const KeyframeStats& stats) {
  return stats.ms_total / static_cast<double>(std::max<size_t>(1, stats.keyframes));
}

std::string KeyframeStatsCsvHeader() {
  return "keyframe,batch,points_in,points_filtered,points_added,points_rejected,"
         "points_duplicate,steiner_added,rays_new,rays_old,cells_e,cells_n,o_left_in_e,cells_t,"
         "cells_f,cells_o,triangles,ms_steiner,ms_enclose,ms_shrink,ms_insert,ms_rays,ms_grow,"
         "ms_total,genus_free_before,genus_free_after,genus_groups,genus_euler_change,"
         "smoothed_vertices,smoothing_rejected,ms_genus,ms_smooth,rays_old_candidates,"
         "old_walk_cells,ms_rays_select,ms_rays_old,points_invalid,points_filtered_ground,"
         "points_filtered_length,points_filtered_aperture,enclose_rounds,cells_e_added,"
         "cells_active,smoothing_candidates,cells_grow_extra,old_ray_facets,"
         "old_ray_facets_uncrossed,old_ray_queries,old_ray_query_voxels,old_ray_facet_tests,"
         "old_ray_plane_passes,cells_enclosed_free,ms_enclosed_free,keyframes,points_merged";
}

std::string KeyframeStatsCsvRow(const KeyframeStats& s) {
  std::ostringstream o;
  o << s.keyframe.value << ',' << (s.batch ? 1 : 0) << ',' << s.points_in << ','
    << s.points_filtered << ',' << s.points_added << ',' << s.points_rejected << ','
    << s.points_duplicate << ',' << s.steiner_added << ',' << s.rays_new << ',' << s.rays_old << ','
    << s.cells_e << ',' << s.cells_n << ',' << s.o_left_in_e << ',' << s.cells_t << ',' << s.cells_f
    << ',' << s.cells_o << ',' << s.triangles << ',' << s.ms_steiner << ',' << s.ms_enclose << ','
    << s.ms_shrink << ',' << s.ms_insert << ',' << s.ms_rays << ',' << s.ms_grow << ','
    << s.ms_total << ',' << s.genus_free_before << ',' << s.genus_free_after << ','
    << s.genus_groups << ',' << s.genus_euler_change << ',' << s.smoothed_vertices << ','
    << s.smoothing_rejected << ',' << s.ms_genus << ',' << s.ms_smooth << ','
    << s.rays_old_candidates << ',' << s.old_walk_cells << ',' << s.ms_rays_select << ','
    << s.ms_rays_old << ',' << s.points_invalid << ',' << s.points_filtered_ground << ','
    << s.points_filtered_length << ',' << s.points_filtered_aperture << ',' << s.enclose_rounds
    << ',' << s.cells_e_added << ',' << s.cells_active << ',' << s.smoothing_candidates << ','
    << s.cells_grow_extra << ',' << s.old_ray_facets << ',' << s.old_ray_facets_uncrossed << ','
    << s.old_ray_queries << ',' << s.old_ray_query_voxels << ',' << s.old_ray_facet_tests << ','
    << s.old_ray_plane_passes << ',' << s.cells_enclosed_free << ',' << s.ms_enclosed_free << ','
    << s.keyframes << ',' << s.points_merged;
  return o.str();
}

namespace {

using Clock = std::chrono::steady_clock;
double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

using internal::CellQueue;

// The order of CellQueue (by ray counter, ties in push order) with one FIFO per counter value
// and a heap of the counters present: O(1) per cell where CellQueue sifts a heap of every cell
// (the shrink of the ball queues all of O ∩ E). Reused: empty between passes.
class CounterQueue {
 public:
  explicit CounterQueue(bool largest_first) : largest_first_(largest_first) {}
  void Push(CellHandle c) {
    const uint32_t k = c->info().counter;
    if (k >= buckets_.size()) buckets_.resize(static_cast<size_t>(k) + 1);
    Bucket& b = buckets_[k];
    if (b.head == b.cells.size()) {  // empty: its counter joins the heap
      b.cells.clear();
      b.head = 0;
      keys_.push_back(k);
      std::push_heap(keys_.begin(), keys_.end(), Less{largest_first_});
    }
    b.cells.push_back(c);
  }
  CellHandle Pop() {
    Bucket& b = buckets_[keys_.front()];
    const CellHandle c = b.cells[b.head++];
    if (b.head == b.cells.size()) {
      std::pop_heap(keys_.begin(), keys_.end(), Less{largest_first_});
      keys_.pop_back();
    }
    return c;
  }
  bool Empty() const { return keys_.empty(); }

 private:
  struct Bucket {
    std::vector<CellHandle> cells;
    size_t head = 0;
  };
  struct Less {  // heap order: the counter to pop first on top
    bool largest_first;
    bool operator()(uint32_t a, uint32_t b) const { return largest_first ? a < b : a > b; }
  };
  bool largest_first_;
  std::vector<Bucket> buckets_;
  std::vector<uint32_t> keys_;
};

struct PointRecord {
  PointId id;
  VertexHandle vertex;
  std::vector<Eigen::Vector3d> origins;
  uint32_t first_ray = 0;  // the rays of the point are first_ray, first_ray + 1, ... (ray ids)
  uint32_t n_stamp = 0;    // equal to the current stamp when the vertex is a vertex of N
  // The next record of the same vertex (a duplicate merged into it, SculptorOptions::
  // duplicate_rays), -1 for none: the vertex's info names the first.
  int next_of_vertex = -1;
};

struct KeyframeRecord {
  KeyframeId id;
  Eigen::Vector3d centre;
  std::vector<int> points;  // indices in Impl::points
};

struct RayTask {
  RayTask(VertexHandle v, const Point& p) : from(v), target(p) {}
  VertexHandle from;
  Point target;
  double stop = 2.0;  // the walk may stop once past this parameter along from→target
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

// The smallest cosine of the angle between two rays of p (1 with fewer than two rays), or the
// first one below stop_below: whether p passes the aperture filter, and when it does not, its
// aperture (the walk over every pair done once).
double MinRayCosine(const SurfacePoint& p, double stop_below) {
  double min_cos = 1.0;
  for (size_t i = 0; i < p.rays.size(); ++i) {
    const Eigen::Vector3d a = (p.rays[i].origin - p.position).normalized();
    for (size_t j = i + 1; j < p.rays.size(); ++j) {
      const Eigen::Vector3d b = (p.rays[j].origin - p.position).normalized();
      min_cos = std::min(min_cos, a.dot(b));
      if (min_cos < stop_below) return min_cos;
    }
  }
  return min_cos;
}

double MinApertureCosine(const SculptorOptions& options) {
  return std::cos(options.min_aperture_deg * M_PI / 180.0);
}

// Two rays of p more than min_aperture_deg apart (the aperture filter of §5.1).
bool WideAperture(const SculptorOptions& options, const SurfacePoint& p) {
  const double cos_min = MinApertureCosine(options);
  return MinRayCosine(p, cos_min) < cos_min;
}

// SculptorOptions::reach_quantile: the distance of the first keyframes' points with a wide
// aperture to their keyframe centre, at that quantile (0 when off or without such a point).
double MeasuredReach(const SculptorOptions& options, const std::vector<SurfaceKeyframe>& first) {
  if (options.reach_quantile == 0.0 || !options.filter_points) return 0.0;
  std::vector<double> distances;
  for (const SurfaceKeyframe& kf : first) {
    for (const SurfacePoint& p : kf.points) {
      if (p.position.allFinite() && WideAperture(options, p)) {
        distances.push_back((p.position - kf.centre).norm());
      }
    }
  }
  if (distances.empty()) return 0.0;
  const size_t k =
      std::min(distances.size() - 1,
               static_cast<size_t>(options.reach_quantile * static_cast<double>(distances.size())));
  std::nth_element(distances.begin(), distances.begin() + static_cast<long>(k), distances.end());
  return distances[k];
}

// s measured on the first keyframes (SculptorOptions::scale when given): their mean spacing or,
// when larger, the points' reach over max_ray_length_factor. 0 when they do not move.
double ScaleOfFirstKeyframes(const SculptorOptions& options,
                             const std::vector<SurfaceKeyframe>& first, double* spacing,
                             double* reach) {
  *spacing = 0.0;
  *reach = 0.0;
  if (options.scale != 0.0) return options.scale;
  *spacing = MeanKeyframeSpacing(first, first.size());
  *reach = MeasuredReach(options, first);
  if (*spacing > 0.0 && *reach > options.max_ray_length_factor * *spacing)
    return *reach / options.max_ray_length_factor;
  return *spacing;
}

}  // namespace

double MeasureScale(const SculptorOptions& options, const std::vector<SurfaceKeyframe>& keyframes,
                    double* spacing) {
  double measured_spacing = 0.0, reach = 0.0;
  if (!spacing) spacing = &measured_spacing;
  *spacing = 0.0;
  if (options.scale != 0.0) return options.scale;
  // As IncrementalSculptor: the keyframes in groups of init_keyframes until a group moves.
  const size_t group = static_cast<size_t>(std::max(1, options.init_keyframes));
  for (size_t begin = 0; begin < keyframes.size(); begin += group) {
    const std::vector<SurfaceKeyframe> first(
        keyframes.begin() + static_cast<long>(begin),
        keyframes.begin() + static_cast<long>(std::min(keyframes.size(), begin + group)));
    const double s = ScaleOfFirstKeyframes(options, first, spacing, &reach);
    if (s > 0.0) return s;
  }
  return 0.0;
}

struct IncrementalSculptor::Impl {
  // A segment of a ray: its origin and its end.
  using Segment = std::pair<Eigen::Vector3d, Eigen::Vector3d>;
  SculptorOptions options;
  DelaunayMesh mesh;
  DelaunayMesh::Impl& t;  // T and O bookkeeping
  std::vector<SurfaceKeyframe> buffered;
  // Keyframes after s is known, waiting for a step of keyframes_per_step.
  std::vector<SurfaceKeyframe> pending;
  double s = 0.0;           // scale of §5.1
  double spacing = 0.0;     // mean keyframe spacing of the first keyframes (s measured)
  double ground = 0.0;      // b of the ground filter
  double step = 0.0;        // Steiner grid step
  double r = 0.0, l = 0.0;  // §3.3 bounds
  Eigen::Vector3d grid_origin = Eigen::Vector3d::Zero();
  std::unordered_set<uint64_t> grid_done;  // materialised grid points
  std::vector<PointRecord> points;
  std::vector<KeyframeRecord> keyframes;
  uint32_t stamp = 0;  // processing index of the current keyframe (the creation date)
  std::vector<VertexHandle> new_vertices;  // inserted during the current keyframe
  std::vector<VertexHandle> touched;       // vertices of cells that changed side (SetInO)
  internal::SurfaceSmoother smoother;      // step 6: smoothed δO positions
  // SmoothingOptions::every_keyframe off: the vertices (by index, each once: pending_flag)
  // whose umbrella may have changed since the last smoothing, smoothed by SmoothPending when a
  // mesh is taken; the mutex makes the const extractions safe to call from several threads.
  std::vector<int> pending_smoothing;
  std::vector<uint8_t> pending_flag;
  IncrementalSculptor::DeferredSmoothing deferred_smoothing;
  std::mutex smoothing_mutex;
  // Old rays (§4.4): the point of each ray id, the rays traced so far in their voxels (ids
  // below num_registered_rays), and a per-ray scratch stamp.
  std::vector<uint32_t> ray_point;
  internal::RayGrid ray_grid;
  uint32_t num_registered_rays = 0;
  std::vector<uint32_t> ray_seen;
  // Scratch of step 4 kept between keyframes: the border of N (rebuilt each time), the points
  // that are vertices of N (indices in `points`, each once) and the candidate rays.
  std::unique_ptr<internal::NewCellBorder> old_ray_border;
  std::vector<int> n_points;
  std::vector<uint32_t> old_ray_candidates;
  // The several-at-once attempts (§4.5, §4.7) that failed in the current phase (the shrink or
  // the growth of one keyframe), by vertex index: the attempt at v fails again while the stars
  // it depended on are unchanged (VertexInfo::changed): that of v (the cells tried) and that of
  // the vertex whose general test failed (`witness`; none when v was off δO or had no cell to
  // try). `permanent`: the growth found a cell out of F in the star of v, which F keeps.
  struct FailedAttempt {
    uint64_t phase = 0;
    uint32_t epoch = 0, time = 0;
    VertexHandle witness;
    bool permanent = false;
  };
  std::vector<FailedAttempt> failed_attempts;
  uint64_t attempt_phase = 0;
  size_t single_tests_skipped = 0, attempts_skipped = 0;  // in the current keyframe
  CounterQueue shrink_queue{/*largest_first=*/false}, grow_queue{/*largest_first=*/true};

  explicit Impl(const SculptorOptions& o) : options(o), t(*mesh.impl()) {
    t.count_surface_vertices = !options.reference_manifold_tests;
  }

  // The star of v in CGAL's incident_cells order (the reference path calls CGAL).
  void Star(VertexHandle v, std::vector<CellHandle>& star) const {
    if (options.reference_manifold_tests) {
      t.tri.incident_cells(v, std::back_inserter(star));
    } else {
      t.IncidentCells(v, star);
    }
  }

  // SingleCellTest(c) with the memo of its last failure (CellInfo::single_test_failed): the
  // test reads only the side of the cells incident to the vertices of c (its facets' neighbours,
  // the stars of its vertices and the rings of its edges), so it fails again while none of them
  // changed side. An insertion never changes it either (§4.3: it destroys only cells out of O and
  // the new cells around a surviving vertex or edge are out of O too).
  bool SingleCellPasses(CellHandle c) {
    internal::CellInfo& info = c->info();
    if (!options.reference_manifold_tests && info.single_test_failed != 0) {
      const uint32_t failed = info.single_test_failed;
      bool unchanged = true;
      for (int i = 0; i < 4 && unchanged; ++i) unchanged = c->vertex(i)->info().changed <= failed;
      if (unchanged) {
        ++single_tests_skipped;
        return false;
      }
    }
    if (t.SingleCellTest(c)) return true;
    info.single_test_failed = t.change_clock;
    return false;
  }

  // A new phase of several-at-once attempts: the failures of the previous one are forgotten.
  void BeginAttemptPhase() { ++attempt_phase; }
  bool KnownToFail(VertexHandle v) {
    if (options.reference_manifold_tests) return false;
    const size_t index = static_cast<size_t>(v->info().index);
    if (index >= failed_attempts.size()) return false;
    const FailedAttempt& f = failed_attempts[index];
    if (f.phase != attempt_phase || f.epoch != t.change_epoch) return false;
    const bool fails =
        f.permanent || (v->info().changed <= f.time &&
                        (f.witness == VertexHandle() || f.witness->info().changed <= f.time));
    attempts_skipped += fails ? 1 : 0;
    return fails;
  }
  void RememberFailure(VertexHandle v, VertexHandle witness, bool permanent = false) {
    const size_t index = static_cast<size_t>(v->info().index);
    if (index >= failed_attempts.size()) failed_attempts.resize(t.vertices.size());
    FailedAttempt& f = failed_attempts[index];
    f.phase = attempt_phase;
    f.epoch = t.change_epoch;
    f.time = t.change_clock;
    f.witness = witness;
    f.permanent = permanent;
  }
  // Flips `cells` to side in_o for a several-at-once attempt; Undo flips them back and restores
  // the change stamps of their vertices (O is as before, so the memos of failures stay valid).
  struct TrialFlip {
    std::vector<std::pair<VertexHandle, uint32_t>> stamps;
  };
  void Flip(const std::vector<CellHandle>& cells, bool in_o, TrialFlip& trial) {
    trial.stamps.clear();
    for (const CellHandle& c : cells) {
      for (int i = 0; i < 4; ++i) {
        trial.stamps.emplace_back(c->vertex(i), c->vertex(i)->info().changed);
      }
    }
    for (const CellHandle& c : cells) t.SetInO(c, in_o);
  }
  void Undo(const std::vector<CellHandle>& cells, bool in_o, const TrialFlip& trial) {
    for (const CellHandle& c : cells) t.SetInO(c, !in_o);
    for (auto it = trial.stamps.rbegin(); it != trial.stamps.rend(); ++it) {
      it->first->info().changed = it->second;
    }
  }

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
    double reach = 0.0;
    s = ScaleOfFirstKeyframes(options, first, &spacing, &reach);
    if (options.scale == 0.0 && s > spacing)
      spdlog::info(
          "surface: s = {:.3f} from the points' reach {:.2f} (keyframe spacing {:.3f}; "
          "r = {:.1f} s)",
          s, reach, spacing, options.max_ray_length_factor);
    if (!(s > 0.0)) {
      spdlog::warn("surface: keyframe centres do not move (s = 0); nothing to sculpt");
      return;
    }
    step = options.steiner_step_factor * s;
    ray_grid = internal::RayGrid(options.ray_grid_step_factor * s);
    l = step * std::sqrt(3.0);
    r = options.max_ray_length_factor * s;
    ground = options.below_ground_factor * s;
    const double depth = MeasuredGroundDepth(first);
    if (depth + options.ground_margin_factor * s > ground) {
      ground = depth + options.ground_margin_factor * s;
      spdlog::info(
          "surface: the ground {:.2f} under the keyframes: points more than {:.2f} below "
          "them are filtered out ({:.1f} s)",
          depth, ground, ground / s);
    }
    // Shift the grid off round coordinates so that grid planes do not contain the (often
    // axis-aligned) points and centres of synthetic scenes.
    grid_origin = first.front().centre + step * Eigen::Vector3d(0.3183, 0.2718, 0.1414);
  }

  double MinApertureCosine() const { return omni::MinApertureCosine(options); }

  // SculptorOptions::uncertain_ray_margin_deg: the shortened rays of p (dropped by the aperture
  // filter, its rays' smallest cosine min_cos), appended to *segments as (origin, end).
  void AddUncertainRays(const SurfacePoint& p, double min_cos,
                        std::vector<Segment>* segments) const {
    if (options.uncertain_ray_margin_deg <= 0.0 || segments == nullptr) return;
    const double aperture = std::acos(std::clamp(min_cos, -1.0, 1.0));
    if (!(aperture > 0.0)) return;
    const double fraction = 1.0 - options.uncertain_ray_margin_deg * M_PI / 180.0 / aperture;
    if (!(fraction >= options.uncertain_ray_min_fraction)) return;
    for (const SurfaceRay& ray : p.rays) {
      if (!ray.origin.allFinite()) continue;
      segments->push_back({ray.origin, ray.origin + fraction * (p.position - ray.origin)});
    }
  }

  bool WideAperture(const SurfacePoint& p) const { return omni::WideAperture(options, p); }

  // SculptorOptions::ground_quantile: g, the depth of the ground under the first keyframes'
  // centres (0 when off, without a point with a wide aperture or when that height is not below).
  double MeasuredGroundDepth(const std::vector<SurfaceKeyframe>& first) const {
    if (options.ground_quantile == 0.0 || !options.filter_points) return 0.0;
    const Eigen::Vector3d up = options.up.normalized();
    std::vector<double> heights;
    for (const SurfaceKeyframe& kf : first) {
      for (const SurfacePoint& p : kf.points) {
        if (p.position.allFinite() && WideAperture(p)) {
          heights.push_back((p.position - kf.centre).dot(up));
        }
      }
    }
    if (heights.empty()) return 0.0;
    const size_t k = std::min(
        heights.size() - 1,
        static_cast<size_t>(options.ground_quantile * static_cast<double>(heights.size())));
    std::nth_element(heights.begin(), heights.begin() + static_cast<long>(k), heights.end());
    return std::max(0.0, -heights[k]);
  }

  // The §5.1 filters; returns the points kept.
  std::vector<const SurfacePoint*> Filter(const SurfaceKeyframe& kf, KeyframeStats& st,
                                          std::vector<Segment>* uncertain = nullptr) const {
    std::vector<const SurfacePoint*> kept;
    const Eigen::Vector3d up = options.up.normalized();
    const double cos_min = MinApertureCosine();
    double min_cos = 1.0;  // of the point the aperture filter looked at last
    // Each point is counted by the first filter that removes it.
    auto removed_by = [&](const SurfacePoint& p) -> size_t* {
      if (!p.position.allFinite() || p.rays.empty()) return &st.points_invalid;
      if (!options.filter_points) return nullptr;
      const Eigen::Vector3d d = p.position - kf.centre;
      if (d.dot(up) < -ground) return &st.points_filtered_ground;
      if (d.norm() > r) return &st.points_filtered_length;
      min_cos = MinRayCosine(p, cos_min);
      return min_cos < cos_min ? nullptr : &st.points_filtered_aperture;
    };
    for (const SurfacePoint& p : kf.points) {
      if (size_t* count = removed_by(p)) {
        ++*count;
        ++st.points_filtered;
        if (count == &st.points_filtered_aperture) AddUncertainRays(p, min_cos, uncertain);
      } else {
        kept.push_back(&p);
      }
    }
    return kept;
  }

  // Inserts p unless its conflict zone meets O (§4.3). Returns the new vertex, or a null handle
  // with *duplicate telling whether p is an existing vertex or closer than `separation` to one
  // (then *merged_into is that vertex) rather than rejected.
  VertexHandle InsertFree(const Point& p, double separation, CellHandle& hint, bool* duplicate,
                          VertexHandle* merged_into, KeyframeStats* verify_stats = nullptr) {
    *duplicate = false;
    *merged_into = VertexHandle();
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
      *merged_into = c->vertex(li);
      return VertexHandle();
    }
    if (separation > 0.0) {
      const VertexHandle nearest = t.tri.nearest_vertex(p, c);
      if (nearest != VertexHandle() && !t.tri.is_infinite(nearest) &&
          CGAL::squared_distance(nearest->point(), p) < separation * separation) {
        *duplicate = true;
        *merged_into = nearest;
        return VertexHandle();
      }
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
    if (options.verify_insertions && verify_stats) {
      for (auto k : t.tri.finite_cell_handles()) {
        if (k->info().in_o && t.tri.side_of_sphere(k, p, true) == CGAL::ON_BOUNDED_SIDE) {
          ++verify_stats->insertions_meeting_o;
          break;
        }
      }
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
      VertexHandle merged_into;
      const VertexHandle v =
          InsertFree(g, options.min_point_separation_factor * s, hint, &duplicate, &merged_into);
      if (v != VertexHandle()) {
        t.AddVertex(v, -1, true);
        ++added;
      }
    }
    return added;
  }

  // The cells in the balls of the keyframes' centres (CellsInBall), each once, in the order the
  // searches first met them (not by address: the order must not depend on the allocator).
  std::vector<CellHandle> CellsInBalls(const std::vector<const SurfaceKeyframe*>& group,
                                       double radius) {
    if (group.size() == 1) return CellsInBall(group.front()->centre, radius);
    std::vector<CellHandle> cells;
    std::unordered_set<const void*> seen;
    for (const SurfaceKeyframe* kf : group) {
      for (const CellHandle& c : CellsInBall(kf->centre, radius))
        if (seen.insert(&*c).second) cells.push_back(c);
    }
    return cells;
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
    const uint32_t mark = t.NewMark();
    start->info().mark = mark;
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
        if (nb->info().mark == mark) continue;
        nb->info().mark = mark;
        stack.push_back(nb);
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
      for (const CellHandle& k : zone) {
        k->info().d_stamp = stamp;
        add(k);
      }
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

  // kConflictZones: the cells of O within `rings` adjacency steps through O of the cells of O
  // left in D by the shrink join E (e_stamp). Returns the cells added to E.
  std::vector<CellHandle> WidenEnclosing(const std::vector<CellHandle>& e_cells, int rings) {
    std::vector<CellHandle> frontier, next, added;
    const uint32_t mark = t.NewMark();
    for (const CellHandle& c : e_cells) {
      if (c->info().in_o && c->info().d_stamp == stamp) {
        c->info().mark = mark;
        frontier.push_back(c);
      }
    }
    for (int ring = 0; ring < rings && !frontier.empty(); ++ring) {
      next.clear();
      for (const CellHandle& c : frontier) {
        for (int k = 0; k < 4; ++k) {
          const CellHandle nb = c->neighbor(k);
          if (!nb->info().in_o || nb->info().mark == mark) continue;
          nb->info().mark = mark;
          next.push_back(nb);
          if (nb->info().e_stamp != stamp) {
            nb->info().e_stamp = stamp;
            added.push_back(nb);
          }
        }
      }
      frontier.swap(next);
    }
    return added;
  }

  // kConflictZones, EnclosingWidening::kVertexStars: the cells of O incident to the vertices of
  // the cells of O left in D by the shrink join E (e_stamp), then, `vertex_rings` − 1 times,
  // those incident to the vertices of the cells added. A cell of O ∩ D that the shrink keeps has
  // all four vertices on δO and the star of one of them leaves E: the several-at-once shrink
  // (§4.7) can only clear such a vertex when its whole star of O is in E. Returns the cells added.
  std::vector<CellHandle> WidenByStars(const std::vector<CellHandle>& e_cells, int vertex_rings) {
    std::vector<CellHandle> added, star;
    std::vector<VertexHandle> frontier;
    for (const CellHandle& c : e_cells) {
      if (!(c->info().in_o && c->info().d_stamp == stamp)) continue;
      for (int i = 0; i < 4; ++i) frontier.push_back(c->vertex(i));
    }
    std::unordered_set<const void*> seen;
    std::vector<VertexHandle> next;
    for (int ring = 0; ring < vertex_rings && !frontier.empty(); ++ring) {
      next.clear();
      for (const VertexHandle& v : frontier) {
        if (t.tri.is_infinite(v) || !seen.insert(&*v).second) continue;
        star.clear();
        Star(v, star);
        for (const CellHandle& c : star) {
          if (!c->info().in_o) continue;
          if (ring + 1 < vertex_rings) {
            for (int k = 0; k < 4; ++k) next.push_back(c->vertex(k));
          }
          if (c->info().e_stamp == stamp) continue;
          c->info().e_stamp = stamp;
          added.push_back(c);
        }
      }
      frontier.swap(next);
    }
    return added;
  }

  // The cells where O may grow in this keyframe: E (what survived of it), N and the cells
  // crossed by new rays, found by a search from N and from the surviving cells of `seeds`.
  std::vector<CellHandle> ActiveCells(const std::vector<CellHandle>& n_cells,
                                      const std::vector<CellHandle>& seeds) {
    std::vector<CellHandle> active;
    const uint32_t mark = t.NewMark();
    auto first_visit = [mark](CellHandle c) {
      if (c->info().mark == mark) return false;
      c->info().mark = mark;
      return true;
    };
    std::vector<CellHandle> stack;
    for (const CellHandle& c : n_cells) {
      if (first_visit(c)) stack.push_back(c);
    }
    for (const CellHandle& c : seeds) {
      if (Active(c) && first_visit(c)) stack.push_back(c);
    }
    while (!stack.empty()) {
      const CellHandle c = stack.back();
      stack.pop_back();
      active.push_back(c);
      for (int i = 0; i < 4; ++i) {
        const CellHandle nb = c->neighbor(i);
        if (Active(nb) && first_visit(nb)) stack.push_back(nb);
      }
    }
    return active;
  }

  // kConflictZones: the growth region E ∪ N ∪ (cells crossed by new rays) holds every cell whose
  // counter changed, but a cell of F \ O outside it that the addition test refused earlier can
  // pass once O changed around its vertices (the ball mode retries it in every keyframe whose
  // ball holds it). So the cells of F \ O in the stars of the vertices whose umbrella changed in
  // this keyframe (the shrink and the growth, recorded by SetInO in `touched`) join the region
  // (e_stamp) and grow, as long as that makes new changes (at most grow_closure_rounds times).
  // Appends them to `active` (step 6 works on them too).
  void GrowAroundChanges(std::vector<CellHandle>& active, KeyframeStats& st) {
    std::vector<CellHandle> star, extra;
    size_t scanned = 0;
    for (int round = 0; round < options.grow_closure_rounds; ++round) {
      extra.clear();
      for (; scanned < touched.size(); ++scanned) {
        star.clear();
        Star(touched[scanned], star);
        for (const CellHandle& c : star) {
          const internal::CellInfo& i = c->info();
          if (i.in_o || i.counter == 0 || Active(c)) continue;
          c->info().e_stamp = stamp;
          extra.push_back(c);
        }
      }
      if (extra.empty()) break;
      st.cells_grow_extra += extra.size();
      active.insert(active.end(), extra.begin(), extra.end());
      Grow(extra);
    }
  }

  // ---- Shrinking (§4.2, §4.7) ----
  void ShrinkOneAtOnce(const std::vector<CellHandle>& seeds) {
    if (options.reference_manifold_tests) {
      CellQueue q(/*largest_first=*/false);
      ShrinkOneAtOnce(seeds, q);
    } else {
      ShrinkOneAtOnce(seeds, shrink_queue);
    }
  }
  template <typename Queue>
  void ShrinkOneAtOnce(const std::vector<CellHandle>& seeds, Queue& q) {
    for (const CellHandle& c : seeds) {
      if (c->info().in_o && c->info().e_stamp == stamp) q.Push(c);
    }
    while (!q.Empty()) {
      const CellHandle c = q.Pop();
      if (!c->info().in_o || !HasSurfaceFacet(c)) continue;
      if (!SingleCellPasses(c)) continue;
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

  // The general test at every vertex of vs; on failure *witness is the first that failed.
  bool GeneralTestAll(const std::vector<VertexHandle>& vs, VertexHandle* witness) const {
    for (const VertexHandle& v : vs) {
      if (!t.GeneralTest(v)) {
        *witness = v;
        return false;
      }
    }
    return true;
  }

  // only_d: the several-at-once passes try only the vertices of the cells of O in a conflict
  // zone D (kConflictZones needs O ∩ D = ∅, not O ∩ E = ∅; E is where cells may leave O).
  void Shrink(const std::vector<CellHandle>& e_cells, bool only_d = false) {
    ShrinkOneAtOnce(e_cells);
    std::vector<CellHandle> star, left, removed, next;
    TrialFlip trial;
    for (int pass = 0; pass < options.max_vertex_passes; ++pass) {
      left.clear();
      for (const CellHandle& c : e_cells) {
        if (c->info().in_o && (!only_d || c->info().d_stamp == stamp)) left.push_back(c);
      }
      if (left.empty()) return;
      bool progress = false;
      for (const VertexHandle& v : VerticesOf(left)) {
        // An attempt that failed in this step fails again while its stars are unchanged (the
        // cells joining E on widening stamp their vertices as changed).
        if (KnownToFail(v)) continue;
        if (!t.VertexOnSurface(v)) {
          RememberFailure(v, VertexHandle());
          continue;
        }
        star.clear();
        Star(v, star);
        removed.clear();
        for (const CellHandle& c : star) {
          if (c->info().in_o && c->info().e_stamp == stamp) removed.push_back(c);
        }
        if (removed.empty()) {
          RememberFailure(v, VertexHandle());
          continue;
        }
        Flip(removed, false, trial);
        VertexHandle witness;
        if (GeneralTestAll(VerticesOf(removed), &witness)) {
          progress = true;
          next.clear();
          for (const CellHandle& c : removed) {
            for (int i = 0; i < 4; ++i) next.push_back(c->neighbor(i));
          }
          ShrinkOneAtOnce(next);
        } else {
          Undo(removed, false, trial);
          RememberFailure(v, witness);
        }
      }
      if (!progress) return;
    }
  }

  // ---- Growing (§4.5) ----
  void GrowOneAtOnce(const std::vector<CellHandle>& seeds, bool allow_isolated_seed) {
    if (options.reference_manifold_tests) {
      CellQueue q(/*largest_first=*/true);
      GrowOneAtOnce(seeds, allow_isolated_seed, q);
    } else {
      GrowOneAtOnce(seeds, allow_isolated_seed, grow_queue);
    }
  }
  template <typename Queue>
  void GrowOneAtOnce(const std::vector<CellHandle>& seeds, bool allow_isolated_seed, Queue& q) {
    for (const CellHandle& c : seeds) {
      if (!c->info().in_o && c->info().counter > 0 && !t.tri.is_infinite(c)) q.Push(c);
    }
    while (!q.Empty()) {
      const CellHandle c = q.Pop();
      if (c->info().in_o) continue;
      if (!HasSurfaceFacet(c) && !allow_isolated_seed) continue;
      if (!SingleCellPasses(c)) continue;
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
    std::vector<CellHandle> star, free, added, next;
    TrialFlip trial;
    for (int pass = 0; pass < options.max_vertex_passes; ++pass) {
      bool progress = false;
      // Only a vertex of a cell of F \ O can have cells to add, and F does not change while O
      // grows: the vertices of the other active cells would all be skipped below.
      free.clear();
      for (const CellHandle& c : active) {
        if (!c->info().in_o && c->info().counter > 0) free.push_back(c);
      }
      for (const VertexHandle& v : VerticesOf(free)) {
        // F is fixed during the growth: an attempt that failed in this step fails again while
        // its stars are unchanged, and always when the star of v leaves F.
        if (KnownToFail(v)) continue;
        if (!t.VertexOnSurface(v)) {
          RememberFailure(v, VertexHandle());
          continue;
        }
        star.clear();
        Star(v, star);
        added.clear();
        bool all_free = true;
        for (const CellHandle& c : star) {
          if (t.tri.is_infinite(c) || c->info().counter == 0) {
            all_free = false;
            break;
          }
          if (!c->info().in_o) added.push_back(c);
        }
        if (!all_free || added.empty()) {
          RememberFailure(v, VertexHandle(), /*permanent=*/!all_free);
          continue;
        }
        Flip(added, true, trial);
        VertexHandle witness;
        if (GeneralTestAll(VerticesOf(added), &witness)) {
          progress = true;
          next.clear();
          for (const CellHandle& c : added) {
            for (int i = 0; i < 4; ++i) next.push_back(c->neighbor(i));
          }
          GrowOneAtOnce(next, false);
        } else {
          Undo(added, true, trial);
          RememberFailure(v, witness);
        }
      }
      if (!progress) return;
    }
  }

  // ---- Ray tracing (§4.4) ----
  // Traces the tasks in parallel; only_new: increment only the cells created in this keyframe.
  // Returns the number of cells the walks visited.
  size_t Trace(const std::vector<RayTask>& tasks, bool only_new) {
    std::atomic<size_t> became_free{0}, visited{0};
    const uint32_t date = stamp;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, tasks.size(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                        size_t local = 0, cells = 0;
                        auto visit = [&](CellHandle c) {
                          ++cells;
                          if (only_new && c->info().date != date) return;
                          if (!only_new)
                            __atomic_store_n(&c->info().ray_stamp, date, __ATOMIC_RELAXED);
                          if (__atomic_fetch_add(&c->info().counter, 1u, __ATOMIC_RELAXED) == 0) {
                            ++local;
                          }
                        };
                        for (size_t i = range.begin(); i != range.end(); ++i) {
                          const RayTask& task = tasks[i];
                          t.Walk(task.from, task.target, task.stop, visit);
                        }
                        became_free += local;
                        visited += cells;
                      });
    t.num_f += became_free;
    return visited;
  }

  // Walks each segment from its origin to its end (located in T from `hint` on, then
  // WalkFromInside), incrementing the counters of the cells it crosses (as Trace). Returns the
  // number of cells the walks visited.
  size_t TraceSegments(const std::vector<Segment>& segments, CellHandle hint) {
    if (segments.empty() || t.tri.dimension() < 3) return 0;
    std::vector<CellHandle> starts(segments.size());
    for (size_t i = 0; i < segments.size(); ++i) {
      starts[i] = t.tri.locate(ToCgal(segments[i].first), hint);
      hint = starts[i];
    }
    std::atomic<size_t> became_free{0}, visited{0};
    const uint32_t date = stamp;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, segments.size(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                        size_t local = 0, cells = 0;
                        auto visit = [&](CellHandle c) {
                          ++cells;
                          __atomic_store_n(&c->info().ray_stamp, date, __ATOMIC_RELAXED);
                          if (__atomic_fetch_add(&c->info().counter, 1u, __ATOMIC_RELAXED) == 0) {
                            ++local;
                          }
                        };
                        for (size_t i = range.begin(); i != range.end(); ++i) {
                          t.WalkFromInside(ToCgal(segments[i].first), ToCgal(segments[i].second),
                                           starts[i], 2.0, visit);
                        }
                        became_free += local;
                        visited += cells;
                      });
    t.num_f += became_free;
    return visited;
  }

  // SurfaceKeyframe::free_rays: each walked from its origin up to free_ray_length_factor · r.
  void TraceFreeRays(const SurfaceKeyframe& kf, KeyframeStats& st) {
    if (kf.free_rays.empty() || options.free_ray_length_factor == 0.0) return;
    const double length = options.free_ray_length_factor * r;
    std::vector<Segment> segments;
    segments.reserve(kf.free_rays.size());
    for (const SurfaceFreeRay& ray : kf.free_rays) {
      if (!ray.origin.allFinite() || !ray.direction.allFinite() || !(ray.direction.norm() > 0.0))
        continue;
      segments.push_back({ray.origin, ray.origin + length * ray.direction.normalized()});
    }
    st.free_ray_cells += TraceSegments(segments, t.tri.locate(ToCgal(kf.centre)));
    st.rays_free += kf.free_rays.size();
  }

  // SculptorOptions::uncertain_ray_margin_deg: the shortened rays of the points the aperture
  // filter dropped.
  void TraceUncertainRays(const std::vector<Segment>& segments, KeyframeStats& st) {
    st.uncertain_ray_cells += TraceSegments(segments, CellHandle());
    st.rays_uncertain += segments.size();
  }

  // Puts the rays of the keyframe's points (traced) in the ray grid.
  void RegisterRays(const KeyframeRecord& kf) {
    for (int i : kf.points) {
      const PointRecord& p = points[i];
      const Eigen::Vector3d a = ToEigen(p.vertex->point());
      for (size_t k = 0; k < p.origins.size(); ++k) {
        ray_grid.Add(p.first_ray + static_cast<uint32_t>(k), a, p.origins[k]);
      }
      num_registered_rays = std::max<uint32_t>(
          num_registered_rays, p.first_ray + static_cast<uint32_t>(p.origins.size()));
    }
  }

  // Step 4 (§4.4): traces the new rays fully and re-traces the old rays (those in the ray grid)
  // over the new cells N (see surface/internal/old_rays.h), incrementing only the counters of N
  // cells. The border of N is collected before any new ray is traced (it leaves out the facets
  // that no old ray crossed into, by the counters the old rays left); its voxel index and the
  // candidate old rays are made while the new rays are traced (they read no counter), then the
  // candidates are walked while the keyframe's rays join the ray grid (RegisterRays: the walks
  // do not read it).
  void TraceRays(const std::vector<RayTask>& new_rays, const std::vector<CellHandle>& n_cells,
                 const std::vector<KeyframeRecord>& recs, KeyframeStats& st) {
    const bool old_rays = !n_cells.empty() && num_registered_rays > 0;
    if (old_rays) CollectOldRayBorder(n_cells, st);
    tbb::task_group side;
    if (old_rays) side.run([&] { SelectOldRays(st); });
    Trace(new_rays, false);
    side.wait();
    side.run([&] {
      for (const KeyframeRecord& rec : recs) RegisterRays(rec);
    });
    if (old_rays) WalkOldRays(st);
    side.wait();
  }

  // The points that are vertices of N (n_points, stamped n_stamp), and the border of N
  // (NewCellBorder::Collect).
  void CollectOldRayBorder(const std::vector<CellHandle>& n_cells, KeyframeStats& st) {
    const uint32_t date = stamp;
    n_points.clear();
    for (const CellHandle& c : n_cells) {
      for (int i = 0; i < 4; ++i) {
        const VertexHandle v = c->vertex(i);
        if (t.tri.is_infinite(v) || v->info().point < 0) continue;
        if (points[v->info().point].n_stamp == date) continue;
        for (int record = v->info().point; record >= 0; record = points[record].next_of_vertex) {
          points[record].n_stamp = date;
          n_points.push_back(record);
        }
      }
    }
    if (options.old_rays == OldRayTracing::kAllRays) return;
    if (!old_ray_border) {
      old_ray_border = std::make_unique<internal::NewCellBorder>(t.tri, ray_grid.grid());
    }
    old_ray_border->Collect(n_cells, date, /*only_crossed=*/true);
    st.old_ray_facets = old_ray_border->NumFacets();
    st.old_ray_facets_uncrossed = old_ray_border->NumUncrossed();
  }

  // The candidate old rays (old_ray_candidates): those registered in the voxels that the border
  // of N touches and those of the points that are vertices of N (every old ray with kAllRays).
  void SelectOldRays(KeyframeStats& st) {
    const auto tick = Clock::now();
    const uint32_t date = stamp;
    std::vector<uint32_t>& candidates = old_ray_candidates;
    candidates.clear();
    if (options.old_rays == OldRayTracing::kAllRays) {
      candidates.resize(num_registered_rays);
      for (uint32_t id = 0; id < num_registered_rays; ++id) candidates[id] = id;
    } else {
      internal::NewCellBorder* border = old_ray_border.get();
      border->Index();
      ray_seen.resize(num_registered_rays, 0);
      auto add = [&](uint32_t id) {
        if (id < num_registered_rays && ray_seen[id] != date) {
          ray_seen[id] = date;
          candidates.push_back(id);
        }
      };
      // Rays that may cross the border of N, and rays starting at a vertex of N.
      for (uint64_t key : border->voxels()) {
        if (const std::vector<uint32_t>* rays = ray_grid.RaysIn(key)) {
          for (uint32_t id : *rays) add(id);
        }
      }
      for (int i : n_points) {
        const PointRecord& p = points[i];
        for (size_t k = 0; k < p.origins.size(); ++k) add(p.first_ray + static_cast<uint32_t>(k));
      }
      std::sort(candidates.begin(), candidates.end());  // rays of nearby points together
    }
    st.rays_old_candidates = candidates.size();
    st.ms_rays_select = MsSince(tick);
  }

  // Walks the candidate old rays over N.
  void WalkOldRays(KeyframeStats& st) {
    const uint32_t date = stamp;
    const std::vector<uint32_t>& candidates = old_ray_candidates;
    const internal::NewCellBorder* border =
        options.old_rays == OldRayTracing::kAllRays ? nullptr : old_ray_border.get();
    const auto walk_tick = Clock::now();
    const bool runs = options.old_rays == OldRayTracing::kNewCellRuns;
    std::atomic<size_t> became_free{0}, visited{0}, traced{0};
    std::mutex work_mutex;
    internal::EntriesWork work;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, candidates.size(), 64),
                      [&](const tbb::blocked_range<size_t>& range) {
                        size_t local_free = 0, cells = 0, rays = 0;
                        auto increment = [&](CellHandle c) {
                          if (__atomic_fetch_add(&c->info().counter, 1u, __ATOMIC_RELAXED) == 0)
                            ++local_free;
                        };
                        // Whole walks count the N cells; runs end at the first cell out of N.
                        auto count_new = [&](CellHandle c) {
                          ++cells;
                          if (c->info().date == date) increment(c);
                        };
                        auto run = [&](CellHandle c) {
                          ++cells;
                          if (c->info().date != date) return false;
                          increment(c);
                          return true;
                        };
                        std::vector<internal::CellFacet> entries;
                        internal::EntriesWork local_work;
                        for (size_t i = range.begin(); i != range.end(); ++i) {
                          const uint32_t id = candidates[i];
                          const PointRecord& p = points[ray_point[id]];
                          const Point target = ToCgal(p.origins[id - p.first_ray]);
                          if (runs && border->Entries(p.vertex, target, &entries, &local_work)) {
                            const bool starts_in_n = p.n_stamp == date;
                            if (starts_in_n) t.Walk(p.vertex, target, 2.0, run);
                            for (const internal::CellFacet& e : entries) {
                              t.WalkFrom(p.vertex->point(), target, e.first, e.second, 2.0, run);
                            }
                            rays += starts_in_n || !entries.empty() ? 1 : 0;
                          } else {
                            t.Walk(p.vertex, target, 2.0, count_new);
                            ++rays;
                          }
                        }
                        became_free += local_free;
                        visited += cells;
                        traced += rays;
                        const std::lock_guard<std::mutex> lock(work_mutex);
                        work += local_work;
                      });
    t.num_f += became_free;
    st.old_ray_queries = work.queries;
    st.old_ray_query_voxels = work.voxels;
    st.old_ray_facet_tests = work.facets;
    st.old_ray_plane_passes = work.plane_passes;
    st.rays_old = traced;
    st.old_walk_cells = visited;
    st.ms_rays_old = MsSince(walk_tick);
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
    st.single_tests_skipped = single_tests_skipped;
    st.attempts_skipped = attempts_skipped;
    // The finite cells: all of them but the star of the infinite vertex (CGAL's
    // number_of_finite_cells walks every cell).
    if (t.tri.dimension() == 3) {
      thread_local std::vector<CellHandle> hull;
      hull.clear();
      t.IncidentCells(t.tri.infinite_vertex(), hull);
      st.cells_t = t.tri.number_of_cells() - hull.size();
    } else {
      st.cells_t = t.tri.number_of_finite_cells();
    }
    st.cells_f = t.num_f;
    st.cells_o = t.num_o;
    st.triangles = t.num_triangles;
  }

  // SculptorOptions::enclosed_free_neighbours: the cells out of F among `cells` and their
  // neighbours with that many neighbours in F join F. Returns how many.
  size_t FreeEnclosedCells(const std::vector<CellHandle>& cells) {
    if (options.enclosed_free_neighbours <= 0) return 0;
    std::vector<CellHandle> candidates, joined, frontier = cells;
    size_t total = 0;
    for (int round = 0; round < options.enclosed_free_rounds && !frontier.empty(); ++round) {
      const uint32_t mark = t.NewMark();
      candidates.clear();
      auto consider = [&](CellHandle c) {
        if (c->info().mark == mark || t.tri.is_infinite(c) || c->info().counter > 0) return;
        c->info().mark = mark;
        candidates.push_back(c);
      };
      for (const CellHandle& c : frontier) {
        consider(c);
        for (int i = 0; i < 4; ++i) consider(c->neighbor(i));
      }
      joined.clear();
      for (const CellHandle& c : candidates) {
        int free = 0;
        for (int i = 0; i < 4; ++i) {
          const CellHandle nb = c->neighbor(i);
          free += !t.tri.is_infinite(nb) && nb->info().counter > 0 ? 1 : 0;
        }
        if (free >= options.enclosed_free_neighbours) joined.push_back(c);
      }
      // Decided on the counters before the round's changes: the result does not depend on the
      // order of the cells.
      for (const CellHandle& c : joined) c->info().counter = 1;
      t.num_f += joined.size();
      total += joined.size();
      frontier = joined;
    }
    return total;
  }

  // v: a vertex just inserted for p, or the vertex p was merged into (its rays are then traced
  // from v, the record chained after v's others).
  int AddPoint(const SurfacePoint& p, VertexHandle v, KeyframeRecord& kf) {
    v = t.AddVertex(v, static_cast<int32_t>(points.size()), false);
    if (v->info().point != static_cast<int32_t>(points.size())) {
      int last = v->info().point;
      while (points[last].next_of_vertex >= 0) last = points[last].next_of_vertex;
      points[last].next_of_vertex = static_cast<int>(points.size());
    }
    PointRecord rec;
    rec.id = p.id;
    rec.vertex = v;
    rec.first_ray = static_cast<uint32_t>(ray_point.size());
    for (const SurfaceRay& ray : p.rays) {
      rec.origins.push_back(ray.origin);
      ray_point.push_back(static_cast<uint32_t>(points.size()));
    }
    points.push_back(std::move(rec));
    kf.points.push_back(static_cast<int>(points.size()) - 1);
    return kf.points.back();
  }

  // The distance under which p is a vertex already (SculptorOptions::min_point_separation_*).
  double Separation(const SurfacePoint& p) const {
    double separation = options.min_point_separation_factor * s;
    if (options.min_point_separation_pixels > 0.0 && options.pixel_angle > 0.0) {
      double nearest = std::numeric_limits<double>::infinity();
      for (const SurfaceRay& ray : p.rays)
        nearest = std::min(nearest, (ray.origin - p.position).norm());
      if (std::isfinite(nearest)) {
        separation = std::max(separation,
                              options.min_point_separation_pixels * options.pixel_angle * nearest);
      }
    }
    return separation;
  }

  // A duplicate point's rays, from the vertex it was merged into (SculptorOptions::
  // duplicate_rays), when that vertex holds a point (not a Steiner vertex).
  void AddMergedPoint(const SurfacePoint& p, VertexHandle merged_into, KeyframeRecord& kf,
                      KeyframeStats& st) {
    if (!options.duplicate_rays || merged_into == VertexHandle() ||
        t.tri.is_infinite(merged_into) || merged_into->info().point < 0) {
      return;
    }
    AddPoint(p, merged_into, kf);
    ++st.points_merged;
  }

  // ---- One keyframe, paper §4 steps 1–6 ----
  // Steps 1-6 for one keyframe, or for several at once (SculptorOptions::keyframes_per_step):
  // their points are inserted together and their rays traced once, after all the insertions,
  // so the rays of a keyframe of the group are not re-traced over the new cells of the next.
  KeyframeStats Incremental(const std::vector<const SurfaceKeyframe*>& group) {
    const auto start = Clock::now();
    ++stamp;
    new_vertices.clear();
    touched.clear();
    t.touched = &touched;
    t.touch_stamp = stamp;
    KeyframeStats st;
    st.keyframe = group.back()->id;
    st.keyframes = group.size();
    single_tests_skipped = attempts_skipped = 0;
    std::vector<std::vector<const SurfacePoint*>> kept_of(group.size());
    std::vector<Segment> uncertain;
    for (size_t g = 0; g < group.size(); ++g) {
      st.points_in += group[g]->points.size();
      kept_of[g] = Filter(*group[g], st, &uncertain);
    }

    auto tick = Clock::now();
    for (const SurfaceKeyframe* kf : group) st.steiner_added += MaterialiseGrid(kf->centre);
    t.UpdateDegrees(new_vertices);  // the stars the manifold tests count (VertexOnSurface)
    st.ms_steiner = MsSince(tick);

    // Step 1: E = cells in B_{r+l}(c_{t+1}), or the conflict zones of the points plus a margin.
    tick = Clock::now();
    std::vector<Point> kept_points;
    for (const auto& kept : kept_of)
      for (const SurfacePoint* p : kept) kept_points.push_back(ToCgal(p->position));
    const std::vector<CellHandle> e_cells =
        options.enclosing == EnclosingMode::kBall
            ? CellsInBalls(group, r + l)
            : CellsInConflictZones(kept_points, options.enclosing_margin);
    st.cells_e = e_cells.size();
    st.ms_enclose = MsSince(tick);

    // Step 2: shrink O out of E; with the conflict zones, widen E where O still meets D and
    // shrink again.
    tick = Clock::now();
    std::vector<CellHandle> e_all = e_cells;
    BeginAttemptPhase();
    const bool only_d =
        options.enclosing == EnclosingMode::kConflictZones && options.targeted_shrink;
    Shrink(e_all, only_d);
    if (options.enclosing == EnclosingMode::kConflictZones) {
      // D is computed in T before any insertion, so it over-covers the zones met at insertion
      // time (an insertion removes cells that later points conflicted with), and a round may
      // leave as many cells of O in D as the one before and the next one still remove them
      // (stopping there doubled the rejected share on the street test): all rounds run while
      // O meets D.
      auto o_in_d = [&] {
        size_t n = 0;
        for (const CellHandle& c : e_all) n += c->info().in_o && c->info().d_stamp == stamp;
        return n;
      };
      size_t left = o_in_d();
      for (int round = 0; round < options.enclosing_rounds && left > 0; ++round) {
        // The first rings may all be in E already (the margin): then the next round reaches
        // farther.
        const std::vector<CellHandle> added =
            options.enclosing_widening == EnclosingWidening::kVertexStars
                ? WidenByStars(e_all, options.enclosing_star_rings + round)
                : WidenEnclosing(
                      e_all, options.enclosing_margin + (options.enclosing_round_rings << round));
        ++st.enclose_rounds;
        if (added.empty()) continue;
        st.cells_e_added += added.size();
        // The stars of their vertices changed for the shrink (more cells of E to remove).
        const uint32_t now = t.NextChange();
        for (const CellHandle& c : added) {
          for (int i = 0; i < 4; ++i) c->vertex(i)->info().changed = now;
        }
        e_all.insert(e_all.end(), added.begin(), added.end());
        Shrink(e_all, only_d);
        left = o_in_d();
      }
      // The targeted passes may leave O in D where clearing other vertices of E first would
      // unblock it: a last shrink over the vertices of all of O ∩ E before points are rejected.
      if (only_d && left > 0 && options.enclosing_rounds > 0) Shrink(e_all, false);
    }
    for (const CellHandle& c : e_all) st.o_left_in_e += c->info().in_o ? 1 : 0;
    st.cells_e = e_all.size();
    // The cells of E out of every conflict zone survive the insertions (a cell is destroyed by
    // a point only if the point is in its circumsphere, i.e. the cell is in that point's D).
    std::vector<CellHandle> surviving;
    if (options.enclosing == EnclosingMode::kConflictZones) {
      for (const CellHandle& c : e_all) {
        if (c->info().d_stamp != stamp) surviving.push_back(c);
      }
    }
    st.ms_shrink = MsSince(tick);

    // Step 3: insert the points whose conflict zone misses O.
    tick = Clock::now();
    std::vector<KeyframeRecord> recs(group.size());
    for (size_t g = 0; g < group.size(); ++g) {
      KeyframeRecord& rec = recs[g];
      rec.id = group[g]->id;
      rec.centre = group[g]->centre;
      const auto sorted = SpatiallySorted(kept_of[g]);
      CellHandle hint = t.tri.locate(ToCgal(group[g]->centre));
      for (const auto& [pt, p] : sorted) {
        bool duplicate;
        VertexHandle merged_into;
        const VertexHandle v = InsertFree(pt, Separation(*p), hint, &duplicate, &merged_into, &st);
        if (v == VertexHandle()) {
          ++(duplicate ? st.points_duplicate : st.points_rejected);
          if (duplicate) AddMergedPoint(*p, merged_into, rec, st);
          continue;
        }
        AddPoint(*p, v, rec);
        ++st.points_added;
      }
    }
    t.UpdateDegrees(new_vertices);  // the stars the manifold tests count (VertexOnSurface)
    const std::vector<CellHandle> n_cells = NewCells();
    st.cells_n = n_cells.size();
    st.ms_insert = MsSince(tick);

    // Step 4: new rays fully, old rays over N.
    tick = Clock::now();
    std::vector<RayTask> tasks;
    for (const KeyframeRecord& rec : recs)
      for (int i : rec.points) {
        for (const Eigen::Vector3d& o : points[i].origins)
          tasks.emplace_back(points[i].vertex, ToCgal(o));
      }
    st.rays_new = tasks.size();
    TraceRays(tasks, n_cells, recs, st);
    for (const SurfaceKeyframe* kf : group) TraceFreeRays(*kf, st);
    TraceUncertainRays(uncertain, st);
    for (KeyframeRecord& rec : recs) keyframes.push_back(std::move(rec));
    st.ms_rays = MsSince(tick);

    // Step 5: grow O in F, within E (recomputed: insertion replaced cells) and N.
    tick = Clock::now();
    if (options.enclosing == EnclosingMode::kBall) surviving = CellsInBalls(group, r + l);
    std::vector<CellHandle> active = ActiveCells(n_cells, surviving);
    const auto enclosed_tick = Clock::now();
    st.cells_enclosed_free = FreeEnclosedCells(active);
    st.ms_enclosed_free = MsSince(enclosed_tick);
    BeginAttemptPhase();
    Grow(active);
    if (options.enclosing == EnclosingMode::kConflictZones) GrowAroundChanges(active, st);
    st.cells_active = active.size();
    st.ms_grow = MsSince(tick);

    // Step 6 on the δO vertices whose umbrella may have changed: those of the cells that
    // changed side (recorded by SetInO) and those of N (their stars changed).
    for (const CellHandle& c : n_cells) {
      for (int i = 0; i < 4; ++i) {
        const VertexHandle v = c->vertex(i);
        if (t.tri.is_infinite(v) || v->info().touched == stamp) continue;
        v->info().touched = stamp;
        touched.push_back(v);
      }
    }
    // The smoothing's ball (when it runs every keyframe): around the last centre, reaching the
    // others' balls too.
    double reach = r + l;
    for (const SurfaceKeyframe* kf : group)
      reach = std::max(reach, (kf->centre - group.back()->centre).norm() + r + l);
    PostProcess(active, &touched, group.back()->centre, reach, st);  // step 6
    t.touched = nullptr;

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
    st.keyframes = kfs.size();
    single_tests_skipped = attempts_skipped = 0;
    st.keyframe = kfs.back().id;
    auto tick = Clock::now();
    for (const SurfaceKeyframe& kf : kfs) st.steiner_added += MaterialiseGrid(kf.centre);
    st.ms_steiner = MsSince(tick);
    tick = Clock::now();
    std::vector<Segment> uncertain;
    for (const SurfaceKeyframe& kf : kfs) {
      st.points_in += kf.points.size();
      KeyframeRecord rec;
      rec.id = kf.id;
      rec.centre = kf.centre;
      const auto kept = Filter(kf, st, &uncertain);
      const auto sorted = SpatiallySorted(kept);
      CellHandle hint = t.tri.locate(ToCgal(kf.centre));
      for (const auto& [pt, p] : sorted) {
        bool duplicate;
        VertexHandle merged_into;  // O is empty: never rejected
        const VertexHandle v = InsertFree(pt, Separation(*p), hint, &duplicate, &merged_into);
        if (v == VertexHandle()) {
          ++(duplicate ? st.points_duplicate : st.points_rejected);
          if (duplicate) AddMergedPoint(*p, merged_into, rec, st);
          continue;
        }
        AddPoint(*p, v, rec);
        ++st.points_added;
      }
      keyframes.push_back(std::move(rec));
    }
    t.UpdateDegrees(new_vertices);
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
    for (const SurfaceKeyframe& kf : kfs) TraceFreeRays(kf, st);
    TraceUncertainRays(uncertain, st);
    for (const KeyframeRecord& kf : keyframes) RegisterRays(kf);
    st.ms_rays = MsSince(tick);
    tick = Clock::now();
    const auto enclosed_tick = Clock::now();
    st.cells_enclosed_free = FreeEnclosedCells(all);
    st.ms_enclosed_free = MsSince(enclosed_tick);
    BeginAttemptPhase();
    Grow(all);
    st.ms_grow = MsSince(tick);
    PostProcess(all, nullptr, kfs.back().centre, std::numeric_limits<double>::infinity(),
                st);  // step 6
    FinishStats(st);
    st.ms_total = MsSince(start);
    return st;
  }

  // ---- Step 6 (§4.6): genus refinement and smoothing, in surface/genus_refinement.cpp and
  // surface/smoothing.cpp ----
  // `vertices`: the vertices whose δO umbrella may have changed (nullptr: those of `active`).
  void PostProcess(const std::vector<CellHandle>& active, std::vector<VertexHandle>* vertices,
                   const Eigen::Vector3d& centre, double radius, KeyframeStats& st) {
    auto tick = Clock::now();
    const internal::GenusRefinementResult genus = internal::RefineGenus(
        t, active, [this](CellHandle c) { return Active(c); }, options.genus);
    st.genus_free_before = genus.free_before;
    st.genus_free_after = genus.free_after;
    st.genus_groups = genus.groups;
    st.genus_euler_change = genus.euler_change;
    st.ms_genus = MsSince(tick);
    if (!options.smoothing.enabled) return;
    if (!options.smoothing.every_keyframe) {
      DeferSmoothing(active, vertices);
      st.smoothing_candidates = pending_smoothing.size();
      return;
    }
    tick = Clock::now();
    if (vertices) {
      st.smoothing_candidates = vertices->size();
    } else {
      st.smoothing_candidates = t.vertices.size();
    }
    const internal::SmoothingResult smoothing =
        vertices ? smoother.UpdateVertices(t, *vertices, centre, radius, options.smoothing)
                 : smoother.Update(t, active, centre, radius, options.smoothing);
    st.smoothed_vertices = smoothing.vertices;
    st.smoothing_rejected = smoothing.rejected;
    st.smoothing_prechecked = smoothing.prechecked;
    st.smoothing_rechecked = smoothing.rechecked;
    st.ms_smooth = MsSince(tick);
  }

  // Notes the vertices whose umbrella may have changed (`vertices`, else those of the cells of
  // `active`) for SmoothPending.
  void DeferSmoothing(const std::vector<CellHandle>& active,
                      const std::vector<VertexHandle>* vertices) {
    std::lock_guard<std::mutex> lock(smoothing_mutex);
    auto note = [&](VertexHandle v) {
      const int index = v->info().index;
      if (index < 0) return;
      if (static_cast<size_t>(index) >= pending_flag.size()) pending_flag.resize(index + 1, 0);
      if (pending_flag[index]) return;
      pending_flag[index] = 1;
      pending_smoothing.push_back(index);
    };
    if (vertices) {
      for (const VertexHandle& v : *vertices) note(v);
      return;
    }
    for (const CellHandle& c : active) {
      for (int i = 0; i < 4; ++i) {
        if (!t.tri.is_infinite(c->vertex(i))) note(c->vertex(i));
      }
    }
  }

  // The smoothing of the vertices noted since the last one, all at once (no bounding ball).
  void SmoothPending() {
    std::lock_guard<std::mutex> lock(smoothing_mutex);
    if (pending_smoothing.empty()) return;
    const auto tick = Clock::now();
    std::vector<VertexHandle> vertices;
    vertices.reserve(pending_smoothing.size());
    for (int index : pending_smoothing) {
      vertices.push_back(t.vertices[index]);
      pending_flag[index] = 0;
    }
    pending_smoothing.clear();
    const internal::SmoothingResult result =
        smoother.UpdateVertices(t, std::move(vertices), Eigen::Vector3d::Zero(),
                                std::numeric_limits<double>::infinity(), options.smoothing);
    ++deferred_smoothing.runs;
    deferred_smoothing.vertices += result.vertices;
    deferred_smoothing.rejected += result.rejected;
    deferred_smoothing.seconds += 1e-3 * MsSince(tick);
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
      pending.insert(pending.end(), buffered.begin(), buffered.end());
    }
    buffered.clear();
    ProcessPending(false, &out);
    return out;
  }

  // The keyframes waiting for a step of keyframes_per_step, in such steps; `all`: the last
  // ones too, in a smaller step.
  void ProcessPending(bool all, std::vector<KeyframeStats>* out) {
    const size_t per_step = static_cast<size_t>(options.keyframes_per_step);
    size_t begin = 0;
    while (pending.size() - begin >= per_step || (all && begin < pending.size())) {
      const size_t end = std::min(pending.size(), begin + per_step);
      std::vector<const SurfaceKeyframe*> group;
      for (size_t k = begin; k < end; ++k) group.push_back(&pending[k]);
      out->push_back(Incremental(group));
      begin = end;
    }
    pending.erase(pending.begin(), pending.begin() + static_cast<std::ptrdiff_t>(begin));
  }
};

IncrementalSculptor::IncrementalSculptor(const SculptorOptions& options)
    : impl_(std::make_unique<Impl>(CheckedOptions(options, "SculptorOptions"))) {}

IncrementalSculptor::~IncrementalSculptor() = default;

std::vector<KeyframeStats> IncrementalSculptor::AddKeyframe(const SurfaceKeyframe& keyframe) {
  Impl& m = *impl_;
  if (m.s > 0.0) {
    m.pending.push_back(keyframe);
    std::vector<KeyframeStats> out;
    m.ProcessPending(false, &out);
    return out;
  }
  m.buffered.push_back(keyframe);
  const bool known = m.options.scale > 0.0 && !m.options.batch_with_known_scale;
  if (static_cast<int>(m.buffered.size()) >= m.options.init_keyframes || known) {
    return m.ProcessBuffered();
  }
  return {};
}

std::vector<KeyframeStats> IncrementalSculptor::Finish() {
  std::vector<KeyframeStats> out = impl_->ProcessBuffered();
  impl_->ProcessPending(true, &out);
  return out;
}

TriangleMesh IncrementalSculptor::ExtractMesh(std::vector<PointId>* vertex_points) const {
  impl_->SmoothPending();
  const Impl& m = *impl_;
  if (!vertex_points) {
    if (m.options.smoothing.enabled) return m.smoother.Extract(m.t);  // step 6
    return m.mesh.ExtractSurface();
  }
  vertex_points->clear();
  return internal::ExtractBorderOfO(m.t, [&](VertexHandle v) {
    const int point = v->info().point;
    vertex_points->push_back(point >= 0 ? m.points[point].id : PointId::Invalid());
    return m.options.smoothing.enabled ? m.smoother.Position(v) : ToEigen(v->point());
  });
}

std::vector<PointId> IncrementalSculptor::InsertedPoints() const {
  std::vector<PointId> ids;
  ids.reserve(impl_->points.size());
  for (size_t i = 0; i < impl_->points.size(); ++i) {
    const PointRecord& point = impl_->points[i];
    if (point.vertex->info().point == static_cast<int32_t>(i)) ids.push_back(point.id);
  }
  return ids;
}

TriangleMesh IncrementalSculptor::ExtractObservedMesh(std::vector<PointId>* vertex_points,
                                                      ObservedMeshStats* stats) const {
  impl_->SmoothPending();
  const Impl& m = *impl_;
  std::vector<int> records;  // per vertex of δO: its index in m.points, -1 for Steiner
  const TriangleMesh closed = internal::ExtractBorderOfO(m.t, [&](VertexHandle v) {
    records.push_back(v->info().point);
    return m.options.smoothing.enabled ? m.smoother.Position(v) : ToEigen(v->point());
  });
  std::vector<ObservedVertex> vertices(records.size());
  // A vertex with points merged into it is seen from all of their origins.
  std::vector<std::vector<Eigen::Vector3d>> merged_origins;
  merged_origins.reserve(records.size());
  for (size_t i = 0; i < records.size(); ++i) {
    if (records[i] < 0) continue;
    const PointRecord& first = m.points[records[i]];
    if (first.next_of_vertex < 0) {
      vertices[i].origins = &first.origins;
      continue;
    }
    std::vector<Eigen::Vector3d>& origins = merged_origins.emplace_back();
    for (int r = records[i]; r >= 0; r = m.points[r].next_of_vertex)
      origins.insert(origins.end(), m.points[r].origins.begin(), m.points[r].origins.end());
    vertices[i].origins = &origins;
  }
  std::vector<int> kept;
  TriangleMesh observed =
      SelectObservedMesh(closed, vertices, m.s, m.options.observed, &kept, stats);
  if (vertex_points) {
    vertex_points->clear();
    for (int v : kept) vertex_points->push_back(m.points[records[v]].id);
  }
  return observed;
}

void ColorMeshVertices(const std::vector<PointId>& vertex_points,
                       const std::unordered_map<PointId, Rgb8>& point_colors, TriangleMesh* mesh,
                       uint8_t grey) {
  if (vertex_points.size() != mesh->vertices.size()) {
    throw std::invalid_argument("ColorMeshVertices: " + std::to_string(vertex_points.size()) +
                                " point ids for " + std::to_string(mesh->vertices.size()) +
                                " vertices");
  }
  mesh->colors.assign(mesh->vertices.size(), Rgb8(grey, grey, grey));
  for (size_t v = 0; v < vertex_points.size(); ++v) {
    const auto it = point_colors.find(vertex_points[v]);
    if (it != point_colors.end()) mesh->colors[v] = it->second;
  }
}
Eigen::Vector3d IncrementalSculptor::SurfacePosition(int vertex) const {
  impl_->SmoothPending();
  return impl_->smoother.Position(impl_->t.vertices.at(vertex));
}
IncrementalSculptor::DeferredSmoothing IncrementalSculptor::DeferredSmoothingStats() const {
  std::lock_guard<std::mutex> lock(impl_->smoothing_mutex);
  return impl_->deferred_smoothing;
}
const DelaunayMesh& IncrementalSculptor::triangulation() const { return impl_->mesh; }
double IncrementalSculptor::scale() const { return impl_->s; }
double IncrementalSculptor::keyframe_spacing() const { return impl_->spacing; }
double IncrementalSculptor::ray_length_bound() const { return impl_->r; }
double IncrementalSculptor::ground_bound() const { return impl_->ground; }
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
  // The star counts of VertexOnSurface (VertexInfo::o_cells, degree) against recounts.
  if (tri.dimension() == 3) {
    std::unordered_map<const void*, std::pair<uint32_t, uint32_t>> counts;  // o_cells, degree
    for (auto c : tri.all_cell_handles()) {
      for (int i = 0; i < 4; ++i) {
        auto& k = counts[&*c->vertex(i)];
        k.first += c->info().in_o ? 1 : 0;
        ++k.second;
      }
    }
    size_t wrong_o = 0, wrong_degree = 0;
    for (auto v : tri.finite_vertex_handles()) {
      const auto& k = counts[&*v];
      wrong_o += v->info().o_cells != k.first;
      wrong_degree += m.t.degrees_valid && m.t.Degree(v) != k.second;
    }
    if (wrong_o) problems << wrong_o << " vertices with a wrong count of cells of O; ";
    if (wrong_degree) problems << wrong_degree << " vertices with a wrong degree; ";
  }
  return problems.str();
}

}  // namespace omni
