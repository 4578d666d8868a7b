// Rendering throughput of the synthetic drives: rays per second and frames (six
// images) per second on the `demo` city, PNG writing excluded; and the cost of building the
// city. Run from a Release build: build/tests/bench/bench_synth.

#include <benchmark/benchmark.h>

#include <memory>

#include "apps/default_rig.h"
#include "synth/drive_writer.h"
#include "synth/renderer.h"

namespace omni::synth {
namespace {

struct DemoScene {
  SyntheticDrive drive = MakeSyntheticDrive(SynthPresetOptions("demo"), DefaultRig());
  SceneRenderer renderer{drive.scene, drive.options.seed, drive.options.render};
};

DemoScene& Demo() {
  static DemoScene demo;
  return demo;
}

// One frame: the six images of the rig, as `omnisculpt synth` renders them.
void BM_RenderFrame(benchmark::State& state) {
  DemoScene& demo = Demo();
  const SyntheticDrive& drive = demo.drive;
  size_t frame = 0;
  const uint64_t rays_before = demo.renderer.RaysCast();
  for (auto _ : state) {
    for (size_t camera = 0; camera < drive.rig.NumCameras(); ++camera) {
      const cv::Mat image =
          demo.renderer.Render(drive.rig.cameras[camera], drive.WorldFromCamera(frame, camera),
                               drive.ImageSeed(frame, camera), drive.camera_gains[camera]);
      benchmark::DoNotOptimize(image.data);
    }
    frame = (frame + 37) % drive.NumFrames();
  }
  const double rays = static_cast<double>(demo.renderer.RaysCast() - rays_before);
  state.counters["rays/s"] = benchmark::Counter(rays, benchmark::Counter::kIsRate);
  state.counters["frames/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
  state.counters["rays/pixel"] = rays / (state.iterations() * drive.rig.NumCameras() *
                                         drive.rig.cameras[0].width * drive.rig.cameras[0].height);
  state.SetLabel("demo preset, seed 1, " + std::to_string(drive.scene.mesh.triangles.size()) +
                 " triangles, 6 x 384x512");
}
BENCHMARK(BM_RenderFrame)->Unit(benchmark::kMillisecond)->UseRealTime()->MinTime(5.0);

// Single rays through CastPixel (the ground-truth query, not packetised).
void BM_CastPixel(benchmark::State& state) {
  DemoScene& demo = Demo();
  const SyntheticDrive& drive = demo.drive;
  const Camera& camera = drive.rig.cameras[1];
  const Rigid3d world_from_cam = drive.WorldFromCamera(100, 1);
  int x = 0, y = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(
        demo.renderer.CastPixel(camera, world_from_cam, Eigen::Vector2d(x, y)));
    x = (x + 7) % camera.width;
    y = (y + 3) % camera.height;
  }
  state.counters["rays/s"] =
      benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_CastPixel);

void BM_BuildDemoCity(benchmark::State& state) {
  const SynthOptions options = SynthPresetOptions("demo");
  for (auto _ : state) {
    const CityScene scene = BuildCity(options.city, options.seed);
    benchmark::DoNotOptimize(scene.mesh.triangles.data());
    state.counters["triangles"] = static_cast<double>(scene.mesh.triangles.size());
  }
}
BENCHMARK(BM_BuildDemoCity)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace omni::synth

BENCHMARK_MAIN();
