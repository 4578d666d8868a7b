#pragma once
// INTERNAL to surface/*.cpp: the re-tracing of old rays over the new cells N (paper §4.4).
//
// The paper collects the old rays that can meet N with bounding boxes per keyframe and walks
// them again. Here the old rays are registered once in the voxels of a uniform grid that they
// cross (RayGrid, kept for the whole drive), and N is described by its border: the facets of N
// cells whose neighbour is not in N (NewCellBorder, built per keyframe and registered in the
// same grid). The candidate rays are those registered in a voxel that a border facet touches,
// plus the rays of the points that are vertices of N cells. A candidate ray then meets N only
// where its walk starts in an N cell (its point is a vertex of N) or where it crosses a border
// facet into N; the walk is done from each of those places while it stays in N, which visits
// exactly the N cells the whole walk from the point would visit. A crossing that is not clean
// (the segment through an edge or a vertex of a border facet, or in its plane) is reported, and
// the caller walks that ray whole instead. Exact predicates decide every crossing.

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>
#include <unordered_map>
#include <utility>
#include <vector>

#include "surface/internal/cgal_delaunay.h"

namespace omni::internal {

// Voxel keys of a uniform grid with cubic voxels of side `step`, origin at 0.
class VoxelGrid {
 public:
  explicit VoxelGrid(double step = 1.0) : step_(step) {}
  double step() const { return step_; }
  Eigen::Vector3i VoxelOf(const Eigen::Vector3d& p) const {
    return (p / step_).array().floor().cast<int>();
  }
  static uint64_t Key(const Eigen::Vector3i& v) {
    constexpr int64_t kOff = 1 << 20;
    return (static_cast<uint64_t>(v.x() + kOff) << 42) |
           (static_cast<uint64_t>(v.y() + kOff) << 21) | static_cast<uint64_t>(v.z() + kOff);
  }
  // Calls f(key) for every voxel the segment a→b passes through, in order from a (a 3D DDA,
  // Amanatides and Woo 1987). Where the segment passes within rounding of a voxel edge or
  // corner, a voxel it only grazes may be left out; NewCellBorder pads its facets for that.
  template <typename F>
  void ForEachVoxelOnSegment(const Eigen::Vector3d& a, const Eigen::Vector3d& b, F&& f) const;

 private:
  double step_;
};

// The old rays in the voxels they cross (persistent). A ray is a dense id given by the caller.
class RayGrid {
 public:
  explicit RayGrid(double step = 1.0) : grid_(step) {}
  const VoxelGrid& grid() const { return grid_; }
  void Add(uint32_t ray, const Eigen::Vector3d& a, const Eigen::Vector3d& b);
  const std::vector<uint32_t>* RaysIn(uint64_t key) const {
    const auto it = rays_.find(key);
    return it == rays_.end() ? nullptr : &it->second;
  }
  size_t NumEntries() const { return entries_; }
  size_t NumVoxels() const { return rays_.size(); }

 private:
  VoxelGrid grid_;
  std::unordered_map<uint64_t, std::vector<uint32_t>> rays_;
  size_t entries_ = 0;
};

// A facet of a cell: the cell and the index of the vertex opposite the facet.
using CellFacet = std::pair<CellHandle, int>;

// What NewCellBorder::Entries did, summed over calls (the cost model of the old rays' queries).
struct EntriesWork {
  size_t queries = 0;
  size_t voxels = 0;        // fine voxels walked along the segments
  size_t facets = 0;        // border facets tested (each once per query)
  size_t plane_passes = 0;  // of them, not settled by the plane filter in doubles
  EntriesWork& operator+=(const EntriesWork& o) {
    queries += o.queries;
    voxels += o.voxels;
    facets += o.facets;
    plane_passes += o.plane_passes;
    return *this;
  }
};

// The border of the new cells N (cells whose date is `date`) in a voxel grid.
//
// For candidate selection the border facets are registered in the voxels of `grid` (those of
// RayGrid). For Entries they are indexed again in the voxels of a finer grid aligned with `grid`
// (side grid.step() / subdivision), in blocks of fine voxels, one per voxel of `grid` that holds
// a facet, found through a dense array over the box of the border (no hashing): a ray walks the
// fine voxels of its part inside that box only and tests their facets. Both registrations are
// padded by more than the rounding of the voxel walks (a voxel that a segment only grazes may be
// left out of its walk), so no crossing is missed.
class NewCellBorder {
 public:
  // Fine voxels per side of a voxel of `grid`. A ray tests the facets of the fine voxels it
  // crosses, a tube around it as wide as a fine voxel (fewer facets in finer voxels), but walks
  // more voxels and the registration fills more. On the paper benchmark (s ≈ 1.9 m) 1 and 2
  // measured alike, 3 and 4 slower; 6 tested 35 % fewer facets than 3 but walked twice the
  // voxels and took 20x longer to register the (large) facets when they all went to fine voxels.
  static constexpr int kDefaultSubdivision = 2;
  // The dense array of blocks holds at most this many entries (4 bytes each): a larger box of N
  // (hundreds of voxels per side) is indexed with blocks of several voxels of `grid` and no
  // subdivision (then voxels() lists every voxel of `grid` of a block with a facet).
  static constexpr size_t kMaxBlocks = size_t{1} << 22;
  // Facets whose box is larger than this many voxels of `grid` (on a side) are registered in
  // the blocks, not in the fine voxels: a fine voxel holds them no better than a block (a ray
  // near them meets them anyway), and they would fill many fine voxels.
  static constexpr double kFineFacetSize = 4.0;

