// Speed of the whole SfM (issue 8: at least 15 frames/s of six 512×384 images on 2 cores) on a
// synthetic drive: the image front end (sfm/track_builder.h: Harris + ZNCC) and the tracker
// (sfm/tracker.h: resection, triangulation, local bundle adjustment) over every frame, as
// `omnisculpt sfm` runs them, with the images decoded beforehand (loading is not measured).
//
// The drive: $OMNI_BENCH_SFM_DRIVE when set (e.g. /tmp/demo), otherwise the `short` preset
// (130 frames) rendered once into a temporary folder; $OMNI_BENCH_SFM_FRAMES limits the frames
// (0 or unset: all). Counters: frames/s and the seconds of each stage per run (wall time;
// detection and matching run in parallel over the cameras).
//
//   BM_SfmRun        the whole SfM (front end with search regions by reprojection + tracker);
//                    its figures move with the tracker's own changes.
//   BM_FrontEndOnly  the front end alone, every frame matched against the previous one with
//                    the constant image-motion model: fixed inputs for the Harris and ZNCC
//                    kernels.
//
// Run from a Release build: nice -n 5 build/tests/bench/bench_sfm_run

#include <benchmark/benchmark.h>
#include <spdlog/spdlog.h>

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "apps/default_rig.h"
#include "calib/drive.h"
#include "sfm/track_builder.h"
#include "sfm/tracker.h"
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
  const Rig& rig = drive.rig;
  TrackBuilderOptions track_options;
  TrackerOptions tracker_options;
  tracker_options.central = rig.central;
  TrackBuilder::Timings front;
  Tracker::Timings back;
  int keyframes = 0, points = 0, untracked = 0;
  for (auto _ : state) {
    TrackBuilder builder(rig, track_options);
    Tracker tracker(rig, tracker_options);
    untracked = 0;
    for (const std::vector<cv::Mat>& images : drive.frames) {
      const TrackedFrame frame = builder.AddFrame(images, ReprojectionPredictor(tracker, rig));
      const FrameResult result = tracker.AddFrame(frame.observations, builder.MapPointSearcher());
      builder.SetFrameResult(result.tracked, result.keyframe);
      benchmark::DoNotOptimize(tracker.TakeFinalized());
      untracked += result.tracked ? 0 : 1;
    }
    tracker.Finish();
    benchmark::DoNotOptimize(tracker.TakeFinalized());
    front = builder.StageTimings();
    back = tracker.StageTimings();
    keyframes = tracker.NumKeyframes();
    points = tracker.NumPoints();
  }
  // Figures of the last run.
  const double frames = static_cast<double>(drive.frames.size());
  state.counters["frames/s"] =
      benchmark::Counter(frames * state.iterations(), benchmark::Counter::kIsRate);
  state.counters["detect_s"] = front.detect;
  state.counters["match_s"] = front.match;
  state.counters["resect_s"] = back.resect;
  state.counters["triangulate_s"] = back.triangulate;
  state.counters["ba_s"] = back.bundle_adjustment;
  state.counters["keyframes"] = keyframes;
  state.counters["points"] = points;
  state.counters["untracked"] = untracked;
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
#ifdef __GLIBC__
  // As `omnisculpt sfm` does (apps/sfm_command.cpp): keep the per-frame image buffers in the
  // heap rather than fresh mappings.
  mallopt(M_MMAP_THRESHOLD, 256 << 20);
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
#endif
  spdlog::set_level(spdlog::level::warn);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
