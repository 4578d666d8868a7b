// The incremental sculptor (paper §4) on a synthetic street between two walls: after every
// keyframe δO is an oriented 2-manifold by the independent CheckMesh, O ⊆ F, T valid.

#include "surface/sculptor.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <functional>
#include <random>
#include <set>

#include "calib/mesh_check.h"
#include "tests/calib/options_error_check.h"
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

constexpr double kHalfWidth = 8.0;  // walls at y = ±8 m
constexpr double kWallHeight = 10.0;
constexpr double kCamHeight = 2.0;
constexpr double kSpacing = 1.0;  // keyframe spacing, so s = 1

Eigen::Vector3d Centre(int t) { return Eigen::Vector3d(kSpacing * t, 0.0, kCamHeight); }

// Keyframe t: points on the walls and the ground near c_t, each with rays to the keyframes
// t' ≤ t within 12 m (all visible: the street interior is free); noise-free.
std::vector<SurfaceKeyframe> StreetDrive(int num_keyframes, int points_per_keyframe,
                                         uint32_t seed) {
  static_assert(kSpacing == 1.0 && kCamHeight == 2.0, "the street of step6_scenes.h");
  return testing::NoisyStreet(num_keyframes, points_per_keyframe, /*noise=*/0.0, seed, kHalfWidth,
                              kWallHeight);
}

// Generalised winding number of a closed mesh at q (solid angles / 4π). With triangles facing
// the free space, points of O have −1 and points of the matter 0.
double WindingNumber(const TriangleMesh& mesh, const Eigen::Vector3d& q) {
  double sum = 0.0;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]] - q, b = mesh.vertices[t[1]] - q,
                          c = mesh.vertices[t[2]] - q;
    const double la = a.norm(), lb = b.norm(), lc = c.norm();
    const double num = a.dot(b.cross(c));
    const double den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    sum += 2.0 * std::atan2(num, den);
  }
  return sum / (4.0 * M_PI);
}

struct RunSummary {
  size_t points_in = 0, points_filtered = 0, points_added = 0, points_rejected = 0;
  size_t keyframes = 0;
  size_t cells_f = 0, cells_o = 0;
  double sculpt_ms = 0;
  TriangleMesh mesh;
};

RunSummary RunStreet(bool batch_init, EnclosingMode enclosing,
                     const std::vector<SurfaceKeyframe>& drive, int keyframes_per_step = 1) {
  SculptorOptions options;
  options.keyframes_per_step = keyframes_per_step;
  options.init_keyframes = 10;
  options.batch_init = batch_init;
  options.enclosing = enclosing;
  // The Delaunay positions: ExpectStreetCarved counts vertices exactly on the walls (step 6
  // smoothing moves the output vertices).
  options.smoothing.enabled = false;
  // Without batch, s is given so that every keyframe is processed (and checked) on arrival.
  if (!batch_init) options.scale = kSpacing;
  IncrementalSculptor sculptor(options);
  RunSummary run;
  auto account = [&](const std::vector<KeyframeStats>& stats) {
    for (const KeyframeStats& st : stats) {
      run.sculpt_ms += st.ms_total;
      run.cells_f = st.cells_f;
      run.cells_o = st.cells_o;
      if (std::getenv("OMNI_PRINT_STATS")) std::cout << KeyframeStatsCsvRow(st) << "\n";
      EXPECT_EQ(st.keyframes, st.batch ? 10u : static_cast<size_t>(keyframes_per_step))
          << "keyframe " << st.keyframe.value;
      run.keyframes += st.keyframes;
      run.points_in += st.points_in;
      run.points_filtered += st.points_filtered;
      run.points_added += st.points_added;
      run.points_rejected += st.points_rejected;
      EXPECT_EQ(st.points_in,
                st.points_filtered + st.points_added + st.points_rejected + st.points_duplicate);
      EXPECT_GT(st.cells_e, 0u);
      // Never buffered with a batch or a given s: a row per step.
      EXPECT_EQ(stats.size(), 1u);
      // After every keyframe: invariants, T valid, δO an oriented 2-manifold.
      const std::string problems = sculptor.CheckInvariants(true);
      EXPECT_TRUE(problems.empty()) << "keyframe " << st.keyframe.value << ": " << problems;
      const MeshCheckReport report = CheckMesh(sculptor.ExtractMesh(), kEmptyAllowed);
      EXPECT_TRUE(report.ok) << "keyframe " << st.keyframe.value << ": " << report.Summary();
    }
    if (!stats.empty()) {
      EXPECT_EQ(sculptor.ExtractMesh().triangles.size(), stats.back().triangles);
    }
  };
  for (const SurfaceKeyframe& kf : drive) account(sculptor.AddKeyframe(kf));
  account(sculptor.Finish());
  EXPECT_DOUBLE_EQ(sculptor.scale(), kSpacing);
  run.mesh = sculptor.ExtractMesh();
  return run;
}

void ExpectStreetCarved(const RunSummary& run, int num_keyframes, bool centres_in_o) {
  EXPECT_EQ(run.keyframes, static_cast<size_t>(num_keyframes));
  EXPECT_GT(run.mesh.triangles.size(), 500u);
  // The keyframe centres (away from the ends) are in O; points behind the walls or below the
  // ground are not.
  for (int t = 5; t < num_keyframes - 5; t += 7) {
    if (centres_in_o) {
      EXPECT_NEAR(WindingNumber(run.mesh, Centre(t)), -1.0, 1e-6) << "centre " << t;
    }
    EXPECT_NEAR(WindingNumber(run.mesh, Centre(t) + Eigen::Vector3d(0, kHalfWidth + 3, 0)), 0.0,
                1e-6);
    EXPECT_NEAR(WindingNumber(run.mesh, Eigen::Vector3d(t, 1.0, -3.0)), 0.0, 1e-6);
  }
  // The surface lies on the walls and the ground: most of its vertices are data points.
  size_t on_scene = 0;
  for (const Eigen::Vector3d& v : run.mesh.vertices) {
    if (std::abs(std::abs(v.y()) - kHalfWidth) < 1e-9 || std::abs(v.z()) < 1e-9) ++on_scene;
  }
  EXPECT_GT(on_scene, run.mesh.vertices.size() * 9 / 10);
}

