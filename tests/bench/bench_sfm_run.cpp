// Speed of the whole SfM on a synthetic drive: the SfM loop of `omnisculpt sfm` and
// `omnisculpt reconstruct` (pipeline/sfm_runner.h: front end, tracker, re-localisation, loop
// closure) over every frame, with the images decoded beforehand (loading is not measured).
//
// The drive: $OMNI_BENCH_SFM_DRIVE when set (e.g. /tmp/demo), otherwise the `short` preset
// (130 frames) rendered once into a temporary folder; $OMNI_BENCH_SFM_FRAMES limits the frames
// (0 or unset: all). Counters: frames/s and the seconds of each stage per run (wall time;
// detection and matching run in parallel over the cameras).
//
//   BM_SfmRun        the whole SfM loop (RunSfm, the commands' default options); its figures
//                    move with the tracker's own changes.
//   BM_FrontEndOnly  the front end alone, every frame matched against the previous one with
//                    the constant image-motion model: fixed inputs for the Harris and ZNCC
//                    kernels.
//
// Run from a Release build: nice -n 5 build/tests/bench/bench_sfm_run

#include <benchmark/benchmark.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "apps/default_rig.h"
#include "calib/drive.h"
#include "pipeline/sfm_runner.h"
#include "sfm/track_builder.h"
#include "synth/drive_writer.h"
#include "synth/synth_options.h"

namespace omni {
namespace {

struct BenchDrive {
  std::string name;
  Rig rig;
  std::vector<std::vector<cv::Mat>> frames;  // frames[f][camera], 8-bit grey
};

std::filesystem::path MakeShortDrive(std::filesystem::path* scratch) {
  *scratch = std::filesystem::temp_directory_path() /
             ("omni_bench_sfm_run_" + std::to_string(static_cast<long>(::getpid())));
  std::filesystem::remove_all(*scratch);
  const std::filesystem::path drive = *scratch / "short";
  synth::SynthWriteOptions write;
  write.progress = false;
  synth::WriteSyntheticDrive(SynthPresetOptions("short"), DefaultRig(), drive, write);
  return drive;
}

const BenchDrive& Drive() {
  static const std::unique_ptr<BenchDrive> loaded = [] {
    auto bench = std::make_unique<BenchDrive>();
    std::filesystem::path scratch;
    std::filesystem::path folder;
    if (const char* given = std::getenv("OMNI_BENCH_SFM_DRIVE"); given && *given) {
      folder = given;
      bench->name = folder.string();
    } else {
      folder = MakeShortDrive(&scratch);
      bench->name = "synth --preset short";
    }
    const omni::Drive drive = omni::Drive::Open(folder);
    bench->rig = drive.rig();
    size_t num_frames = drive.NumFrames();
    if (const char* limit = std::getenv("OMNI_BENCH_SFM_FRAMES"); limit && std::atoi(limit) > 0)
      num_frames = std::min<size_t>(num_frames, std::atoi(limit));
    for (size_t f = 0; f < num_frames; ++f) {
      std::vector<cv::Mat> images;
      for (size_t c = 0; c < bench->rig.NumCameras(); ++c) images.push_back(drive.LoadGray(f, c));
      bench->frames.push_back(std::move(images));
    }
    if (!scratch.empty()) std::filesystem::remove_all(scratch);
    return bench;
  }();
  return *loaded;
}

std::string Label(const BenchDrive& drive) {
  return drive.name + ", " + std::to_string(drive.frames.size()) + " frames x " +
         std::to_string(drive.rig.NumCameras()) + " cameras";
}

void BM_SfmRun(benchmark::State& state) {
  const BenchDrive& drive = Drive();
  SfmRunnerOptions options;
  options.tracker.central = drive.rig.central;
  SfmFrameSource source;
  source.folder = drive.name;
  source.num_frames = drive.frames.size();
  source.load = [&drive](size_t frame) { return drive.frames[frame]; };
  source.name = [](size_t frame) { return std::to_string(frame); };
  SfmRunResult run;
  for (auto _ : state) run = RunSfm(drive.rig, source, options);
  // Figures of the last run.
  const double frames = static_cast<double>(drive.frames.size());
  state.counters["frames/s"] =
      benchmark::Counter(frames * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["detect_s"] = run.front.detect;
  state.counters["match_s"] = run.front.match;
  state.counters["resect_s"] = run.back.resect;
  state.counters["triangulate_s"] = run.back.triangulate;
  state.counters["ba_s"] = run.back.bundle_adjustment;
  state.counters["loop_s"] = run.loop_closure_seconds;
  state.counters["keyframes"] = static_cast<double>(run.keyframes.size());
  state.counters["untracked"] = static_cast<double>(run.frames_total - run.frames_tracked);
  state.SetLabel(Label(drive));
}
BENCHMARK(BM_SfmRun)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

void BM_FrontEndOnly(benchmark::State& state) {
  const BenchDrive& drive = Drive();
  TrackBuilderOptions options;
  TrackBuilder::Timings timings;
  double matched = 0.0, corners = 0.0;
  for (auto _ : state) {
    TrackBuilder builder(drive.rig, options);
    matched = corners = 0.0;
    for (const std::vector<cv::Mat>& images : drive.frames) {
      const TrackedFrame frame = builder.AddFrame(images);
      builder.SetFrameResult(true, false);
      matched += frame.num_matched;
      corners += frame.num_corners;
    }
    timings = builder.StageTimings();
  }
  const double frames = static_cast<double>(drive.frames.size());
  state.counters["frames/s"] =
      benchmark::Counter(frames * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["detect_ms/frame"] = 1e3 * timings.detect / frames;
  state.counters["match_ms/frame"] = 1e3 * timings.match / frames;
  state.counters["corners/frame"] = corners / frames;
  state.counters["matched/frame"] = matched / frames;
  state.SetLabel(Label(drive));
}
BENCHMARK(BM_FrontEndOnly)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

}  // namespace
}  // namespace omni

int main(int argc, char** argv) {
  // As the SfM loop does: the per-frame image buffers in the heap rather than fresh mappings
  // (BM_FrontEndOnly gets it too).
  omni::ConfigureAllocatorForSfm();
  spdlog::set_level(spdlog::level::warn);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