  NewCellBorder(const Delaunay& tri, const std::vector<CellHandle>& n_cells, uint32_t date,
                const VoxelGrid& grid, int subdivision = kDefaultSubdivision);
  // Empty; Build makes it the border of N (again for each keyframe, reusing its memory).
  NewCellBorder(const Delaunay& tri, const VoxelGrid& grid, int subdivision = kDefaultSubdivision);
  // only_crossed: leaves out the facets whose outer cell (not in N) has a zero ray counter. An
  // old ray (traced before the keyframe) that enters N through a facet crosses the cell outside
  // it first, which its walk counted, so none enters through those. Exact for rays in general
  // position; a walk through an edge or a vertex of T may pick other cells around it than an
  // earlier walk of the same ray did (OldRayTracingGivesTheBruteForceCountersOnARandomStream,
  // with points on common planes, compares every counter with the brute force).
  void Build(const std::vector<CellHandle>& n_cells, uint32_t date, bool only_crossed = false);
  // Build in two parts: Collect finds the border facets (the only part that reads the cells'
  // ray counters), Index registers them in the voxels (it reads only the facets, so it may run
  // while rays are traced).
  void Collect(const std::vector<CellHandle>& n_cells, uint32_t date, bool only_crossed);
  void Index();
  // Border facets left out by only_crossed in the last Build (their outer cell uncrossed).
  size_t NumUncrossed() const { return uncrossed_; }
  // Keys of the voxels of `grid` that a border facet touches (a superset).
  const std::vector<uint64_t>& voxels() const { return keys_; }
  size_t NumFacets() const { return facets_.size(); }
  // The subdivision used (1 when the box is huge), the voxels of `grid` per block side and the
  // number of blocks.
  int subdivision() const { return subdivision_; }
  int grid_voxels_per_block() const { return grid_per_block_; }
  size_t NumBlocks() const { return num_blocks_; }

  // The places where the segment from→target (from: the vertex `from`) crosses the border into
  // N, each as the N cell entered and the facet it is entered through, in no particular order.
  // False when a crossing is not clean (then *entries is incomplete: walk the whole segment).
  // Thread-safe. work: if given, what the call did is added to it.
  bool Entries(VertexHandle from, const Point& target, std::vector<CellFacet>* entries,
               EntriesWork* work = nullptr) const;
  // The same with every border facet tested (no voxels): the reference of the tests.
  bool EntriesBruteForce(VertexHandle from, const Point& target,
                         std::vector<CellFacet>* entries) const;

 private:
  // What the double-precision filter of Entries reads, packed (it runs over every facet in the
  // voxels of every candidate ray): the plane test reads the first cache line only.
  struct alignas(64) Facet {
    Eigen::Vector3d normal;  // (b − a) × (d − a) of the facet's vertices a, b, d
    double offset;           // normal · a
    // +1 or −1: the sign of normal · x − offset on the side of the N cell (x its fourth vertex).
    double inner;
    double extent;  // largest coordinate magnitude of the facet (at least 1)
    // Times the largest coordinate magnitude involved: a bound of the rounding of
    // normal · x − offset.
    double tolerance;
    double norm;  // ‖normal‖
    // Edge e (from corner e to corner e+1): x is beyond its line, seen along the normal, when
    // edge_normal[e] · x − edge_offset[e] < −edge_slack[e] · (largest coordinate magnitude).
    // edge_normal[e] = normal × (corner[e+1] − corner[e]).
    Eigen::Vector3d edge_normal[3];
    double edge_offset[3];
    double edge_slack[3];
  };
  // The facet itself: the N cell and the index of the vertex opposite the facet, and the facet's
  // vertices a, b, d (cyclic order of the cell).
  struct FacetOf {
    CellHandle cell;
    int index;
    VertexHandle vertex[3];
  };
  // What Entries tests per facet: the segment a→b (from→target in doubles) and its exact ends.
  struct Query;
  enum class Test { kMiss, kEnters, kDegenerate };
  Test TestFacet(uint32_t id, const Query& q) const;