TEST(IncrementalSculptor, StreetStaysManifoldAfterEveryKeyframeIncrementalAndBatch) {
  const int n = 40;
  const auto drive = StreetDrive(n, 100, 11);
  struct Mode {
    const char* name;
    bool batch;
    EnclosingMode enclosing;
    int keyframes_per_step;
  };
  for (const Mode& mode :
       {Mode{"batch init, ball E", true, EnclosingMode::kBall, 1},
        Mode{"incremental from start, ball E", false, EnclosingMode::kBall, 1},
        Mode{"incremental from start, ball E, 2 keyframes a step", false, EnclosingMode::kBall, 2},
        Mode{"batch init, conflict-zone E", true, EnclosingMode::kConflictZones, 1},
        // Steps of several keyframes: 30 after the batch of 10 in steps of 3, 40 in steps of 2.
        Mode{"batch init, conflict-zone E, 3 keyframes a step", true, EnclosingMode::kConflictZones,
             3},
        Mode{"incremental from start, conflict-zone E, 2 keyframes a step", false,
             EnclosingMode::kConflictZones, 2}}) {
    SCOPED_TRACE(mode.name);
    const RunSummary run = RunStreet(mode.batch, mode.enclosing, drive, mode.keyframes_per_step);
    const double rejected =
        static_cast<double>(run.points_rejected) /
        static_cast<double>(std::max<size_t>(1, run.points_added + run.points_rejected));
    std::cout << mode.name << ": points in " << run.points_in << ", filtered "
              << run.points_filtered << ", added " << run.points_added << ", rejected "
              << run.points_rejected << " (" << 100.0 * rejected << "%), triangles "
              << run.mesh.triangles.size() << ", |O|/|F| " << run.cells_o << "/" << run.cells_f
              << ", sculpting " << run.sculpt_ms << " ms\n";
    EXPECT_LT(rejected, 0.05);
    EXPECT_GT(run.points_added, run.points_in / 2);
    // With its widening rounds the conflict-zone E carves the keyframe centres too.
    ExpectStreetCarved(run, n, /*centres_in_o=*/true);
  }
}

// Steps of several keyframes: AddKeyframe returns a row only when a step is complete, Finish
// sculpts the last keyframes in a smaller step, and every keyframe is sculpted once.
TEST(IncrementalSculptor, KeyframesInStepsAreEachSculptedOnceAndFinishTakesTheRest) {
  const auto drive = StreetDrive(11, 60, 3);
  SculptorOptions options;
  options.scale = kSpacing;  // no batch: every keyframe in the steps
  options.batch_init = false;
  options.keyframes_per_step = 4;
  IncrementalSculptor sculptor(options);
  std::vector<size_t> step_sizes;
  std::vector<uint32_t> last_keyframes;
  for (size_t k = 0; k < drive.size(); ++k) {
    const std::vector<KeyframeStats> stats = sculptor.AddKeyframe(drive[k]);
    // A step ends with every fourth keyframe, and only then.
    ASSERT_EQ(stats.size(), (k + 1) % 4 == 0 ? 1u : 0u) << "keyframe " << k;
    for (const KeyframeStats& st : stats) {
      step_sizes.push_back(st.keyframes);
      last_keyframes.push_back(st.keyframe.value);
    }
    EXPECT_EQ(sculptor.NumProcessedKeyframes(), (k + 1) / 4 * 4);
  }
  for (const KeyframeStats& st : sculptor.Finish()) {
    step_sizes.push_back(st.keyframes);
    last_keyframes.push_back(st.keyframe.value);
  }
  EXPECT_EQ(step_sizes, (std::vector<size_t>{4, 4, 3}));
  EXPECT_EQ(last_keyframes,
            (std::vector<uint32_t>{drive[3].id.value, drive[7].id.value, drive[10].id.value}));
  EXPECT_EQ(sculptor.NumProcessedKeyframes(), drive.size());
  EXPECT_TRUE(sculptor.Finish().empty());
  const std::string problems = sculptor.CheckInvariants(true);
  EXPECT_TRUE(problems.empty()) << problems;
  EXPECT_TRUE(CheckMesh(sculptor.ExtractMesh()).ok);
}

