// The tight enclosing set (EnclosingMode::kConflictZones): E is the union of the new
// points' conflict zones plus a margin, widened after the shrink where O still meets them. After
// every keyframe of a clean street (the tiny drive of sculptor_test.cpp) and of a noisy one, δO
// is an oriented 2-manifold by the independent CheckMesh and O ⊆ F; no point is inserted
// with its conflict zone meeting O (a brute-force recount over O); and the rejected share stays
// below a bound that the conflict-zone E without widening (enclosing_rounds = 0) exceeds.

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
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

struct TightRun {
  size_t added = 0, rejected = 0, keyframes_checked = 0, meeting_o = 0, rounds = 0;
  size_t triangles = 0, cells_o = 0, cells_f = 0, keyframes = 0;
  double RejectedShare() const {
    return static_cast<double>(rejected) /
           static_cast<double>(std::max<size_t>(1, added + rejected));
  }
};

// Sculpts the drive in the tight mode with `rounds` widening rounds, or with the ball when
// rounds < 0 (the first 10 keyframes in one batch, s measured = 1), checking δO and O ⊆ F after
// every keyframe when `check` is set.
TightRun RunTight(const std::vector<SurfaceKeyframe>& drive, int rounds, bool check,
                  SculptorOptions options = {}) {
  options.init_keyframes = 10;
  if (rounds >= 0) {
    options.enclosing = EnclosingMode::kConflictZones;
    options.enclosing_rounds = rounds;
  } else {
    options.enclosing = EnclosingMode::kBall;
  }
  options.verify_insertions = check;
  IncrementalSculptor sculptor(options);
  TightRun run;
  auto account = [&](const std::vector<KeyframeStats>& stats) {
    for (const KeyframeStats& st : stats) {
      run.added += st.points_added;
      run.rejected += st.points_rejected;
      run.meeting_o += st.insertions_meeting_o;
      run.rounds += st.enclose_rounds;
      run.triangles = st.triangles;
      run.cells_o = st.cells_o;
      run.cells_f = st.cells_f;
      run.keyframes += st.batch ? 0 : 1;
      EXPECT_LE(st.enclose_rounds, static_cast<size_t>(std::max(rounds, 0)));
      if (!check) continue;
      ++run.keyframes_checked;
      const std::string problems = sculptor.CheckInvariants(/*check_triangulation=*/false);
      EXPECT_TRUE(problems.empty()) << "keyframe " << st.keyframe.value << ": " << problems;
      const MeshCheckReport report = CheckMesh(sculptor.ExtractMesh(), kEmptyAllowed);
      EXPECT_TRUE(report.ok) << "keyframe " << st.keyframe.value << ": " << report.Summary();
      EXPECT_EQ(static_cast<size_t>(report.triangles), st.triangles);
    }
  };
  for (const SurfaceKeyframe& kf : drive) account(sculptor.AddKeyframe(kf));
  account(sculptor.Finish());
  if (check) {
    EXPECT_EQ(sculptor.CheckInvariants(/*check_triangulation=*/true), "");
  }
  return run;
}

TEST(TightEnclosing, CleanAndNoisyStreetsStayManifoldWithNoInsertionIntoO) {
  struct Scene {
    const char* name;
    double noise;
    uint32_t seed;
  };
  for (const Scene& scene : {Scene{"clean street", 0.0, 11}, Scene{"noisy street", 0.05, 3}}) {
    SCOPED_TRACE(scene.name);
    const auto drive = testing::NoisyStreet(32, 100, scene.noise, scene.seed);
    const TightRun run = RunTight(drive, SculptorOptions().enclosing_rounds, /*check=*/true);
    std::cout << scene.name << " (tight E): added " << run.added << ", rejected " << run.rejected
              << " (" << 100.0 * run.RejectedShare() << "%), widening rounds " << run.rounds
              << ", triangles " << run.triangles << "\n";
    EXPECT_EQ(run.keyframes_checked, 32u - 10u + 1u);  // the batch row, then one per keyframe
    EXPECT_EQ(run.meeting_o, 0u);
    EXPECT_GT(run.added, 2000u);
    EXPECT_GT(run.triangles, 500u);
  }
}

