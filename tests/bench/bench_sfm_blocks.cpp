// Speed of the sfm building blocks on synthetic problems (sfm/synthetic.h): the RANSAC pose
// solvers, the local bundle adjustment and the Harris + ZNCC front end on a 512×384 image (the
// paper's halved Ladybug size). Run from a Release build; compare runs as ratios on one machine.

#include <benchmark/benchmark.h>

#include "sfm/absolute_pose_central.h"
#include "sfm/absolute_pose_noncentral.h"
#include "sfm/bundle_adjustment.h"
#include "sfm/harris.h"
#include "sfm/relative_pose_central.h"
#include "sfm/relative_pose_noncentral.h"
#include "sfm/synthetic.h"
#include "sfm/zncc_matching.h"

namespace omni {
namespace {

std::vector<Rigid3d> TwoPoses() {
  return {Rigid3d(), Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitZ())),
                             Eigen::Vector3d(1.0, 0.2, 0.0))};
}

SyntheticScene Scene(const Rig& rig, double outliers) {
  SyntheticSceneOptions options;
  options.num_points = 400;
  options.min_depth = 3.0;
  options.max_depth = 15.0;
  options.noise = 0.0005;
  options.outlier_ratio = outliers;
  return MakeSyntheticScene(rig, TwoPoses(), options);
}

void BM_CentralRelativePose(benchmark::State& state) {
  const SyntheticScene scene = Scene(MakeSyntheticRingRig(1, false, 0.0), 0.1);
  const SyntheticMatches matches = MatchSyntheticFrames(scene, 0, 1);
  CentralRelativePoseOptions options;
  Rigid3d pose;
  for (auto _ : state)
    benchmark::DoNotOptimize(
        EstimateCentralRelativePose(matches.bearings1, matches.bearings2, options, &pose));
  state.counters["correspondences"] = matches.bearings1.size();
}
BENCHMARK(BM_CentralRelativePose)->Unit(benchmark::kMillisecond);

void BM_NoncentralRelativePose(benchmark::State& state) {
  const Rig rig = MakeSyntheticRingRig(5, true, 0.3);
  const SyntheticScene scene = Scene(rig, 0.05);
  const SyntheticMatches m = MatchSyntheticFrames(scene, 0, 1);
  NoncentralRelativePoseOptions options;
  Rigid3d pose;
  for (auto _ : state)
    benchmark::DoNotOptimize(EstimateNoncentralRelativePose(
        rig, m.bearings1, m.cameras1, m.bearings2, m.cameras2, options, &pose));
  state.counters["correspondences"] = m.bearings1.size();
}
BENCHMARK(BM_NoncentralRelativePose)->Unit(benchmark::kMillisecond);

void BM_NoncentralAbsolutePose(benchmark::State& state) {
  const Rig rig = MakeSyntheticRingRig(5, true, 0.3);
  const SyntheticScene scene = Scene(rig, 0.2);
  std::vector<Eigen::Vector3d> bearings, points;
  std::vector<int> cameras;
  for (const SyntheticObservation& o : scene.observations) {
    if (o.frame != 1) continue;
    bearings.push_back(o.bearing);
    cameras.push_back(o.camera);
    points.push_back(scene.points_in_world[o.point]);
  }
  NoncentralAbsolutePoseOptions options;
  Rigid3d pose;
  for (auto _ : state)
    benchmark::DoNotOptimize(
        EstimateNoncentralAbsolutePose(rig, bearings, cameras, points, options, &pose));
  state.counters["correspondences"] = bearings.size();
}
BENCHMARK(BM_NoncentralAbsolutePose)->Unit(benchmark::kMillisecond);

// Ten keyframes (7 fixed, 3 free, the local window), 2000 points; central mode on a rig whose
// cameras share one centre, so that the model is exact.
void BM_LocalBundleAdjustment(benchmark::State& state) {
  const Rig rig = MakeSyntheticRingRig(5, true, 0.0);
  std::vector<Rigid3d> poses;
  for (int i = 0; i < 10; ++i)
    poses.emplace_back(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.5 * i, 0.0, 0.0));
  SyntheticSceneOptions scene_options;
  scene_options.num_points = 2000;
  scene_options.min_depth = 3.0;
  scene_options.max_depth = 15.0;
  scene_options.noise = 0.0005;
  const SyntheticScene scene = MakeSyntheticScene(rig, poses, scene_options);
  BundleAdjustmentProblem start;
  for (size_t i = 0; i < poses.size(); ++i) start.keyframes.push_back({poses[i], i < 7});
  start.points_in_world = scene.points_in_world;
  for (const SyntheticObservation& o : scene.observations)
    start.observations.push_back({o.frame, o.camera, o.point, o.bearing});
  for (auto& keyframe : start.keyframes)
    if (!keyframe.fixed) keyframe.world_from_rig.translation.y() += 0.05;
  BundleAdjustmentOptions options;
  BundleAdjustmentSummary summary;
  for (auto _ : state) {
    BundleAdjustmentProblem problem = start;
    summary = LocalBundleAdjust(rig, options, &problem);
  }
  state.counters["observations"] = start.observations.size();
  state.counters["solver_iterations"] = summary.num_iterations;
  state.counters["rms_mrad"] = 1e3 * summary.rms_angle_after;
}
BENCHMARK(BM_LocalBundleAdjustment)->Unit(benchmark::kMillisecond);