// The three ways of re-tracing old rays over N (§4.4) give the same F, O and surface on the
// street: every old ray walked whole (brute force), the rays found by the ray grid walked whole,
// and those rays walked only over N from the border crossings.
TEST(IncrementalSculptor, OldRayModesGiveTheSameSculpture) {
  const auto drive = StreetDrive(24, 80, 5);
  std::vector<std::vector<KeyframeStats>> runs;
  std::vector<TriangleMesh> meshes;
  for (OldRayTracing mode :
       {OldRayTracing::kAllRays, OldRayTracing::kWholeWalks, OldRayTracing::kNewCellRuns}) {
    SculptorOptions options;
    options.scale = kSpacing;
    options.init_keyframes = 8;
    options.enclosing = EnclosingMode::kConflictZones;
    options.old_rays = mode;
    IncrementalSculptor sculptor(options);
    runs.emplace_back();
    for (const SurfaceKeyframe& kf : drive) {
      for (const KeyframeStats& st : sculptor.AddKeyframe(kf)) runs.back().push_back(st);
    }
    meshes.push_back(sculptor.ExtractMesh());
  }
  size_t all = 0, grid = 0, runs_walked = 0, cells_all = 0, cells_runs = 0;
  for (size_t m = 1; m < runs.size(); ++m) {
    ASSERT_EQ(runs[0].size(), runs[m].size());
    for (size_t k = 0; k < runs[0].size(); ++k) {
      EXPECT_EQ(runs[0][k].cells_f, runs[m][k].cells_f) << "mode " << m << " keyframe " << k;
      EXPECT_EQ(runs[0][k].cells_o, runs[m][k].cells_o) << "mode " << m << " keyframe " << k;
    }
    EXPECT_EQ(meshes[0].triangles, meshes[m].triangles);
    EXPECT_EQ(meshes[0].vertices, meshes[m].vertices);
  }
  for (size_t k = 0; k < runs[0].size(); ++k) {
    all += runs[0][k].rays_old;
    grid += runs[1][k].rays_old;
    runs_walked += runs[2][k].rays_old;
    cells_all += runs[0][k].old_walk_cells;
    cells_runs += runs[2][k].old_walk_cells;
    // The grid's candidates are the rays the whole-walk mode walks.
    EXPECT_EQ(runs[1][k].rays_old, runs[1][k].rays_old_candidates);
    EXPECT_EQ(runs[1][k].rays_old_candidates, runs[2][k].rays_old_candidates);
  }
  std::cout << "old rays walked: all " << all << ", grid candidates " << grid << ", crossing N "
            << runs_walked << "; cells visited: all " << cells_all << ", runs " << cells_runs
            << "\n";
  EXPECT_GT(runs_walked, 0u);
  EXPECT_LE(runs_walked, grid);
  EXPECT_LT(grid, all);              // the grid leaves rays out
  EXPECT_LT(cells_runs, cells_all);  // and the runs skip cells
}

// The ray grid and the border runs of old rays (§4.4) give exactly the per-cell counters of the
// brute force (every old ray walked whole from its point), after every keyframe of a random
// stream (points scattered in a box, rays to random earlier keyframes): the grid's candidate
// rays include every old ray that crosses N, and the runs visit exactly its N cells.
// A random stream of 16 keyframes, 60 points each (some on common planes, which give degenerate
// crossings of N's border); near_copies: every third point also comes again 1-2.5 cm away in the
// next keyframe with that keyframe's rays (a point the separation merges into a vertex).
std::vector<SurfaceKeyframe> RandomOldRayStream(bool near_copies) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<SurfaceKeyframe> stream;
  uint32_t next_point = 0;
  for (int t = 0; t < 16; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(t);
    kf.centre = Eigen::Vector3d(t + 0.3 * u(rng), 0.5 * u(rng), 1.5 + 0.5 * u(rng));
    for (int i = 0; i < 60; ++i) {
      SurfacePoint p;
      p.id = PointId(next_point++);
      p.position =
          kf.centre + Eigen::Vector3d(12.0 * u(rng) - 4.0, 16.0 * u(rng) - 8.0, 6.0 * u(rng) - 1.5);
      // Some points on the planes of earlier ones (degenerate crossings of N's border).
      if (i % 5 == 0) p.position.z() = 0.0;
      if (i % 7 == 0) p.position.y() = 8.0;
      for (int k = std::max(0, t - 6); k < t; ++k) {
        if (u(rng) < 0.4) p.rays.push_back({KeyframeId(k), stream[k].centre});
      }
      p.rays.push_back({kf.id, kf.centre});
      kf.points.push_back(p);
    }
    if (near_copies && t > 0) {
      const std::vector<SurfacePoint>& before = stream.back().points;
      for (size_t i = 0; i < before.size(); i += 3) {
        SurfacePoint copy = before[i];
        copy.id = PointId(next_point++);
        copy.position += 0.01 * Eigen::Vector3d(1.0 + u(rng), u(rng), u(rng));
        copy.rays = {{kf.id, kf.centre}, {KeyframeId(t - 1), stream.back().centre}};
        kf.points.push_back(copy);
      }
    }
    stream.push_back(kf);
  }
  return stream;
}

