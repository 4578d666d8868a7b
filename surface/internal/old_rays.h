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

// The border of the new cells N (cells whose date is `date`) in a voxel grid.
class NewCellBorder {
 public:
  NewCellBorder(const Delaunay& tri, const std::vector<CellHandle>& n_cells, uint32_t date,
                const VoxelGrid& grid);
  // Keys of the voxels that a border facet touches.
  const std::vector<uint64_t>& voxels() const { return keys_; }
  size_t NumFacets() const { return facets_.size(); }

  // The places where the segment from→target (from: the vertex `from`) crosses the border into
  // N, each as the N cell entered and the facet it is entered through, in no particular order.
  // False when a crossing is not clean (then *entries is incomplete: walk the whole segment).
  // Thread-safe.
  bool Entries(VertexHandle from, const Point& target, std::vector<CellFacet>* entries) const;

 private:
  // What the double-precision filter of Entries reads, packed (it runs over every facet in the
  // voxels of every candidate ray).
  struct Facet {
    Eigen::Vector3d normal;  // (b − a) × (d − a) of the facet's vertices a, b, d
    double offset;           // normal · a
    double extent;           // largest coordinate magnitude of the facet (at least 1)
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
  const Delaunay& tri_;
  const VoxelGrid& grid_;
  std::vector<Facet> facets_;
  std::vector<FacetOf> facet_of_;
  // Facet ids per voxel: those of keys_[i] are ids_[first_[i]] .. ids_[first_[i + 1] − 1].
  std::unordered_map<uint64_t, uint32_t> voxel_index_;  // key → i
  std::vector<uint32_t> first_, ids_;
  std::vector<uint64_t> keys_;
};

template <typename F>
void VoxelGrid::ForEachVoxelOnSegment(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                      F&& f) const {
  Eigen::Vector3i v = VoxelOf(a);
  const Eigen::Vector3i end = VoxelOf(b);
  const Eigen::Vector3d d = b - a;
  int step[3];
  double t_max[3], t_delta[3];
  for (int k = 0; k < 3; ++k) {
    step[k] = d[k] > 0 ? 1 : (d[k] < 0 ? -1 : 0);
    if (step[k] == 0) {
      t_max[k] = t_delta[k] = 2.0;
      continue;
    }
    t_delta[k] = step_ / std::abs(d[k]);
    const double boundary = (v[k] + (step[k] > 0 ? 1 : 0)) * step_;
    t_max[k] = (boundary - a[k]) / d[k];
  }
  const int max_steps = (end - v).cwiseAbs().sum();
  for (int n = 0;; ++n) {
    f(Key(v));
    if (v == end || n >= max_steps) return;
    int k = t_max[0] < t_max[1] ? 0 : 1;
    if (t_max[2] < t_max[k]) k = 2;
    if (t_max[k] > 1.0) {
      // Rounding: the end voxel was not reached on the way; walk straight to it.
      for (int j = 0; j < 3; ++j) {
        while (v[j] != end[j]) {
          v[j] += end[j] > v[j] ? 1 : -1;
          f(Key(v));
        }
      }
      return;
    }
    v[k] += step[k];
    t_max[k] += t_delta[k];
  }
}

}  // namespace omni::internal
