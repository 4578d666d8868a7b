// Step 6 of paper §4.6, incremental smoothing: on a noisy street (flat walls and ground) and
// inside a noisy sphere it brings the surface closer to the truth, never turns a triangle
// against its free side nor makes two triangles intersect, moves no vertex outside the
// keyframe's enclosing ball (when it runs every keyframe), waits for the surface to be taken
// by default, and switched off gives the Delaunay positions.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <functional>
#include <iostream>
#include <numeric>

#include "calib/mesh_check.h"
#include "surface/sculptor.h"
#include "tests/surface/step6_scenes.h"

namespace omni {
namespace {

struct SculptRun {
  TriangleMesh smoothed, plain;  // ExtractMesh and the surface at the Delaunay positions
};

SculptRun Sculpt(const std::vector<SurfaceKeyframe>& drive, bool smoothing,
                 bool every_keyframe = false) {
  SculptorOptions options;
  options.scale = 1.0;
  options.smoothing.enabled = smoothing;
  options.smoothing.every_keyframe = every_keyframe;
  IncrementalSculptor sculptor(options);
  for (const SurfaceKeyframe& kf : drive) sculptor.AddKeyframe(kf);
  return {sculptor.ExtractMesh(), sculptor.triangulation().ExtractSurface()};
}

// RMS of distance(v) over the vertices whose unsmoothed position is within `near` of the truth
// (the data vertices; the same set for both meshes).
double RmsError(const TriangleMesh& mesh, const TriangleMesh& plain,
                const std::function<double(const Eigen::Vector3d&)>& distance, double near) {
  double sum = 0.0;
  size_t n = 0;
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    if (distance(plain.vertices[i]) > near) continue;
    sum += std::pow(distance(mesh.vertices[i]), 2);
    ++n;
  }
  EXPECT_GT(n, 200u);
  return std::sqrt(sum / static_cast<double>(std::max<size_t>(n, 1)));
}

// Whether segment p→q crosses triangle (a, b, c) at an interior point of both (Möller–Trumbore,
// touching at an end or an edge does not count).
bool SegmentCrossesTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& q,
                            const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                            const Eigen::Vector3d& c) {
  constexpr double kEps = 1e-9;
  const Eigen::Vector3d d = q - p, e1 = b - a, e2 = c - a;
  const Eigen::Vector3d h = d.cross(e2);
  const double det = e1.dot(h);
  if (std::abs(det) < 1e-14) return false;
  const Eigen::Vector3d s = p - a;
  const double u = s.dot(h) / det;
  const Eigen::Vector3d k = s.cross(e1);
  const double v = d.dot(k) / det;
  const double t = e2.dot(k) / det;
  return u > kEps && v > kEps && u + v < 1 - kEps && t > kEps && t < 1 - kEps;
}

// Pairs of triangles that intersect: no shared vertex and an edge of one crossing the other,
// or one shared vertex and the far edge of one crossing the other.
size_t CountIntersectingPairs(const TriangleMesh& mesh) {
  const size_t n = mesh.triangles.size();
  std::vector<Eigen::AlignedBox3d> boxes(n);
  for (size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) boxes[i].extend(mesh.vertices[mesh.triangles[i][k]]);
  }
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return boxes[a].min().x() < boxes[b].min().x(); });
  size_t pairs = 0;
  for (size_t oi = 0; oi < n; ++oi) {
    const size_t i = order[oi];
    for (size_t oj = oi + 1; oj < n && boxes[order[oj]].min().x() <= boxes[i].max().x(); ++oj) {
      const size_t j = order[oj];
      if (!boxes[i].intersects(boxes[j])) continue;
      const Eigen::Vector3i& ti = mesh.triangles[i];
      const Eigen::Vector3i& tj = mesh.triangles[j];
      int shared = 0;
      for (int a = 0; a < 3; ++a) {
        for (int b = 0; b < 3; ++b) shared += ti[a] == tj[b] ? 1 : 0;
      }
      if (shared >= 2) continue;
      auto crosses = [&](const Eigen::Vector3i& s, const Eigen::Vector3i& t) {
        for (int e = 0; e < 3; ++e) {
          const int u = s[e], w = s[(e + 1) % 3];
          if (u == t[0] || u == t[1] || u == t[2] || w == t[0] || w == t[1] || w == t[2]) {
            continue;  // an edge through the shared vertex
          }
          if (SegmentCrossesTriangle(mesh.vertices[u], mesh.vertices[w], mesh.vertices[t[0]],
                                     mesh.vertices[t[1]], mesh.vertices[t[2]])) {
            return true;
          }
        }
        return false;
      };
      if (crosses(ti, tj) || crosses(tj, ti)) ++pairs;
    }
  }
  return pairs;
}