// Old rays walked over N only (the border index) against every old ray walked whole: the same
// counters in every cell after every keyframe. Returns the points merged into a vertex.
size_t ExpectOldRaysGiveTheBruteForceCounters(const std::vector<SurfaceKeyframe>& stream,
                                              SculptorOptions options) {
  options.scale = 1.0;
  options.filter_points = false;
  options.ray_grid_step_factor = 1.5;
  options.old_rays = OldRayTracing::kAllRays;
  IncrementalSculptor brute(options);
  options.old_rays = OldRayTracing::kNewCellRuns;
  IncrementalSculptor fast(options);
  size_t old_rays = 0, compared = 0, candidates = 0, facets = 0, uncrossed = 0, queries = 0,
         facet_tests = 0, merged = 0;
  for (const SurfaceKeyframe& kf : stream) {
    const std::vector<KeyframeStats> a = brute.AddKeyframe(kf), b = fast.AddKeyframe(kf);
    EXPECT_EQ(a.size(), 1u);
    EXPECT_EQ(b.size(), 1u);
    if (a.size() != 1u || b.size() != 1u) return merged;
    old_rays += a[0].rays_old;
    candidates += b[0].rays_old_candidates;
    facets += b[0].old_ray_facets;
    uncrossed += b[0].old_ray_facets_uncrossed;
    merged += b[0].points_merged;
    EXPECT_EQ(a[0].points_merged, b[0].points_merged);
    EXPECT_LE(b[0].rays_old, b[0].rays_old_candidates);
    // Every candidate asks the border index for its crossings (when N has a border to cross).
    if (b[0].old_ray_facets > 0) {
      EXPECT_EQ(b[0].old_ray_queries, b[0].rays_old_candidates);
    }
    EXPECT_LE(b[0].old_ray_plane_passes, b[0].old_ray_facet_tests);
    queries += b[0].old_ray_queries;
    facet_tests += b[0].old_ray_facet_tests;
    std::vector<CellKey> cells = brute.triangulation().FiniteCells();
    std::vector<CellKey> cells_fast = fast.triangulation().FiniteCells();
    std::sort(cells.begin(), cells.end());
    std::sort(cells_fast.begin(), cells_fast.end());
    EXPECT_EQ(cells, cells_fast) << "keyframe " << kf.id.value;
    if (cells != cells_fast) return merged;
    for (const CellKey& c : cells) {
      EXPECT_EQ(brute.triangulation().Counter(c), fast.triangulation().Counter(c))
          << "keyframe " << kf.id.value;
      if (brute.triangulation().Counter(c) != fast.triangulation().Counter(c)) return merged;
      compared += brute.triangulation().Counter(c) > 0 ? 1 : 0;
    }
    EXPECT_EQ(a[0].cells_o, b[0].cells_o);
    EXPECT_EQ(a[0].triangles, b[0].triangles);
  }
  EXPECT_GT(old_rays, 1000u);
  EXPECT_LT(candidates, old_rays);
  EXPECT_GT(compared, 1000u);
  // The border facets whose outer cell no ray crossed were left out, and the counters are still
  // exact.
  std::cout << "border facets of N indexed " << facets << ", left out uncrossed " << uncrossed
            << "\n";
  EXPECT_GT(facets, 0u);
  EXPECT_GT(uncrossed, facets / 10);
  EXPECT_GT(queries, 0u);
  EXPECT_GT(facet_tests, 0u);
  return merged;
}

TEST(IncrementalSculptor, OldRayTracingGivesTheBruteForceCountersOnARandomStream) {
  SculptorOptions options;
  options.pixel_angle = 0.0;  // no merging: every point is its own vertex
  EXPECT_EQ(ExpectOldRaysGiveTheBruteForceCounters(RandomOldRayStream(false), options), 0u);
}

// Points merged into a vertex: their rays are walked from it, as old rays too (a ray of a
// merged point starting in N is found through the vertex's other points).
TEST(IncrementalSculptor, OldRaysOfPointsMergedIntoAVertexGiveTheBruteForceCounters) {
  SculptorOptions options;
  options.min_point_separation_factor = 0.05;  // s = 1: 5 cm, the copies are 1-2.5 cm away
  const std::vector<SurfaceKeyframe> stream = RandomOldRayStream(true);
  EXPECT_GT(ExpectOldRaysGiveTheBruteForceCounters(stream, options), 15u * 20u / 2u);
}

// Paper §5.1 filters, with s = 1: below the ground by more than 3 s, farther than 15 s from the
// keyframe centre, or no two rays more than 10° apart.
TEST(IncrementalSculptor, PointFiltersOfSection51) {
  SculptorOptions options;
  options.scale = 1.0;
  options.ground_quantile = 0.0;  // the paper's ground bound, 3 s
  IncrementalSculptor sculptor(options);
  SurfaceKeyframe kf;
  kf.id = KeyframeId(0);
  kf.centre = Eigen::Vector3d(0, 0, 2);
  const Eigen::Vector3d left(-1.5, 0, 2), right(1.5, 0, 2);
  auto point = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& o1, const Eigen::Vector3d& o2) {
    SurfacePoint sp;
    sp.id = PointId(static_cast<uint32_t>(kf.points.size()));
    sp.position = p;
    sp.rays = {{KeyframeId(0), o1}, {KeyframeId(0), o2}};
    kf.points.push_back(sp);
  };
  point({0, 5, 1}, left, right);     // kept: 33° aperture
  point({0.5, 6, 0}, left, right);   // kept
  point({0, 5, -1.5}, left, right);  // (p − c)·up = −3.5 < −3 s: filtered
  point({0, 5, -2}, left, right);    // (p − c)·up = −4 < −3: filtered
  point({0, 16, 2}, left, right);    // 16 > 15 s: filtered
  point({0, 10, 2}, left, left + Eigen::Vector3d(0.5, 0, 0));  // 2.9°: filtered
  const std::vector<KeyframeStats> stats = sculptor.AddKeyframe(kf);
  ASSERT_EQ(stats.size(), 1u);
  EXPECT_EQ(stats[0].points_filtered, 4u);
  EXPECT_EQ(stats[0].points_filtered_ground, 2u);
  EXPECT_EQ(stats[0].points_filtered_length, 1u);
  EXPECT_EQ(stats[0].points_filtered_aperture, 1u);
  EXPECT_EQ(stats[0].points_invalid, 0u);
  EXPECT_EQ(stats[0].points_added, 2u);
  EXPECT_EQ(sculptor.CheckInvariants(), "");
}