// The widening is what keeps the rejected points rare: on the clean street of
// sculptor_test.cpp the conflict zones without it (the previous mode) reject about 6 % of the
// points, with it well under 1 %.
TEST(TightEnclosing, WideningKeepsTheRejectedShareBelowABoundThatNoWideningExceeds) {
  const auto drive = testing::NoisyStreet(40, 100, 0.0, 11);
  const TightRun widened = RunTight(drive, SculptorOptions().enclosing_rounds, false);
  const TightRun fixed = RunTight(drive, 0, false);
  std::cout << "rejected: widened " << 100.0 * widened.RejectedShare() << "% (" << widened.rounds
            << " rounds), fixed margin " << 100.0 * fixed.RejectedShare() << "%\n";
  constexpr double kBound = 0.01;
  EXPECT_LT(widened.RejectedShare(), kBound);
  EXPECT_GT(fixed.RejectedShare(), kBound);
  EXPECT_GT(widened.rounds, 0u);
  EXPECT_EQ(fixed.rounds, 0u);
}

// A cell of O ∩ D that the shrink keeps has all its vertices on δO and the star of one
// of them leaves E, so the several-at-once shrink cannot clear it. Widening E by the stars of
// those vertices clears D in fewer rounds than widening by facet rings through O, on the noisy
// street, without rejecting more points.
TEST(TightEnclosing, VertexStarWideningNeedsFewerRoundsThanRings) {
  const auto drive = testing::NoisyStreet(32, 400, 0.05, 3);  // dense: 100 points need ~1 round
  SculptorOptions stars, rings;
  stars.enclosing_widening = EnclosingWidening::kVertexStars;
  rings.enclosing_widening = EnclosingWidening::kRings;
  const int max_rounds = SculptorOptions().enclosing_rounds;
  const TightRun by_stars = RunTight(drive, max_rounds, false, stars);
  const TightRun by_rings = RunTight(drive, max_rounds, false, rings);
  const double stars_mean = static_cast<double>(by_stars.rounds) / by_stars.keyframes;
  const double rings_mean = static_cast<double>(by_rings.rounds) / by_rings.keyframes;
  std::cout << "noisy street, widening rounds per keyframe: vertex stars " << stars_mean
            << " (rejected " << 100.0 * by_stars.RejectedShare() << "%), facet rings " << rings_mean
            << " (rejected " << 100.0 * by_rings.RejectedShare() << "%)\n";
  EXPECT_EQ(by_stars.keyframes, 22u);
  EXPECT_LT(stars_mean, 0.8 * rings_mean);
  EXPECT_LE(by_stars.RejectedShare(), by_rings.RejectedShare());
  EXPECT_LT(by_stars.RejectedShare(), 0.01);
}

// The tight mode's growth region (E ∪ N ∪ the cells crossed by new rays) misses the free
// cells that the addition test refused earlier and that a change of O around them would now
// admit; the ball mode retries them in every keyframe. With the growth around the changes of δO
// the tight mode leaves about as many cells of F outside O as the ball mode; without it, more.
TEST(TightEnclosing, GrowthAroundChangesLeavesAboutAsFewFreeCellsOutsideOAsTheBall) {
  const auto drive = testing::NoisyStreet(40, 100, 0.05, 3);
  const TightRun ball = RunTight(drive, -1, false);
  const TightRun tight = RunTight(drive, SculptorOptions().enclosing_rounds, false);
  SculptorOptions no_closure;
  no_closure.grow_closure_rounds = 0;
  const TightRun bare = RunTight(drive, SculptorOptions().enclosing_rounds, false, no_closure);
  auto left_out = [](const TightRun& run) {
    return static_cast<double>(run.cells_f - run.cells_o) / static_cast<double>(run.cells_f);
  };
  std::cout << "cells of F outside O: ball " << left_out(ball) * 100 << "% (|O| " << ball.cells_o
            << "), tight " << left_out(tight) * 100 << "% (|O| " << tight.cells_o
            << "), tight without the growth around changes " << left_out(bare) * 100 << "% (|O| "
            << bare.cells_o << ")\n";
  // Measured: ball 2.65 %, tight 2.66 %, without the growth around changes 3.14 % (|O| −0.5 %).
  EXPECT_LT(left_out(tight), left_out(ball) + 0.0025);
  EXPECT_GT(left_out(bare), left_out(tight));
  EXPECT_NEAR(static_cast<double>(tight.cells_o) / ball.cells_o, 1.0, 0.003);
}