Eigen::Vector3d Normal(const TriangleMesh& m, const Eigen::Vector3i& t) {
  return (m.vertices[t[1]] - m.vertices[t[0]]).cross(m.vertices[t[2]] - m.vertices[t[0]]);
}

// The smoothed surface has the triangles of the unsmoothed one, each facing the same side, no
// intersecting pair, and is an oriented 2-manifold.
void ExpectSameTrianglesNoFlipNoIntersection(const SculptRun& run) {
  ASSERT_EQ(run.smoothed.triangles, run.plain.triangles);
  size_t flipped = 0;
  for (const Eigen::Vector3i& t : run.smoothed.triangles) {
    flipped += Normal(run.smoothed, t).dot(Normal(run.plain, t)) > 0.0 ? 0 : 1;
  }
  EXPECT_EQ(flipped, 0u);
  EXPECT_EQ(CountIntersectingPairs(run.plain), 0u);  // the checker sees the Delaunay surface clean
  EXPECT_EQ(CountIntersectingPairs(run.smoothed), 0u);
  const MeshCheckReport check = CheckMesh(run.smoothed);
  EXPECT_TRUE(check.ok) << check.Summary();
}

TEST(Smoothing, NoisyStreetWallsAndGroundGetCloserToTheTruth) {
  const auto drive = testing::NoisyStreet(30, 120, 0.05, 5);
  const SculptRun on = Sculpt(drive, true), off = Sculpt(drive, false);
  // Off: the output is the surface at the Delaunay positions.
  EXPECT_EQ(off.smoothed.vertices, off.plain.vertices);
  EXPECT_EQ(off.smoothed.triangles, off.plain.triangles);
  // Smoothing does not touch T, so both runs carve the same O.
  ASSERT_EQ(on.plain.triangles, off.plain.triangles);
  const auto distance = [](const Eigen::Vector3d& q) { return testing::StreetDistance(q); };
  const double before = RmsError(on.plain, on.plain, distance, 0.25);
  const double after = RmsError(on.smoothed, on.plain, distance, 0.25);
  std::cout << "street: RMS distance of the data vertices to the walls/ground " << before
            << " m -> " << after << " m smoothed\n";
  EXPECT_LT(after, 0.9 * before);  // measured: about 17 % lower
  ExpectSameTrianglesNoFlipNoIntersection(on);
}

// Smoothing every keyframe (the paper's incremental smoothing) and once when the surface is
// taken (the default) give surfaces as close to the truth, both clean.
TEST(Smoothing, EveryKeyframeOrOnceAtTheEndAreAsCloseToTheTruth) {
  const auto drive = testing::NoisyStreet(30, 120, 0.05, 5);
  const SculptRun once = Sculpt(drive, true), every = Sculpt(drive, true, true);
  ASSERT_EQ(once.plain.triangles, every.plain.triangles);
  const auto distance = [](const Eigen::Vector3d& q) { return testing::StreetDistance(q); };
  const double before = RmsError(once.plain, once.plain, distance, 0.25);
  const double after_once = RmsError(once.smoothed, once.plain, distance, 0.25);
  const double after_every = RmsError(every.smoothed, every.plain, distance, 0.25);
  std::cout << "street: RMS distance to the walls/ground " << before << " m -> " << after_once
            << " m smoothed once, " << after_every << " m smoothed every keyframe\n";
  EXPECT_LT(after_every, 0.9 * before);
  EXPECT_LT(after_once, 0.9 * before);
  EXPECT_LT(after_once, 1.05 * after_every);
  EXPECT_NE(once.smoothed.vertices, every.smoothed.vertices);  // two different runs
  ExpectSameTrianglesNoFlipNoIntersection(every);
  ExpectSameTrianglesNoFlipNoIntersection(once);
}