// The aperture bound: a point whose two rays are 7.6° apart passes the default (5°) and is
// dropped by the paper's 10°; one at 2.9° is dropped by both.
TEST(IncrementalSculptor, ApertureFilterKeepsNarrowerTriangulationsThanThePaper) {
  auto added_and_filtered = [](double min_aperture_deg) {
    SculptorOptions options;
    options.scale = 1.0;
    options.min_aperture_deg = min_aperture_deg;
    IncrementalSculptor sculptor(options);
    SurfaceKeyframe kf;
    kf.id = KeyframeId(0);
    kf.centre = Eigen::Vector3d(0, 0, 2);
    const Eigen::Vector3d left(-0.5, 0, 2), right(0.5, 0, 2);
    auto point = [&](const Eigen::Vector3d& p, const Eigen::Vector3d& o1,
                     const Eigen::Vector3d& o2) {
      SurfacePoint sp;
      sp.id = PointId(static_cast<uint32_t>(kf.points.size()));
      sp.position = p;
      sp.rays = {{KeyframeId(0), o1}, {KeyframeId(0), o2}};
      kf.points.push_back(sp);
    };
    point({0, 5, 1}, {-3, 0, 2}, {3, 0, 2});                     // 62°: kept by both
    point({0.5, 6, 0}, {-3, 0, 2}, {3, 0, 2});                   // wide: kept by both
    point({0, 7.5, 2}, left, right);                             // 7.6°
    point({0, 10, 2}, left, left + Eigen::Vector3d(0.5, 0, 0));  // 2.9°
    const std::vector<KeyframeStats> stats = sculptor.AddKeyframe(kf);
    EXPECT_EQ(sculptor.CheckInvariants(), "");
    return std::make_pair(stats.at(0).points_added, stats.at(0).points_filtered_aperture);
  };
  EXPECT_EQ(SculptorOptions().min_aperture_deg, 5.0);
  const auto by_default = added_and_filtered(SculptorOptions().min_aperture_deg);
  const auto paper = added_and_filtered(10.0);
  EXPECT_EQ(by_default.first, 3u);
  EXPECT_EQ(by_default.second, 1u);
  EXPECT_EQ(paper.first, 2u);
  EXPECT_EQ(paper.second, 2u);
}

// Keyframes 0.5 m apart along x, 4 m above a ground; points on the ground and on two facades
// 10 m to each side, within 8 m along x, seen from origins 3 m apart.
std::vector<SurfaceKeyframe> StreetStream(int keyframes, std::vector<double> extra_heights = {}) {
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<SurfaceKeyframe> stream;
  uint32_t id = 0;
  for (int t = 0; t < keyframes; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(t);
    kf.centre = Eigen::Vector3d(0.5 * t, 0, 4);
    auto add = [&](const Eigen::Vector3d& p) {
      SurfacePoint sp;
      sp.id = PointId(id++);
      sp.position = p;
      sp.rays = {{kf.id, kf.centre - Eigen::Vector3d(1.5, 0, 0)},
                 {kf.id, kf.centre + Eigen::Vector3d(1.5, 0, 0)}};
      kf.points.push_back(sp);
    };
    for (int i = 0; i < 60; ++i) {
      const double x = kf.centre.x() - 8.0 + 16.0 * u(rng);
      const double side = i % 2 == 0 ? -10.0 : 10.0;
      if (i % 3 == 0) {
        add({x, side * u(rng), 0.0});  // the ground
      } else {
        add({x, side, 8.0 * u(rng)});  // a facade
      }
    }
    for (double h : extra_heights) add({kf.centre.x(), 3.0, h});
    stream.push_back(kf);
  }
  return stream;
}

// The stats of every keyframe of the stream.
std::vector<KeyframeStats> Sculpt(IncrementalSculptor& sculptor,
                                  const std::vector<SurfaceKeyframe>& stream) {
  std::vector<KeyframeStats> all;
  for (const SurfaceKeyframe& kf : stream) {
    for (const KeyframeStats& st : sculptor.AddKeyframe(kf)) all.push_back(st);
  }
  for (const KeyframeStats& st : sculptor.Finish()) all.push_back(st);
  return all;
}

TEST(IncrementalSculptor, TheScaleFollowsThePointsReachAndTheGroundItsDepth) {
  const std::vector<SurfaceKeyframe> stream = StreetStream(8);
  SculptorOptions paper;
  paper.init_keyframes = 8;
  paper.reach_quantile = 0.0;
  paper.ground_quantile = 0.0;
  IncrementalSculptor spacing(paper);
  size_t paper_far = 0, paper_ground = 0;
  for (const KeyframeStats& st : Sculpt(spacing, stream)) {
    paper_far += st.points_filtered_length;
    paper_ground += st.points_filtered_ground;
  }
  EXPECT_NEAR(spacing.scale(), 0.5, 1e-12);  // the keyframe spacing: r = 7.5 m, ground 1.5 m
  EXPECT_GT(paper_far, 100u);
  EXPECT_GT(paper_ground, 100u);

  SculptorOptions measured = paper;
  measured.reach_quantile = SculptorOptions().reach_quantile;
  measured.ground_quantile = SculptorOptions().ground_quantile;
  IncrementalSculptor reach(measured);
  size_t far = 0, ground = 0;
  for (const KeyframeStats& st : Sculpt(reach, stream)) {
    far += st.points_filtered_length;
    ground += st.points_filtered_ground;
  }
  EXPECT_NEAR(reach.keyframe_spacing(), 0.5, 1e-12);
  // The farthest points are 13.4 m away (8 m along, 10 m across, 4 m down or up): s about
  // 13 / 15.
  EXPECT_GT(reach.scale(), 0.75);
  EXPECT_LT(reach.scale(), 0.9);
  EXPECT_NEAR(reach.ray_length_bound(), 15.0 * reach.scale(), 1e-9);
  EXPECT_LT(far, paper_far / 10);
  EXPECT_EQ(ground, 0u);
  // The ground 4 m down, plus s.
  EXPECT_NEAR(reach.ground_bound(), 4.0 + reach.scale(), 0.05);
}