  const Delaunay& tri_;
  const VoxelGrid& grid_;
  int subdivision_asked_;
  size_t uncrossed_ = 0;
  std::vector<Facet> facets_;
  std::vector<FacetOf> facet_of_;
  std::vector<uint64_t> keys_;
  // Fine voxels of side fine_step_ = grid.step() / subdivision_, in blocks of block_side_ =
  // subdivision_ · grid_per_block_ fine voxels per side (aligned with `grid`), blocks lo_ .. lo_ +
  // size_ − 1 of the box (global block indices); block_ gives each block of the box (x fastest) its
  // number, −1 when it holds no facet. The facet ids of fine voxel v of block number b (v: x
  // fastest in the block) are ids_[first_[b · block_side_³ + v]] .. ids_[first_[b · block_side_³ +
  // v + 1] − 1].
  int subdivision_ = 1;
  int grid_per_block_ = 1;
  int block_side_ = 1;
  double fine_step_ = 1.0;
  size_t num_blocks_ = 0;
  Eigen::Vector3i lo_ = Eigen::Vector3i::Zero(), size_ = Eigen::Vector3i::Zero();
  // Facets larger than kFineFacetSize voxels of `grid` are registered in the blocks instead
  // (a large facet would fill many fine voxels): those of block number b are
  // block_ids_[block_first_[b]] .. block_ids_[block_first_[b + 1] − 1].
  std::vector<int32_t> block_;
  std::vector<uint32_t> first_, ids_, block_first_, block_ids_;
  // Per axis, for a fine voxel index r relative to the box (0 ≤ r < size_ · block_side_): the
  // offset of its block in block_ and of the voxel in its block.
  std::vector<int32_t> block_offset_[3], voxel_offset_[3];
  struct Scratch {  // Build's buffers, kept for their memory
    std::vector<Eigen::AlignedBox3d> boxes;
    Eigen::AlignedBox3d all;  // of the boxes
    std::vector<std::pair<uint32_t, uint32_t>> registered, registered_in_block;
    std::vector<uint32_t> count, block_count;
  } scratch_;
};

// Calls f(v) for every voxel v (integer coordinates) of the grid of side `step` that the segment
// a→b passes through, in order from a (a 3D DDA, Amanatides and Woo 1987). Where the segment
// passes within rounding of a voxel edge or corner, a voxel it only grazes may be left out.
// f may return false to stop the walk.
template <typename F>
void ForEachVoxelIndexOnSegment(double step, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                F&& f);

template <typename F>
void VoxelGrid::ForEachVoxelOnSegment(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                      F&& f) const {
  ForEachVoxelIndexOnSegment(step_, a, b, [&](const Eigen::Vector3i& v) {
    f(Key(v));
    return true;
  });
}

template <typename F>
void ForEachVoxelIndexOnSegment(double step_size, const Eigen::Vector3d& a,
                                const Eigen::Vector3d& b, F&& f) {
  const auto voxel_of = [step_size](const Eigen::Vector3d& p) -> Eigen::Vector3i {
    return (p / step_size).array().floor().cast<int>();
  };
  Eigen::Vector3i v = voxel_of(a);
  const Eigen::Vector3i end = voxel_of(b);
  const Eigen::Vector3d d = b - a;
  int step[3];
  double t_max[3], t_delta[3];
  for (int k = 0; k < 3; ++k) {
    step[k] = d[k] > 0 ? 1 : (d[k] < 0 ? -1 : 0);
    if (step[k] == 0) {
      t_max[k] = t_delta[k] = 2.0;
      continue;
    }
    t_delta[k] = step_size / std::abs(d[k]);
    const double boundary = (v[k] + (step[k] > 0 ? 1 : 0)) * step_size;
    t_max[k] = (boundary - a[k]) / d[k];
  }
  const int max_steps = (end - v).cwiseAbs().sum();
  for (int n = 0;; ++n) {
    if (!f(static_cast<const Eigen::Vector3i&>(v))) return;
    if (v == end || n >= max_steps) return;
    int k = t_max[0] < t_max[1] ? 0 : 1;
    if (t_max[2] < t_max[k]) k = 2;
    if (t_max[k] > 1.0) {
      // Rounding: the end voxel was not reached on the way; walk straight to it.
      for (int j = 0; j < 3; ++j) {
        while (v[j] != end[j]) {
          v[j] += end[j] > v[j] ? 1 : -1;
          if (!f(static_cast<const Eigen::Vector3i&>(v))) return;
        }
      }
      return;
    }
    v[k] += step[k];
    t_max[k] += t_delta[k];
  }
}

}  // namespace omni::internal
