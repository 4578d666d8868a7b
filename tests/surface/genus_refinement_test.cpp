// Step 6 of paper §4.6, genus refinement: a hand-built tunnel loop of free cells blocked by a
// slab of free cells outside O (a false bridge) is opened, δO going from a sphere to a torus;
// δO stays a 2-manifold after every keyframe of a noisy street run with refinement; the off
// switch leaves O as step 5 made it.

#include "surface/genus_refinement.h"

#include <gtest/gtest.h>

#include <random>

#include "calib/mesh_check.h"
#include "surface/sculptor.h"
#include "tests/surface/step6_scenes.h"

namespace omni {
namespace {

// δO may be empty before the first cell is carved: an empty surface passes the check.
MeshCheckOptions EmptyAllowed() {
  MeshCheckOptions options;
  options.allow_empty = true;
  return options;
}
const MeshCheckOptions kEmptyAllowed = EmptyAllowed();

struct Tunnel {
  DelaunayMesh mesh;
  std::vector<CellKey> tunnel, slab;  // cells of the loop (slab included) and of the slab
};

Eigen::Vector3d Centroid(const DelaunayMesh& mesh, const CellKey& c) {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (int v : c) m += mesh.Position(v);
  return m / 4.0;
}

// A jittered 12×12×6 lattice; the loop is the square annulus 1 < x, y < 10 minus the square
// 4 < x, y < 7, for 1 < z < 4 (cells by centroid); the slab is its part 5 < x < 6, y < 4.
// Every cell of the loop is free (counter 1, by a ray from one of its vertices to its
// centroid); O is grown one cell at once (addition test, §3.1) in the loop without the slab.
Tunnel MakeTunnel(uint32_t seed) {
  Tunnel t;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> jitter(-0.12, 0.12);
  for (int i = 0; i < 12; ++i) {
    for (int j = 0; j < 12; ++j) {
      for (int k = 0; k < 6; ++k) {
        t.mesh.Insert(Eigen::Vector3d(i + jitter(rng), j + jitter(rng), k + jitter(rng)));
      }
    }
  }
  auto in_loop = [](const Eigen::Vector3d& p) {
    const bool annulus = p.x() > 1 && p.x() < 10 && p.y() > 1 && p.y() < 10 &&
                         !(p.x() > 4 && p.x() < 7 && p.y() > 4 && p.y() < 7);
    return annulus && p.z() > 1 && p.z() < 4;
  };
  auto in_slab = [](const Eigen::Vector3d& p) { return p.x() > 5 && p.x() < 6 && p.y() < 4; };
  for (const CellKey& c : t.mesh.FiniteCells()) {
    const Eigen::Vector3d m = Centroid(t.mesh, c);
    if (!in_loop(m)) continue;
    t.tunnel.push_back(c);
    if (in_slab(m)) t.slab.push_back(c);
    t.mesh.TraceRay(c[0], m);
  }
  std::vector<CellKey> grow;
  for (const CellKey& c : t.tunnel) {
    if (!in_slab(Centroid(t.mesh, c))) grow.push_back(c);
  }
  t.mesh.SetInO(grow.front(), true);
  for (bool progress = true; progress;) {
    progress = false;
    for (const CellKey& c : grow) {
      if (t.mesh.InO(c) || t.mesh.CountsInSurface(c).triangles == 0) continue;
      if (!t.mesh.SingleCellTest(c)) continue;
      t.mesh.SetInO(c, true);
      progress = true;
    }
  }
  return t;
}

TEST(GenusRefinement, OpensAFalseBridgeAcrossATunnelLoop) {
  Tunnel t = MakeTunnel(7);
  ASSERT_GT(t.slab.size(), 20u);
  // Exactly the loop is free: each ray stayed in its cell.
  size_t free_cells = 0;
  for (const CellKey& c : t.mesh.FiniteCells()) free_cells += t.mesh.Counter(c) > 0 ? 1 : 0;
  ASSERT_EQ(free_cells, t.tunnel.size());
  for (const CellKey& c : t.slab) ASSERT_FALSE(t.mesh.InO(c));

  const MeshCheckReport before = CheckMesh(t.mesh.ExtractSurface());
  ASSERT_TRUE(before.ok) << before.Summary();
  ASSERT_EQ(before.components, 1);
  ASSERT_EQ(before.euler_characteristic, 2);  // a sphere: the growing cannot close the loop
  const size_t o_before = t.mesh.NumInO();

  GenusRefinementOptions options;
  options.max_group_cells = 64;
  const GenusRefinementStats stats = RefineGenus(t.mesh, options);
  const MeshCheckReport after = CheckMesh(t.mesh.ExtractSurface());
  EXPECT_TRUE(after.ok) << after.Summary();
  EXPECT_EQ(after.components, 1);
  EXPECT_EQ(after.euler_characteristic, 0) << "a torus: genus 1";
  EXPECT_EQ(stats.euler_change, after.euler_characteristic - before.euler_characteristic);
  EXPECT_GE(stats.groups, 1u);
  EXPECT_GT(t.mesh.NumInO(), o_before);
  EXPECT_EQ(stats.free_before, t.tunnel.size() - o_before);
  EXPECT_EQ(stats.free_after, t.tunnel.size() - t.mesh.NumInO());
  size_t slab_in_o = 0;
  for (const CellKey& c : t.slab) slab_in_o += t.mesh.InO(c) ? 1 : 0;
  EXPECT_GT(slab_in_o, t.slab.size() / 2);
  std::cout << "tunnel: " << t.tunnel.size() << " free cells, slab " << t.slab.size() << ", O "
            << o_before << " -> " << t.mesh.NumInO() << ", groups " << stats.groups
            << ", slab cells opened " << slab_in_o << "\n";
}

TEST(GenusRefinement, SwitchedOffOrWithoutGroupsItKeepsTheSphere) {
  Tunnel t = MakeTunnel(7);
  const size_t o_before = t.mesh.NumInO();
  GenusRefinementOptions off;
  off.enabled = false;
  const GenusRefinementStats stats = RefineGenus(t.mesh, off);
  EXPECT_EQ(t.mesh.NumInO(), o_before);
  EXPECT_EQ(stats.groups, 0u);
  EXPECT_EQ(stats.free_after, stats.free_before);
  // Single cells only (no edge stars, no groups): the addition test never changes the
  // topology, so the slab stays closed.
  GenusRefinementOptions singles;
  singles.edge_stars = false;
  singles.max_group_cells = 0;
  RefineGenus(t.mesh, singles);
  const MeshCheckReport report = CheckMesh(t.mesh.ExtractSurface());
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_EQ(report.euler_characteristic, 2);
}

TEST(GenusRefinementOptions, CheckRejectsBadValues) {
  GenusRefinementOptions o;
  EXPECT_EQ(o.Check(), "");
  o.max_group_cells = -1;
  EXPECT_NE(o.Check(), "");
  SculptorOptions s;
  s.genus.max_group_cells = -1;
  EXPECT_NE(s.Check(), "");
}

// A noisy street (5 cm) sculpted keyframe by keyframe with refinement: after every keyframe
// δO is an oriented 2-manifold by the independent checker, the invariants hold, and the
// refinement's counts are consistent.
TEST(GenusRefinement, StreetStaysManifoldAfterEveryKeyframe) {
  const auto drive = testing::NoisyStreet(30, 100, 0.05, 3);
  SculptorOptions options;
  options.scale = 1.0;
  options.smoothing.enabled = false;
  IncrementalSculptor sculptor(options);
  size_t groups = 0, checked = 0;
  for (const SurfaceKeyframe& kf : drive) {
    for (const KeyframeStats& st : sculptor.AddKeyframe(kf)) {
      EXPECT_LE(st.genus_free_after, st.genus_free_before);
      groups += st.genus_groups;
      const std::string problems = sculptor.CheckInvariants(false);
      EXPECT_TRUE(problems.empty()) << "keyframe " << st.keyframe.value << ": " << problems;
      const MeshCheckReport report = CheckMesh(sculptor.ExtractMesh(), kEmptyAllowed);
      EXPECT_TRUE(report.ok) << "keyframe " << st.keyframe.value << ": " << report.Summary();
      EXPECT_EQ(static_cast<size_t>(report.triangles), st.triangles);
      ++checked;
    }
  }
  EXPECT_EQ(checked, drive.size());
  std::cout << "street: " << groups << " groups added by the genus refinement\n";
}

// The shortcuts of the refinement (memo of the groups that failed since O last changed, the
// vertex that failed last tested first) against the reference: after every keyframe of a noisy
// street, the same δO and the same counts.
TEST(GenusRefinement, ShortcutsMatchTheReference) {
  const auto drive = testing::NoisyStreet(24, 100, 0.08, 21);
  SculptorOptions fast;
  fast.scale = 1.0;
  fast.smoothing.enabled = false;
  SculptorOptions reference = fast;
  reference.genus.reference = true;
  IncrementalSculptor a(fast), b(reference);
  size_t groups = 0;
  for (const SurfaceKeyframe& kf : drive) {
    const std::vector<KeyframeStats> sa = a.AddKeyframe(kf), sb = b.AddKeyframe(kf);
    ASSERT_EQ(sa.size(), sb.size());
    for (size_t i = 0; i < sa.size(); ++i) {
      EXPECT_EQ(sa[i].genus_groups, sb[i].genus_groups);
      EXPECT_EQ(sa[i].genus_euler_change, sb[i].genus_euler_change);
      EXPECT_EQ(sa[i].genus_free_after, sb[i].genus_free_after);
      groups += sa[i].genus_groups;
    }
    const TriangleMesh ma = a.ExtractMesh(), mb = b.ExtractMesh();
    ASSERT_EQ(ma.triangles, mb.triangles) << "keyframe " << kf.id.value;
    ASSERT_EQ(ma.vertices, mb.vertices) << "keyframe " << kf.id.value;
  }
  EXPECT_GT(groups, 0u);  // the comparison is not vacuous
}

TEST(GenusRefinement, ShortcutsMatchTheReferenceOnTunnels) {
  size_t groups = 0;
  for (uint32_t seed : {7u, 8u, 9u, 10u}) {
    for (int max_group_cells : {4, 8, 64}) {
      Tunnel fast = MakeTunnel(seed), reference = MakeTunnel(seed);
      GenusRefinementOptions options;
      options.max_group_cells = max_group_cells;
      const GenusRefinementStats a = RefineGenus(fast.mesh, options);
      options.reference = true;
      const GenusRefinementStats b = RefineGenus(reference.mesh, options);
      EXPECT_EQ(a.groups, b.groups) << "seed " << seed << " groups of " << max_group_cells;
      EXPECT_EQ(a.euler_change, b.euler_change);
      EXPECT_EQ(fast.mesh.ExtractSurface().triangles, reference.mesh.ExtractSurface().triangles);
      groups += a.groups;
    }
  }
  EXPECT_GT(groups, 0u);
}

}  // namespace
}  // namespace omni