TEST(IncrementalSculptor, PointsFarBelowTheMeasuredGroundAreFiltered) {
  // One point per keyframe 0.5 m below the ground (kept) and one 3 m below it (filtered).
  const std::vector<SurfaceKeyframe> stream = StreetStream(8, {-0.5, -3.0});
  SculptorOptions options;
  options.init_keyframes = 8;
  IncrementalSculptor sculptor(options);
  size_t ground = 0;
  for (const KeyframeStats& st : Sculpt(sculptor, stream)) ground += st.points_filtered_ground;
  EXPECT_EQ(ground, 8u);
}

// Free rays (the sky) carve the cells they cross: more of F, O still bounded by a closed
// 2-manifold; ignored with free_ray_length_factor 0.
TEST(IncrementalSculptor, FreeRaysCarveTheCellsTheyCross) {
  std::vector<SurfaceKeyframe> stream = StreetStream(12);
  size_t free_rays = 0;
  for (SurfaceKeyframe& kf : stream) {
    for (int i = 0; i < 40; ++i) {  // a fan upwards across the street, over the facades
      const double a = -1.2 + 2.4 * i / 39.0;
      kf.free_rays.push_back(
          {kf.centre, Eigen::Vector3d(0.2 * std::sin(3.0 * a), std::sin(a), std::cos(a))});
      ++free_rays;
    }
  }
  auto sculpt = [&](double length, size_t* traced, size_t* cells) {
    SculptorOptions options;
    options.init_keyframes = 6;  // a batch of 6, then 6 one by one
    options.free_ray_length_factor = length;
    IncrementalSculptor sculptor(options);
    *traced = *cells = 0;
    size_t cells_f = 0;
    for (const KeyframeStats& st : Sculpt(sculptor, stream)) {
      *traced += st.rays_free;
      *cells += st.free_ray_cells;
      cells_f = st.cells_f;
    }
    EXPECT_EQ(sculptor.CheckInvariants(), "") << "length " << length;
    const MeshCheckReport report = CheckMesh(sculptor.ExtractMesh());
    EXPECT_TRUE(report.ok) << "length " << length << ": " << report.Summary();
    return cells_f;
  };
  size_t traced = 0, cells = 0;
  const size_t without = sculpt(0.0, &traced, &cells);
  EXPECT_EQ(traced, 0u);
  EXPECT_EQ(cells, 0u);
  const size_t with = sculpt(1.0, &traced, &cells);
  EXPECT_EQ(traced, free_rays);
  EXPECT_GT(cells, free_rays);
  EXPECT_GT(with, without);
}

// The rays of the points that the aperture filter drops carve short of them, up to
// 1 − margin / aperture of the way: exactly the rays of the points with that fraction at least
// uncertain_ray_min_fraction. Here a wall across the street 12 m ahead of each keyframe, seen
// from origins 0.2 m apart (0.6° to 1°). O stays bounded by a closed 2-manifold with the space
// behind the facades matter; in one batch (the same T whatever the margin) a smaller margin
// walks longer segments of the same rays, so over more cells. None with the margin 0 (the
// default).
TEST(IncrementalSculptor, TheRaysOfPointsWithANarrowApertureCarveShortOfThem) {
  std::vector<SurfaceKeyframe> stream = StreetStream(12);
  std::vector<double> apertures;  // of the wall's points, radians
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  uint32_t id = 100000;
  for (SurfaceKeyframe& kf : stream) {
    for (int i = 0; i < 20; ++i) {
      SurfacePoint p;
      p.id = PointId(id++);
      p.position = kf.centre + Eigen::Vector3d(12.0, -6.0 + 12.0 * u(rng), -4.0 + 8.0 * u(rng));
      p.rays = {{kf.id, kf.centre}, {kf.id, kf.centre + Eigen::Vector3d(0, 0.2, 0)}};
      const Eigen::Vector3d a = (p.rays[0].origin - p.position).normalized();
      const Eigen::Vector3d b = (p.rays[1].origin - p.position).normalized();
      apertures.push_back(std::acos(a.dot(b)));
      kf.points.push_back(p);
    }
  }
  auto sculpt = [&](double margin_deg, int init_keyframes, size_t* filtered, size_t* rays,
                    size_t* cells) {
    SculptorOptions options;
    options.scale = 1.0;  // r = 15 m: no point is too far
    options.init_keyframes = init_keyframes;
    options.batch_with_known_scale = true;
    options.uncertain_ray_margin_deg = margin_deg;
    IncrementalSculptor sculptor(options);
    *filtered = *rays = *cells = 0;
    for (const KeyframeStats& st : Sculpt(sculptor, stream)) {
      *filtered += st.points_filtered_aperture;
      *rays += st.rays_uncertain;
      *cells += st.uncertain_ray_cells;
    }
    EXPECT_EQ(sculptor.CheckInvariants(), "") << "margin " << margin_deg;
    const TriangleMesh mesh = sculptor.ExtractMesh();
    const MeshCheckReport report = CheckMesh(mesh);
    EXPECT_TRUE(report.ok) << "margin " << margin_deg << ": " << report.Summary();
    for (double x : {1.0, 2.5, 4.0}) {  // behind the facades: matter
      EXPECT_NEAR(WindingNumber(mesh, Eigen::Vector3d(x, 10.5, 3.0)), 0.0, 1e-6);
      EXPECT_NEAR(WindingNumber(mesh, Eigen::Vector3d(x, -10.5, 3.0)), 0.0, 1e-6);
    }
  };
  size_t filtered = 0, rays = 0, cells = 0;
  sculpt(0.0, 6, &filtered, &rays, &cells);  // a batch of 6, then 6 one by one
  EXPECT_EQ(filtered, apertures.size());
  EXPECT_EQ(rays, 0u);
  EXPECT_EQ(cells, 0u);
  const double margin_deg = 0.6;
  size_t expected_rays = 0;
  for (double aperture : apertures) {
    const double fraction = 1.0 - margin_deg * M_PI / 180.0 / aperture;
    if (fraction >= SculptorOptions().uncertain_ray_min_fraction) expected_rays += 2;
  }
  ASSERT_GT(expected_rays, 0u);
  ASSERT_LT(expected_rays, 2 * apertures.size());  // some are too uncertain to carve
  sculpt(margin_deg, 6, &filtered, &rays, &cells);
  EXPECT_EQ(filtered, apertures.size());
  EXPECT_EQ(rays, expected_rays);
  EXPECT_GT(cells, rays);
  size_t rays_wide = 0, cells_wide = 0, rays_narrow = 0, cells_narrow = 0;
  sculpt(margin_deg, 12, &filtered, &rays_wide, &cells_wide);
  sculpt(margin_deg / 2, 12, &filtered, &rays_narrow, &cells_narrow);
  EXPECT_EQ(rays_wide, expected_rays);
  EXPECT_EQ(rays_narrow, 2 * apertures.size());
  EXPECT_GT(cells_narrow, cells_wide + (rays_narrow - rays_wide));
}

