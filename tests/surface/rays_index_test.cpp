// The index of the border of the new cells N (surface/internal/old_rays.h) that the re-tracing of
// old rays (paper §4.4) uses: its entries into N against every border facet tested and against
// the cells of the walk, its voxels against the voxels of the rays that cross N, on random
// triangulations with points on a lattice (segments through voxel edges and corners, facets in
// voxel planes) and at several subdivisions, voxel sizes and the coarse fallback of huge boxes.

#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <unordered_set>
#include <vector>

#include "surface/internal/cgal_delaunay.h"
#include "surface/internal/old_rays.h"

namespace omni {
namespace {

using internal::CellFacet;
using internal::CellHandle;
using internal::NewCellBorder;
using internal::Point;
using internal::VertexHandle;
using internal::VoxelGrid;

struct Scene {
  DelaunayMesh mesh;
  std::vector<CellHandle> n_cells;
  std::vector<VertexHandle> vertices;
};

// Points in [−1, 1]³, half of them on a lattice of step 0.25 (the voxel planes of the grids
// below), N the finite cells with a vertex in a ball (date 1; the others date 0).
void MakeScene(std::mt19937& rng, Scene* scene) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> lattice(-4, 4);
  for (int i = 0; i < 400; ++i) {
    const Eigen::Vector3d p =
        i % 2 == 0
            ? Eigen::Vector3d(u(rng), u(rng), u(rng))
            : 0.25 * Eigen::Vector3i(lattice(rng), lattice(rng), lattice(rng)).cast<double>();
    scene->mesh.Insert(p, i);
  }
  DelaunayMesh::Impl& t = *scene->mesh.impl();
  for (const VertexHandle& v : t.vertices) {
    if (v != VertexHandle()) scene->vertices.push_back(v);
  }
  const Eigen::Vector3d centre(0.3 * u(rng), 0.3 * u(rng), 0.3 * u(rng));
  for (CellHandle c : t.tri.finite_cell_handles()) {
    bool near = false;
    for (int k = 0; k < 4; ++k)
      near |= (internal::ToEigen(c->vertex(k)->point()) - centre).norm() < 0.6;
    c->info().date = near ? 1 : 0;
    if (near) scene->n_cells.push_back(c);
  }
}

std::vector<CellFacet> Sorted(std::vector<CellFacet> entries) {
  std::sort(entries.begin(), entries.end(), [](const CellFacet& a, const CellFacet& b) {
    return a.first != b.first ? &*a.first < &*b.first : a.second < b.second;
  });
  return entries;
}

// The entries into N of the whole walk from `from` to `target`: a cell of N visited after a cell
// out of N (the first cell is a start in N, not an entry). The walk gives nothing past its end
// ends early (off the hull: the targets are inside it).
std::vector<CellFacet> WalkEntries(const DelaunayMesh::Impl& t, VertexHandle from,
                                   const Point& target) {
  std::vector<CellFacet> entries;
  CellHandle previous;
  t.Walk(from, target, 2.0, [&](CellHandle c) {
    if (previous != CellHandle() && previous->info().date != 1 && c->info().date == 1) {
      entries.emplace_back(c, c->index(previous));
    }
    previous = c;
  });
  return entries;
}

// Runs every check on random rays; returns the numbers of (rays, clean rays with an entry).
std::pair<size_t, size_t> CheckBorder(const Scene& scene, const NewCellBorder& border,
                                      const VoxelGrid& grid, std::mt19937& rng) {
  const DelaunayMesh::Impl& t = *scene.mesh.impl();
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> lattice(-2, 2);
  const std::unordered_set<uint64_t> voxels(border.voxels().begin(), border.voxels().end());
  size_t rays = 0, crossing = 0;
  std::vector<CellFacet> fast, brute;
  for (int i = 0; i < 300; ++i) {
    const VertexHandle from = scene.vertices[rng() % scene.vertices.size()];
    // Targets inside the hull: random, on the lattice (segments along lattice lines and
    // planes, through voxel edges and corners) or at another vertex.
    Eigen::Vector3d target(0.6 * u(rng), 0.6 * u(rng), 0.6 * u(rng));
    if (i % 3 == 1) {
      target = 0.25 * Eigen::Vector3i(lattice(rng), lattice(rng), lattice(rng)).cast<double>();
    }
    if (i % 3 == 2) {
      target = 0.5 * internal::ToEigen(scene.vertices[rng() % scene.vertices.size()]->point());
    }
    const Point target_point = internal::ToCgal(target);
    if (target_point == from->point()) continue;
    ++rays;
    const bool clean_fast = border.Entries(from, target_point, &fast);
    const bool clean_brute = border.EntriesBruteForce(from, target_point, &brute);
    // A degenerate crossing found near the ray is found by the brute force too; the brute force
    // may also find the segment in the plane of a facet far from it (the index does not look
    // there): both then walk the ray whole, which is right either way.
    EXPECT_TRUE(clean_fast || !clean_brute) << "ray " << i;
    if (!clean_fast) continue;
    // The whole walk enters N exactly there.
    EXPECT_EQ(Sorted(fast), Sorted(WalkEntries(t, from, target_point))) << "ray " << i;
    if (clean_brute) {
      EXPECT_EQ(Sorted(fast), Sorted(brute)) << "ray " << i;
    }
    if (fast.empty()) continue;
    ++crossing;
    // A ray that enters N passes through a voxel of the border (what the candidate selection
    // relies on), by the walk of RayGrid.
    bool found = false;
    grid.ForEachVoxelOnSegment(internal::ToEigen(from->point()), target,
                               [&](uint64_t key) { found |= voxels.count(key) > 0; });
    EXPECT_TRUE(found) << "ray " << i;
  }
  return {rays, crossing};
}

TEST(NewCellBorderIndex, EntriesAreThoseOfEveryFacetAndOfTheWalk) {
  std::mt19937 rng(7);
  size_t rays = 0, crossing = 0;
  for (int trial = 0; trial < 3; ++trial) {
    Scene scene;
    MakeScene(rng, &scene);
    ASSERT_GT(scene.n_cells.size(), 50u);
    for (double step : {0.25, 0.5, 1.3}) {
      const VoxelGrid grid(step);
      for (int subdivision : {1, 2, 3, 6}) {
        const NewCellBorder border(scene.mesh.impl()->tri, scene.n_cells, 1, grid, subdivision);
        ASSERT_GT(border.NumFacets(), 10u);
        EXPECT_EQ(border.subdivision(), subdivision);
        EXPECT_EQ(border.grid_voxels_per_block(), 1);
        const auto [r, c] = CheckBorder(scene, border, grid, rng);
        rays += r;
        crossing += c;
      }
    }
  }
  EXPECT_GT(rays, 10000u);
  EXPECT_GT(crossing, 2000u);  // the comparisons are about real crossings
}

// A box of N of more than NewCellBorder::kMaxBlocks voxels is indexed with blocks of several
// voxels; rebuilding one border for another N gives the same entries as a new one.
TEST(NewCellBorderIndex, CoarseBlocksAndRebuildsKeepTheEntries) {
  std::mt19937 rng(11);
  Scene scene;
  MakeScene(rng, &scene);
  const VoxelGrid tiny(0.006);  // N spans ~200 voxels per side: > 2^22 voxels in its box
  const NewCellBorder coarse(scene.mesh.impl()->tri, scene.n_cells, 1, tiny, 3);
  EXPECT_GT(coarse.grid_voxels_per_block(), 1);
  EXPECT_EQ(coarse.subdivision(), 1);
  const auto [rays, crossing] = CheckBorder(scene, coarse, tiny, rng);
  EXPECT_GT(crossing, 50u);
  EXPECT_GT(rays, crossing);

  const VoxelGrid grid(0.5);
  NewCellBorder rebuilt(scene.mesh.impl()->tri, grid);
  std::vector<CellHandle> half(scene.n_cells.begin(),
                               scene.n_cells.begin() + scene.n_cells.size() / 2);
  for (CellHandle c : scene.n_cells) c->info().date = 2;
  for (CellHandle c : half) c->info().date = 1;
  rebuilt.Build(half, 1);
  const NewCellBorder fresh_half(scene.mesh.impl()->tri, half, 1, grid);
  EXPECT_EQ(rebuilt.NumFacets(), fresh_half.NumFacets());
  for (CellHandle c : scene.n_cells) c->info().date = 1;
  rebuilt.Build(scene.n_cells, 1);
  const auto [r2, c2] = CheckBorder(scene, rebuilt, grid, rng);
  EXPECT_GT(c2, 50u);
  EXPECT_GT(r2, c2);
}

}  // namespace
}  // namespace omni
