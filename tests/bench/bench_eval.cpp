// Evaluation speed: Embree ray casting and closest-point queries, and the mesh checker, on
// synthetic scenes of paper-like size (the paper's estimated surface: 182k triangles; §5.2
// samples 769k pixels). Run from a Release build; compare runs as ratios on the same machine.

#include <benchmark/benchmark.h>

#include <cmath>

#include "calib/mesh_check.h"
#include "eval/primitives.h"
#include "eval/surface_eval.h"
#include "raycast/raycast.h"

namespace omni {
namespace {

// A city of boxes and spheres inside a closed enclosure: about 513k triangles (the paper's
// City surface: 528k).
TriangleMesh MakeCity() {
  TriangleMesh mesh = FlipOrientation(MakeBox({-10, -10, -1}, {610, 110, 60}));
  for (int i = 0; i < 50; ++i) {
    for (int j = 0; j < 2; ++j) {
      const double x = 12.0 * i, y = j ? 20.0 : 80.0;
      AppendMesh(MakeBox({x, y, -1}, {x + 9, y + 10, 8.0 + (i * 7 + j * 3) % 11}), &mesh);
      AppendMesh(MakeIcosphere({x + 4, 50.0 + 10 * j, 3.0}, 1.5, 4), &mesh);  // 5120 each
    }
  }
  return mesh;
}

std::vector<Ray> MakeRays(long count) {
  std::vector<Ray> rays;
  for (long i = 0; i < count; ++i) {
    const double a = 2.0 * M_PI * ((i * 0.6180339887) - std::floor(i * 0.6180339887));
    const double b = 0.6 * std::sin(0.001 * i);
    rays.push_back(
        {Eigen::Vector3d(300.0 * (i % 1000) / 1000.0, 50.0, 2.0),
         Eigen::Vector3d(std::cos(a) * std::cos(b), std::sin(a) * std::cos(b), std::sin(b))});
  }
  return rays;
}

void BM_BuildRayCaster(benchmark::State& state) {
  const TriangleMesh city = MakeCity();
  for (auto _ : state) {
    RayCaster caster(city);
    benchmark::DoNotOptimize(caster.NumTriangles());
  }
  state.counters["triangles"] = static_cast<double>(city.triangles.size());
}
BENCHMARK(BM_BuildRayCaster)->Unit(benchmark::kMillisecond);

void BM_CastRays(benchmark::State& state) {
  const TriangleMesh city = MakeCity();
  const RayCaster caster(city);
  const std::vector<Ray> rays = MakeRays(state.range(0));
  for (auto _ : state) benchmark::DoNotOptimize(caster.CastMany(rays));
  state.SetItemsProcessed(state.iterations() * state.range(0));
  state.counters["triangles"] = static_cast<double>(city.triangles.size());
}
BENCHMARK(BM_CastRays)->Arg(769000)->Unit(benchmark::kMillisecond);

void BM_ClosestPoints(benchmark::State& state) {
  const TriangleMesh city = MakeCity();
  const RayCaster caster(city);
  const std::vector<Eigen::Vector3d> points = SampleSurface(city, state.range(0), 3);
  for (auto _ : state) benchmark::DoNotOptimize(caster.DistancesTo(points));
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_ClosestPoints)->Arg(200000)->Unit(benchmark::kMillisecond);

void BM_CheckMesh(benchmark::State& state) {
  const TriangleMesh sphere = MakeIcosphere({0, 0, 0}, 1.0, static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(CheckMesh(sphere).ok);
  state.SetItemsProcessed(state.iterations() * static_cast<int64_t>(sphere.triangles.size()));
  state.counters["triangles"] = static_cast<double>(sphere.triangles.size());
}
BENCHMARK(BM_CheckMesh)->Arg(6)->Arg(7)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace omni

BENCHMARK_MAIN();