// The point and ray counts of a sculpting, summed over its steps.
struct PointCounts {
  size_t duplicates = 0, merged = 0, added = 0, rays = 0;
};

// Sculpts the drive (10 keyframes in the batch) and sums its steps' counts; `after` reads the
// finished sculptor, whose invariants hold.
PointCounts SculptCountingPoints(const std::vector<SurfaceKeyframe>& drive, SculptorOptions options,
                                 const std::function<void(const IncrementalSculptor&)>& after) {
  options.init_keyframes = 10;
  IncrementalSculptor sculptor(options);
  PointCounts counts;
  auto count = [&counts](const std::vector<KeyframeStats>& stats) {
    for (const KeyframeStats& st : stats) {
      counts.duplicates += st.points_duplicate;
      counts.merged += st.points_merged;
      counts.added += st.points_added;
      counts.rays += st.rays_new;
    }
  };
  for (const SurfaceKeyframe& kf : drive) count(sculptor.AddKeyframe(kf));
  count(sculptor.Finish());
  EXPECT_EQ(sculptor.CheckInvariants(), "");
  after(sculptor);
  return counts;
}

// A quarter of the street's points come twice, 4 nm apart (as in a COLMAP model): by default
// each twin is the vertex of its original (a duplicate), so no two vertices of T share a
// position once rounded to the float coordinates of a PLY file, and δO written as floats is
// still a closed 2-manifold without zero-area triangles; without the separation both twins are
// vertices and collapse in float.
TEST(IncrementalSculptor, PointsCloserThanTheSeparationAreOneVertex) {
  std::vector<SurfaceKeyframe> drive = testing::NoisyStreet(20, 80, 0.02, 5);
  size_t twins = 0;
  for (SurfaceKeyframe& kf : drive) {
    const size_t n = kf.points.size();
    for (size_t i = 0; i < n; i += 4) {
      SurfacePoint twin = kf.points[i];
      twin.id = PointId(static_cast<uint32_t>(1000000 + twins++));
      twin.position += Eigen::Vector3d(3e-9, -2e-9, 1e-9);
      kf.points.push_back(twin);
    }
  }
  struct Run {
    PointCounts counts;
    size_t float_collisions = 0;
    TriangleMesh closed;
  };
  auto run = [&drive](double separation_factor) {
    SculptorOptions options;
    options.min_point_separation_factor = separation_factor;
    Run r;
    r.counts = SculptCountingPoints(drive, options, [&r](const IncrementalSculptor& sculptor) {
      std::set<std::array<float, 3>> positions;
      const DelaunayMesh& tri = sculptor.triangulation();
      for (size_t v = 0; v < tri.NumVertices(); ++v) {
        const Eigen::Vector3f q = tri.Position(static_cast<int>(v)).cast<float>();
        r.float_collisions += !positions.insert({q.x(), q.y(), q.z()}).second;
      }
      r.closed = sculptor.ExtractMesh();
      for (Eigen::Vector3d& q : r.closed.vertices) q = q.cast<float>().cast<double>();
    });
    return r;
  };
  const Run merged = run(SculptorOptions().min_point_separation_factor);
  const Run apart = run(0.0);
  EXPECT_GE(merged.counts.duplicates, twins / 2) << twins << " twins";
  EXPECT_EQ(merged.float_collisions, 0u);
  const MeshCheckReport report = CheckMesh(merged.closed);
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_EQ(apart.counts.duplicates, 0u);
  EXPECT_GT(apart.counts.added, merged.counts.added);
  EXPECT_GE(apart.float_collisions, merged.counts.duplicates / 2);
}