// By default the keyframes only note their vertices: no keyframe smooths, and the first mesh
// taken smooths them all in one run; taking it again smooths nothing more; a mesh taken midway
// (a snapshot: the closed δO and its observed part) smooths what was noted until then, once,
// and the sculpting goes on from there.
TEST(Smoothing, WaitsForTheSurfaceToBeTaken) {
  const auto drive = testing::NoisyStreet(24, 100, 0.05, 21);
  SculptorOptions options;
  options.scale = 1.0;
  ASSERT_FALSE(options.smoothing.every_keyframe);
  IncrementalSculptor sculptor(options);
  size_t candidates = 0, midway_runs = 0;
  for (size_t k = 0; k < drive.size(); ++k) {
    for (const KeyframeStats& st : sculptor.AddKeyframe(drive[k])) {
      EXPECT_EQ(st.smoothed_vertices, 0u);
      EXPECT_EQ(st.ms_smooth, 0.0);
      candidates = st.smoothing_candidates;  // noted and waiting
    }
    if (k == drive.size() / 2) {
      EXPECT_GT(candidates, 0u);
      const TriangleMesh snapshot = sculptor.ExtractMesh();
      const TriangleMesh observed_snapshot = sculptor.ExtractObservedMesh();
      EXPECT_FALSE(observed_snapshot.triangles.empty());
      midway_runs = sculptor.DeferredSmoothingStats().runs;
      EXPECT_EQ(midway_runs, 1u);
      EXPECT_GT(sculptor.DeferredSmoothingStats().vertices, 100u);
      EXPECT_EQ(CountIntersectingPairs(snapshot), 0u);
    }
  }
  const TriangleMesh first = sculptor.ExtractMesh();
  const IncrementalSculptor::DeferredSmoothing after = sculptor.DeferredSmoothingStats();
  EXPECT_EQ(after.runs, midway_runs + 1);
  EXPECT_GT(after.seconds, 0.0);
  const TriangleMesh second = sculptor.ExtractMesh();
  EXPECT_EQ(sculptor.DeferredSmoothingStats().runs, after.runs);  // nothing left to smooth
  EXPECT_EQ(first.vertices, second.vertices);
  ExpectSameTrianglesNoFlipNoIntersection({first, sculptor.triangulation().ExtractSurface()});
  size_t moved = 0;
  const TriangleMesh plain = sculptor.triangulation().ExtractSurface();
  for (size_t i = 0; i < first.vertices.size(); ++i)
    moved += first.vertices[i] != plain.vertices[i];
  EXPECT_GT(moved, first.vertices.size() / 2);
}

TEST(Smoothing, NoisySphereGetsCloserToTheTruth) {
  constexpr double kRadius = 8.0;
  const auto drive = testing::NoisySphere(14, 150, kRadius, 0.05, 9);
  const SculptRun on = Sculpt(drive, true);
  const auto distance = [&](const Eigen::Vector3d& q) { return std::abs(q.norm() - kRadius); };
  const double before = RmsError(on.plain, on.plain, distance, 0.25);
  const double after = RmsError(on.smoothed, on.plain, distance, 0.25);
  std::cout << "sphere: RMS distance of the data vertices to the sphere " << before << " m -> "
            << after << " m smoothed\n";
  EXPECT_LT(after, 0.9 * before);  // measured: about 17 % lower
  ExpectSameTrianglesNoFlipNoIntersection(on);
}

// A street longer than the enclosing ball (r = 12 s, l = 4√3 s): after every keyframe, the
// output positions that changed are all within B_{r+l}(c_t), while surface vertices outside it
// exist.
TEST(Smoothing, MovesNoVertexOutsideTheKeyframeBall) {
  const auto drive = testing::NoisyStreet(45, 80, 0.05, 8);
  SculptorOptions options;
  options.scale = 1.0;
  options.steiner_step_factor = 4.0;
  options.max_ray_length_factor = 12.0;
  options.smoothing.every_keyframe = true;
  const double radius = 12.0 + 4.0 * std::sqrt(3.0);
  IncrementalSculptor sculptor(options);
  std::vector<Eigen::Vector3d> previous;
  size_t moved_inside = 0, moved_outside = 0, surface_outside = 0;
  for (const SurfaceKeyframe& kf : drive) {
    sculptor.AddKeyframe(kf);
    const DelaunayMesh& t = sculptor.triangulation();
    for (size_t i = 0; i < previous.size(); ++i) {
      const Eigen::Vector3d now = sculptor.SurfacePosition(static_cast<int>(i));
      if (now == previous[i]) continue;
      if ((t.Position(static_cast<int>(i)) - kf.centre).norm() < radius) {
        ++moved_inside;
      } else {
        ++moved_outside;
      }
    }
    previous.resize(t.NumVertices());
    for (size_t i = 0; i < previous.size(); ++i) {
      previous[i] = sculptor.SurfacePosition(static_cast<int>(i));
    }
    for (const Eigen::Vector3d& v : sculptor.triangulation().ExtractSurface().vertices) {
      surface_outside += (v - kf.centre).norm() > radius ? 1 : 0;
    }
  }
  EXPECT_EQ(moved_outside, 0u);
  EXPECT_GT(moved_inside, 1000u);
  EXPECT_GT(surface_outside, 1000u);
}