TEST(TightEnclosing, OptionsCheckRejectsBadWidening) {
  SculptorOptions o;
  o.enclosing_rounds = -1;
  EXPECT_NE(o.Check(), "");
  o = SculptorOptions();
  o.enclosing_round_rings = 0;
  EXPECT_NE(o.Check(), "");
  o = SculptorOptions();
  o.enclosing_star_rings = 0;
  EXPECT_NE(o.Check(), "");
  o = SculptorOptions();
  o.grow_closure_rounds = -1;
  EXPECT_NE(o.Check(), "");
}

// Paper §5.1 filters one by one on a random stream: each point counted by the first filter that
// removes it (invalid, ground, length, aperture), against a recount written here.
TEST(PointFilters, PerFilterCountsAddUpAndMatchABruteForceRecount) {
  std::mt19937 rng(21);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double s = 1.0;
  SculptorOptions options;
  options.scale = s;
  options.ground_quantile = 0.0;  // the paper's ground bound, 3 s
  IncrementalSculptor sculptor(options);
  size_t totals[4] = {0, 0, 0, 0}, counted[4] = {0, 0, 0, 0}, filtered = 0, filtered_sum = 0;
  for (int t = 0; t < 6; ++t) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(t);
    kf.centre = Eigen::Vector3d(2.0 * t, 0.0, 2.0);
    for (int i = 0; i < 300; ++i) {
      SurfacePoint p;
      p.id = PointId(static_cast<uint32_t>(t * 1000 + i));
      // Around the keyframe, up to 20 m away and 6 m below it.
      p.position = kf.centre + Eigen::Vector3d(20.0 * u(rng), 20.0 * u(rng), 4.0 * u(rng) - 2.0);
      const int num_rays = i % 17 == 0 ? 0 : 1 + static_cast<int>(3.0 * (u(rng) + 1.0) / 2.0);
      for (int k = 0; k < num_rays; ++k) {
        // Origins spread by up to `spread` metres around the centre: some pairs far apart
        // (wide aperture), some close (narrow).
        const double spread = i % 3 == 0 ? 0.2 : 3.0;
        p.rays.push_back(
            {KeyframeId(t), kf.centre + spread * Eigen::Vector3d(u(rng), u(rng), 0.3 * u(rng))});
      }
      if (i % 29 == 0) p.position.x() = std::nan("");
      // The recount: angles from acos, the filters in the documented order.
      int reason = -1;
      const Eigen::Vector3d d = p.position - kf.centre;
      if (!p.position.allFinite() || p.rays.empty()) {
        reason = 0;
      } else if (d.z() < -3.0 * s) {
        reason = 1;
      } else if (std::sqrt(d.x() * d.x() + d.y() * d.y() + d.z() * d.z()) > 15.0 * s) {
        reason = 2;
      } else {
        double widest = 0.0;
        for (const SurfaceRay& a : p.rays) {
          for (const SurfaceRay& b : p.rays) {
            const Eigen::Vector3d x = a.origin - p.position, y = b.origin - p.position;
            const double c = std::clamp(x.dot(y) / (x.norm() * y.norm()), -1.0, 1.0);
            widest = std::max(widest, std::acos(c) * 180.0 / M_PI);
          }
        }
        if (!(widest > options.min_aperture_deg)) reason = 3;
      }
      if (reason >= 0) ++totals[reason];
      kf.points.push_back(p);
    }
    for (const KeyframeStats& st : sculptor.AddKeyframe(kf)) {
      counted[0] += st.points_invalid;
      counted[1] += st.points_filtered_ground;
      counted[2] += st.points_filtered_length;
      counted[3] += st.points_filtered_aperture;
      filtered += st.points_filtered;
      filtered_sum += st.points_invalid + st.points_filtered_ground + st.points_filtered_length +
                      st.points_filtered_aperture;
      EXPECT_EQ(st.points_in,
                st.points_filtered + st.points_added + st.points_rejected + st.points_duplicate);
    }
  }
  EXPECT_EQ(filtered, filtered_sum);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(counted[k], totals[k]) << "filter " << k;
    EXPECT_GT(totals[k], 20u) << "filter " << k << " has cases";
  }
  EXPECT_EQ(sculptor.CheckInvariants(), "");
}

}  // namespace
}  // namespace omni