// The separation in pixels: with a pixel of 10⁻⁴ rad, a twin 1.5 mm from a point seen from 5 m
// or more is less than 3 pixels from it, so it is that vertex; its two rays are traced from the
// vertex (or dropped with duplicate_rays off). Without pixel_angle (unknown camera) only the
// factor of s holds (1 mm), and the twins are vertices of their own.
TEST(IncrementalSculptor, PointsAFewPixelsApartAreOneVertexThatKeepsTheirRays) {
  std::vector<SurfaceKeyframe> drive = testing::NoisyStreet(20, 80, 0.02, 5);
  size_t twins = 0;
  for (size_t t = 1; t < drive.size(); ++t) {
    SurfaceKeyframe& kf = drive[t];
    const size_t n = kf.points.size();
    for (size_t i = 0; i < n; i += 4) {
      SurfacePoint twin = kf.points[i];
      twin.id = PointId(static_cast<uint32_t>(1000000 + twins++));
      twin.position += Eigen::Vector3d(0.0015, 0.0, 0.0);
      twin.rays = {{kf.id, kf.centre}, {drive[t - 1].id, drive[t - 1].centre}};
      kf.points.push_back(twin);
    }
  }
  struct Run {
    PointCounts counts;
    TriangleMesh observed;
  };
  auto run = [&drive](double pixel_angle, bool duplicate_rays) {
    SculptorOptions options;
    options.pixel_angle = pixel_angle;
    options.min_point_separation_pixels = 3.0;
    options.duplicate_rays = duplicate_rays;
    Run r;
    r.counts = SculptCountingPoints(drive, options, [&r](const IncrementalSculptor& sculptor) {
      r.observed = sculptor.ExtractObservedMesh();
    });
    return r;
  };
  const Run kept = run(1e-4, true), dropped = run(1e-4, false), unknown = run(0.0, true);
  EXPECT_GE(kept.counts.duplicates, twins / 4) << twins << " twins";
  EXPECT_LE(kept.counts.duplicates, twins);
  EXPECT_EQ(kept.counts.merged, kept.counts.duplicates);
  EXPECT_EQ(dropped.counts.merged, 0u);
  EXPECT_EQ(dropped.counts.duplicates, kept.counts.duplicates);
  EXPECT_EQ(dropped.counts.added, kept.counts.added);
  // Every ray is traced whether its point is a vertex of its own or merged into one (a twin, or
  // the original when its twin came first); dropping loses at least one ray per merged point.
  EXPECT_EQ(kept.counts.rays, unknown.counts.rays);
  EXPECT_GE(kept.counts.rays, dropped.counts.rays + kept.counts.merged);
  EXPECT_EQ(unknown.counts.duplicates, 0u);
  EXPECT_EQ(unknown.counts.added, kept.counts.added + kept.counts.duplicates);
  MeshCheckOptions bounded;
  bounded.allow_boundary = true;
  const MeshCheckReport report = CheckMesh(kept.observed, bounded);
  EXPECT_TRUE(report.ok) << report.Summary();
  EXPECT_GT(kept.observed.triangles.size(), 100u);
}

TEST(SculptorOptions, CheckRejectsBadValues) {
  SculptorOptions o;
  EXPECT_EQ(o.Check(), "");
  o.steiner_step_factor = 0.0;
  EXPECT_NE(o.Check(), "");
  o = SculptorOptions();
  o.init_keyframes = 1;
  EXPECT_NE(o.Check(), "");
  o.scale = 2.0;
  EXPECT_EQ(o.Check(), "");
  o.min_aperture_deg = 180.0;
  EXPECT_NE(o.Check(), "");
  o = SculptorOptions();
  o.keyframes_per_step = 0;
  EXPECT_NE(o.Check().find("keyframes_per_step"), std::string::npos);
  o.keyframes_per_step = 65;
  EXPECT_NE(o.Check().find("keyframes_per_step"), std::string::npos);
  o.keyframes_per_step = 3;
  EXPECT_EQ(o.Check(), "");
  o = SculptorOptions();
  o.uncertain_ray_margin_deg = -0.1;
  EXPECT_NE(o.Check().find("uncertain_ray_margin_deg"), std::string::npos);
  o = SculptorOptions();
  o.uncertain_ray_min_fraction = 1.0;
  EXPECT_NE(o.Check().find("uncertain_ray_min_fraction"), std::string::npos);
  o.uncertain_ray_min_fraction = 0.0;
  EXPECT_NE(o.Check().find("uncertain_ray_min_fraction"), std::string::npos);
  o = SculptorOptions();
  o.min_point_separation_factor = -1e-3;
  EXPECT_NE(o.Check().find("min_point_separation_factor"), std::string::npos);
  o = SculptorOptions();
  o.min_point_separation_pixels = -1.0;
  EXPECT_NE(o.Check().find("min_point_separation_pixels"), std::string::npos);
  o = SculptorOptions();
  o.pixel_angle = 0.2;
  EXPECT_NE(o.Check().find("pixel_angle"), std::string::npos);
  o.min_aperture_deg = 180.0;
  EXPECT_THROW(IncrementalSculptor{o}, std::invalid_argument);
}

TEST(IncrementalSculptor, BadOptionsThrowNamingTheField) {
  SculptorOptions o;
  o.init_keyframes = 0;
  EXPECT_THROW(IncrementalSculptor{o}, OptionsError);
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { IncrementalSculptor sculptor(o); },
                                          "SculptorOptions.init_keyframes"));
  o = SculptorOptions();
  o.smoothing.lambda = 2.0;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { IncrementalSculptor sculptor(o); },
                                          "SculptorOptions.smoothing.lambda"));
  o = SculptorOptions();
  o.genus.max_group_cells = -1;
  EXPECT_TRUE(testing::ThrowsOptionsError([&] { IncrementalSculptor sculptor(o); },
                                          "SculptorOptions.genus.max_group_cells"));
}

}  // namespace
}  // namespace omni