void BM_HarrisAndZncc512x384(benchmark::State& state) {
  const cv::Mat image1 = MakeSyntheticTexture(512, 384, Eigen::Vector2d::Zero(), 400, 1);
  const cv::Mat image2 = MakeSyntheticTexture(512, 384, Eigen::Vector2d(3.3, 1.2), 400, 1);
  HarrisOptions harris;
  ZnccOptions zncc;
  size_t matched = 0;
  for (auto _ : state) {
    std::vector<Eigen::Vector2d> c1, c2;
    for (const Corner& c : DetectHarrisCorners(image1, harris)) c1.push_back(c.pixel);
    for (const Corner& c : DetectHarrisCorners(image2, harris)) c2.push_back(c.pixel);
    std::vector<SearchRegion> regions;
    for (const auto& p : c1) regions.push_back({p + Eigen::Vector2d(3.0, 1.0), 20.0});
    matched = MatchZncc(image1, c1, regions, image2, c2, zncc).size();
  }
  state.counters["matches"] = matched;
}
BENCHMARK(BM_HarrisAndZncc512x384)->Unit(benchmark::kMillisecond);

// The two kernels apart, on one camera's share of a frame: detection on a 512×384 image, and
// matching its corners against the next image's with the tracker's 30-pixel search regions.
void BM_Harris512x384(benchmark::State& state) {
  const cv::Mat image = MakeSyntheticTexture(512, 384, Eigen::Vector2d::Zero(), 400, 1);
  HarrisOptions harris;
  size_t corners = 0;
  for (auto _ : state) corners = DetectHarrisCorners(image, harris).size();
  state.counters["corners"] = corners;
}
BENCHMARK(BM_Harris512x384)->Unit(benchmark::kMillisecond);

// The detector's stages: 0 the whole detector, 1 without the subpixel step, 2 the response
// alone (quality 0.999 leaves almost no candidate: the scan and the selection cost nothing).
void BM_Harris512x384_Stages(benchmark::State& state) {
  const cv::Mat image = MakeSyntheticTexture(512, 384, Eigen::Vector2d::Zero(), 400, 1);
  HarrisOptions harris;
  if (state.range(0) >= 1) harris.subpixel_iterations = 0;
  if (state.range(0) >= 2) harris.quality_level = 0.999;
  size_t corners = 0;
  for (auto _ : state) corners = DetectHarrisCorners(image, harris).size();
  state.counters["corners"] = corners;
}
BENCHMARK(BM_Harris512x384_Stages)->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

void BM_Zncc512x384(benchmark::State& state) {
  const cv::Mat image1 = MakeSyntheticTexture(512, 384, Eigen::Vector2d::Zero(), 400, 1);
  const cv::Mat image2 = MakeSyntheticTexture(512, 384, Eigen::Vector2d(3.3, 1.2), 400, 1);
  HarrisOptions harris;
  ZnccOptions zncc;
  std::vector<Eigen::Vector2d> c1, c2;
  for (const Corner& c : DetectHarrisCorners(image1, harris)) c1.push_back(c.pixel);
  for (const Corner& c : DetectHarrisCorners(image2, harris)) c2.push_back(c.pixel);
  std::vector<SearchRegion> regions;
  for (const auto& p : c1)
    regions.push_back({p + Eigen::Vector2d(3.3, 1.2), static_cast<double>(state.range(0))});
  size_t matched = 0;
  for (auto _ : state) matched = MatchZncc(image1, c1, regions, image2, c2, zncc).size();
  state.counters["matches"] = matched;
}
// The search radius: the tracker's 30 pixels without a predicted position, 15 with one (where
// the subpixel refinement of the matches is most of the work).
BENCHMARK(BM_Zncc512x384)->Arg(30)->Arg(15)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace omni

BENCHMARK_MAIN();
