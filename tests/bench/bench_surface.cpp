// The incremental sculptor (surface/) on a keyframe stream from a simulated perfect
// SfM: per-keyframe time (median, p95, max), max |E|, the flatness ratio (mean time over the
// last fifth of the incremental keyframes / over the first fifth) and the share of rejected
// points, for both enclosing modes.
//
// Stream: OMNI_BENCH_DRIVE=<drive from `omnisculpt synth`> (gt/ used through --from-gt's
// generator), otherwise a straight street of OMNI_BENCH_STREET_M metres (default 300) between
// two 12 m walls, 16 m apart, keyframes every 1.9 m, 370 points each (the paper's density).

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <numeric>
#include <string>

#include "calib/mesh_check.h"
#include "pipeline/gt_keyframes.h"
#include "surface/sculptor.h"

namespace omni {
namespace {

void AddQuad(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c,
             const Eigen::Vector3d& d, TriangleMesh* mesh) {
  const int k = static_cast<int>(mesh->vertices.size());
  mesh->vertices.insert(mesh->vertices.end(), {a, b, c, d});
  mesh->triangles.emplace_back(k, k + 1, k + 2);
  mesh->triangles.emplace_back(k, k + 2, k + 3);
}

const std::vector<SurfaceKeyframe>& Stream(std::string* description) {
  static std::vector<SurfaceKeyframe> stream;
  static std::string what;
  if (stream.empty()) {
    GtKeyframeOptions options;
    if (const char* drive = std::getenv("OMNI_BENCH_DRIVE")) {
      stream = LoadGtKeyframes(drive, options);
      what = std::string("drive ") + drive;
    } else {
      const char* length_env = std::getenv("OMNI_BENCH_STREET_M");
      const double length = length_env ? std::atof(length_env) : 300.0;
      TriangleMesh street;
      const double x0 = -50, x1 = length + 50, w = 8, h = 12;
      // Facing the street (the free space).
      AddQuad({x0, -w, 0}, {x1, -w, 0}, {x1, w, 0}, {x0, w, 0}, &street);
      AddQuad({x0, -w, 0}, {x0, -w, h}, {x1, -w, h}, {x1, -w, 0}, &street);
      AddQuad({x0, w, 0}, {x1, w, 0}, {x1, w, h}, {x0, w, h}, &street);
      std::vector<Eigen::Vector3d> centres;
      for (double x = 0; x <= length; x += options.keyframe_spacing)
        centres.emplace_back(x, 0.3, 4.0);
      stream = MakeGtKeyframes(street, centres, options);
      what = "straight street " + std::to_string(static_cast<int>(length)) + " m";
    }
  }
  *description = what;
  return stream;
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0.0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

void BM_Sculpt(benchmark::State& state) {
  std::string description;
  const auto& stream = Stream(&description);
  SculptorOptions options;
  options.enclosing = state.range(0) == 0 ? EnclosingMode::kBall : EnclosingMode::kConflictZones;
  if (const char* step = std::getenv("OMNI_BENCH_RAY_GRID"))
    options.ray_grid_step_factor = std::atof(step);
  // OMNI_BENCH_OLD_RAYS=whole|all: the reference ways of re-tracing old rays (same counters).
  if (const char* mode = std::getenv("OMNI_BENCH_OLD_RAYS")) {
    if (std::string(mode) == "whole") options.old_rays = OldRayTracing::kWholeWalks;
    if (std::string(mode) == "all") options.old_rays = OldRayTracing::kAllRays;
  }
  // OMNI_BENCH_REFERENCE_MANIFOLD=1: steps 2 and 5 without the memos of failed manifold tests
  // and the star counts (the same surface, slower).
  if (const char* reference = std::getenv("OMNI_BENCH_REFERENCE_MANIFOLD"))
    options.reference_manifold_tests = std::string(reference) == "1";
  std::vector<KeyframeStats> stats;
  TriangleMesh mesh;
  for (auto _ : state) {
    IncrementalSculptor sculptor(options);
    stats.clear();
    for (const SurfaceKeyframe& kf : stream) {
      for (const KeyframeStats& st : sculptor.AddKeyframe(kf)) stats.push_back(st);
    }
    for (const KeyframeStats& st : sculptor.Finish()) stats.push_back(st);
    mesh = sculptor.ExtractMesh();
  }
  std::vector<double> ms;
  size_t max_e = 0, added = 0, rejected = 0;
  for (const KeyframeStats& st : stats) {
    added += st.points_added;
    rejected += st.points_rejected;
    if (st.batch) continue;
    ms.push_back(MsPerKeyframe(st));
    max_e = std::max(max_e, st.cells_e);
  }
  const size_t fifth = std::max<size_t>(1, ms.size() / 5);
  auto mean = [](auto b, auto e) { return std::accumulate(b, e, 0.0) / std::max<long>(1, e - b); };
  const double flatness = ms.empty() ? 0.0
                                     : mean(ms.end() - fifth, ms.end()) /
                                           std::max(1e-9, mean(ms.begin(), ms.begin() + fifth));
  state.counters["ms_median"] = Quantile(ms, 0.5);
  state.counters["ms_p95"] = Quantile(ms, 0.95);
  state.counters["ms_max"] = ms.empty() ? 0.0 : *std::max_element(ms.begin(), ms.end());
  state.counters["max_E"] = static_cast<double>(max_e);
  state.counters["flatness"] = flatness;
  state.counters["rejected_pct"] = 100.0 * rejected / std::max<size_t>(1, added + rejected);
  state.counters["triangles"] = static_cast<double>(mesh.triangles.size());
  // Means over the incremental keyframes, per step.
  auto mean_of = [&](auto field) {
    double sum = 0;
    size_t n = 0;
    for (const KeyframeStats& st : stats) {
      if (!st.batch) sum += field(st), ++n;
    }
    return n ? sum / n : 0.0;
  };
  state.counters["rays_new"] = mean_of([](const KeyframeStats& s) { return s.rays_new; });
  state.counters["rays_old"] = mean_of([](const KeyframeStats& s) { return s.rays_old; });
  state.counters["ms_shrink"] = mean_of([](const KeyframeStats& s) { return s.ms_shrink; });
  state.counters["ms_insert"] = mean_of([](const KeyframeStats& s) { return s.ms_insert; });
  state.counters["ms_rays"] = mean_of([](const KeyframeStats& s) { return s.ms_rays; });
  state.counters["ms_grow"] = mean_of([](const KeyframeStats& s) { return s.ms_grow; });
  state.counters["ms_select"] = mean_of([](const KeyframeStats& s) { return s.ms_rays_select; });
  state.counters["ms_old"] = mean_of([](const KeyframeStats& s) { return s.ms_rays_old; });
  state.counters["candidates"] =
      mean_of([](const KeyframeStats& s) { return s.rays_old_candidates; });
  state.counters["old_cells"] = mean_of([](const KeyframeStats& s) { return s.old_walk_cells; });
  state.counters["cells_n"] = mean_of([](const KeyframeStats& s) { return s.cells_n; });
  state.counters["ms_genus"] = mean_of([](const KeyframeStats& s) { return s.ms_genus; });
  state.counters["ms_smooth"] = mean_of([](const KeyframeStats& s) { return s.ms_smooth; });
  if (const char* csv = std::getenv("OMNI_BENCH_CSV")) {
    if (FILE* f = std::fopen(csv, "w")) {
      std::fprintf(f, "%s\n", KeyframeStatsCsvHeader().c_str());
      for (const KeyframeStats& st : stats)
        std::fprintf(f, "%s\n", KeyframeStatsCsvRow(st).c_str());
      std::fclose(f);
    }
  }
  state.counters["manifold"] = CheckMesh(mesh).ok ? 1 : 0;
  state.SetLabel(description + ", " + std::to_string(stream.size()) +
                 " keyframes, E=" + (state.range(0) == 0 ? "ball" : "conflict zones"));
}
BENCHMARK(BM_Sculpt)->Arg(0)->Arg(1)->Iterations(1)->Unit(benchmark::kSecond);

}  // namespace
}  // namespace omni

BENCHMARK_MAIN();