// The fast local intersection checks (δO triangles around each vertex gathered once per keyframe,
// a box filter per triangle pair) against the reference (gathered anew for every check, no
// filter; the fast path also runs the first check of every moved vertex in parallel and keeps
// its result while no position it reads was reverted): after every keyframe, the same smoothed
// position for every vertex and the same counts; and after every keyframe no two triangles of the
// smoothed surface intersect (brute force over all pairs whose boxes meet). (Flips are checked at
// the end of the runs above: a vertex sent back to its previous position by the intersection checks
// is not flip-checked, and a triangle can stay turned for some keyframes.)
void ExpectFastChecksMatchReference(const std::vector<SurfaceKeyframe>& drive, double radius) {
  SculptorOptions fast;
  fast.scale = 1.0;
  fast.steiner_step_factor = 4.0;
  fast.max_ray_length_factor = radius;
  fast.smoothing.every_keyframe = true;  // per keyframe counts to compare
  SculptorOptions reference = fast;
  reference.smoothing.reference_checks = true;
  IncrementalSculptor a(fast), b(reference);
  size_t keyframes = 0, moved = 0, rejected = 0, prechecked = 0, rechecked = 0;
  for (const SurfaceKeyframe& kf : drive) {
    const std::vector<KeyframeStats> sa = a.AddKeyframe(kf), sb = b.AddKeyframe(kf);
    ASSERT_EQ(sa.size(), sb.size());
    for (size_t i = 0; i < sa.size(); ++i) {
      EXPECT_EQ(sa[i].smoothed_vertices, sb[i].smoothed_vertices);
      EXPECT_EQ(sa[i].smoothing_rejected, sb[i].smoothing_rejected);
      EXPECT_EQ(sb[i].smoothing_prechecked, 0u);  // the reference checks one by one
      EXPECT_LE(sa[i].smoothing_rechecked, sa[i].smoothing_prechecked);
      rejected += sa[i].smoothing_rejected;
      prechecked += sa[i].smoothing_prechecked;
      rechecked += sa[i].smoothing_rechecked;
    }
    if (sa.empty()) continue;
    ++keyframes;
    const DelaunayMesh& t = a.triangulation();
    ASSERT_EQ(t.NumVertices(), b.triangulation().NumVertices());
    double worst = 0.0;
    for (size_t i = 0; i < t.NumVertices(); ++i) {
      const Eigen::Vector3d p = a.SurfacePosition(static_cast<int>(i));
      worst = std::max(worst, (p - b.SurfacePosition(static_cast<int>(i))).norm());
      moved += p != t.Position(static_cast<int>(i)) ? 1 : 0;
    }
    EXPECT_LE(worst, 1e-9) << "keyframe " << kf.id.value;
    SCOPED_TRACE("keyframe " + std::to_string(kf.id.value));
    const TriangleMesh smoothed = a.ExtractMesh();
    ASSERT_EQ(smoothed.triangles, t.ExtractSurface().triangles);
    EXPECT_EQ(CountIntersectingPairs(smoothed), 0u);
    MeshCheckOptions empty_allowed;  // δO is still empty after the first keyframes
    empty_allowed.allow_empty = true;
    const MeshCheckReport check = CheckMesh(smoothed, empty_allowed);
    EXPECT_TRUE(check.ok) << check.Summary();
    if (::testing::Test::HasFailure()) return;
  }
  EXPECT_GT(keyframes, 5u);
  EXPECT_GT(moved, 1000u);    // the comparison is not vacuous
  EXPECT_GT(rejected, 0u);    // nor are the intersection checks
  EXPECT_GT(prechecked, 0u);  // nor the parallel first checks
  EXPECT_GT(rechecked, 0u);   // nor the rule that takes a first check again after a revert
}

TEST(Smoothing, FastChecksMatchTheReferenceOnANoisyStreet) {
  ExpectFastChecksMatchReference(testing::NoisyStreet(24, 80, 0.08, 11), 12.0);
}

TEST(Smoothing, FastChecksMatchTheReferenceInANoisySphere) {
  ExpectFastChecksMatchReference(testing::NoisySphere(12, 120, 8.0, 0.08, 13), 12.0);
}

// Same input, same output: two runs give bit-identical smoothed surfaces.
TEST(Smoothing, IsDeterministic) {
  const auto drive = testing::NoisyStreet(20, 80, 0.05, 17);
  const SculptRun first = Sculpt(drive, true), second = Sculpt(drive, true);
  EXPECT_EQ(first.smoothed.triangles, second.smoothed.triangles);
  EXPECT_EQ(first.smoothed.vertices, second.smoothed.vertices);
}

TEST(SmoothingOptions, CheckRejectsBadValues) {
  SmoothingOptions o;
  EXPECT_EQ(o.Check(), "");
  o.mu = -0.4;  // |μ| must exceed λ for a shrink-free filter
  EXPECT_NE(o.Check(), "");
  o = SmoothingOptions();
  o.taubin_steps = -1;
  EXPECT_NE(o.Check(), "");
  SculptorOptions s;
  s.smoothing.lambda = 0.0;
  EXPECT_NE(s.Check(), "");
}

}  // namespace
}  // namespace omni
