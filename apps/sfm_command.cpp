// `omnisculpt sfm DRIVE --out OUT [--central|--non-central]`: the incremental rig SfM
// of sfm/ on a drive's images, writing the keyframe poses (poses.tum), the points (points.ply)
// a COLMAP text model (sparse/), per-frame statistics (stats/sfm_frames.csv), the time per
// stage (stats/sfm_stages.csv) and a summary (stats/sfm_summary.csv). ZNCC tracks per camera
// (sfm/track_builder.h, search regions by reprojection once the pose is predicted, and
// re-localisation against the last keyframe after a failure) feeding sfm/tracker.h.

#include <spdlog/spdlog.h>

#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <sstream>
#include <string>

#include "apps/commands.h"
#include "apps/pipeline/frame_prefetcher.h"
#include "apps/pipeline/point_colors.h"
#include "apps/pipeline/sfm_stats.h"
#include "calib/atomic_file.h"
#include "calib/drive.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "sfm/colmap_model.h"
#include "sfm/track_builder.h"
#include "sfm/tracker.h"

namespace omni {
namespace {

struct SfmCommandOptions {
  std::string drive;
  std::string out;
  bool central = false;
  bool non_central = false;
  int max_frames = 0;        // 0: all
  double frame_rate = 15.0;  // timestamps of poses.tum: frame index / frame_rate
  // Central mode treats the camera centres as one point: a camera offset d seen at depth z
  // bends the rays by about d / z radians. The map's scale is unknown in central mode, so the
  // depth is the user's (metres; street facades are 5-20 m away); above this ratio of the
  // largest offset to it, the log says the non-central mode is the right one.
  double scene_depth = 10.0;
  double max_central_offset_ratio = 0.01;
  FramePrefetcherOptions prefetch;
  TrackBuilderOptions tracks;
  TrackerOptions tracker;
};

// Seconds since `start`.
double SecondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

void RunSfm(SfmCommandOptions& o, const GlobalOptions& global) {
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  if (o.central && o.non_central)
    throw InputError("", "--central, --non-central", "give at most one of them");
  if (!(o.frame_rate > 0.0)) throw InputError("", "--frame-rate", "expected a positive rate");
  if (o.max_frames < 0) throw InputError("", "--max-frames", "expected 0 or a positive count");
  if (!(o.scene_depth > 0.0)) throw InputError("", "--scene-depth", "expected a positive depth");
  const Drive drive = Drive::Open(o.drive);
  const Rig& rig = drive.rig();
  o.tracker.central = o.central ? true : o.non_central ? false : rig.central;
  ThrowIfInvalid(o.prefetch.Check(), "FramePrefetcherOptions");
  ThrowIfInvalid(o.tracks.Check(), "TrackBuilderOptions");
  ThrowIfInvalid(o.tracker.Check(), "TrackerOptions");
  spdlog::info("sfm: {} frames, {} cameras, {} mode (largest camera offset {:.3f} m)",
               drive.NumFrames(), rig.NumCameras(), o.tracker.central ? "central" : "non-central",
               rig.MaxCenterOffset());

  const double offset_ratio = rig.MaxCenterOffset() / o.scene_depth;
  if (o.tracker.central && offset_ratio > o.max_central_offset_ratio)
    spdlog::warn(
        "sfm: central mode, but the cameras are up to {:.2f} m from their mean centre, {:.1f} % "
        "of a {:.0f} m scene depth (--scene-depth): rays bent by up to {:.2f} degrees; the "
        "non-central mode (--non-central) is the right one for this rig",
        rig.MaxCenterOffset(), 100.0 * offset_ratio, o.scene_depth,
        offset_ratio * 180.0 / 3.14159265358979323846);

#ifdef __GLIBC__
  // Every frame allocates and frees the same large image buffers (Harris responses, pyramids);
  // above glibc's default mmap threshold each is a fresh mapping, and the page faults cost
  // about half of the detection time (perf). Keep them in the heap instead.
  mallopt(M_MMAP_THRESHOLD, 256 << 20);
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
#endif

  TrackBuilder builder(rig, o.tracks);
  Tracker tracker(rig, o.tracker);
  const size_t num_frames =
      o.max_frames > 0 ? std::min<size_t>(drive.NumFrames(), o.max_frames) : drive.NumFrames();
  std::ostringstream csv;
  csv << "frame,name,corners,matched,predicted,relocalising,tracked,keyframe,inliers,status\n";
  const auto start = std::chrono::steady_clock::now();
  auto last_progress = start;
  SfmStats stats;
  std::vector<FinalizedKeyframe> keyframes;
  // The next frames' images are decoded on their own thread while the SfM runs (the same
  // prefetcher as reconstruct's); stopped and joined when this function ends.
  FramePrefetcher prefetcher(drive, num_frames, o.prefetch);
  for (size_t f = 0; f < num_frames; ++f) {
    auto load_start = std::chrono::steady_clock::now();
    std::optional<PrefetchedFrame> next = prefetcher.Next();
    if (!next) break;  // cannot happen: every frame is delivered until stopped
    next->Rethrow();   // a frame that cannot be read ends the run (exit code 2)
    std::vector<cv::Mat> images = std::move(next->images);
    stats.load_seconds += SecondsSince(load_start);

    // Search regions by reprojection of the map points once the pose is predicted.
    const TrackedFrame frame = builder.AddFrame(images, ReprojectionPredictor(tracker, rig));
    const FrameResult result = tracker.AddFrame(frame.observations, builder.MapPointSearcher());
    builder.SetFrameResult(result.tracked, result.keyframe);
    for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
      keyframes.push_back(std::move(keyframe));
    stats.AddFrame(true, frame.num_matched, result);
    csv << f << ',' << drive.FrameName(f) << ',' << frame.num_corners << ',' << frame.num_matched
        << ',' << frame.num_predicted << ',' << frame.relocalising << ',' << result.tracked << ','
        << result.keyframe << ',' << result.inliers << ',' << result.status << '\n';
    if (!result.tracked)
      spdlog::warn("frame {}: not tracked ({}){}", drive.FrameName(f), result.status,
                   frame.relocalising ? ", re-localising against the last keyframe" : "");
    const auto now = std::chrono::steady_clock::now();
    if (!global.quiet && (std::chrono::duration<double>(now - last_progress).count() >= 2.0 ||
                          f + 1 == num_frames)) {
      last_progress = now;
      const double rate = (f + 1) / std::max(SecondsSince(start), 1e-9);
      spdlog::info("sfm: frame {}/{}, {:.1f} frames/s, ETA {:.0f} s, {} keyframes, {} points",
                   f + 1, num_frames, rate, (num_frames - f - 1) / rate, tracker.NumKeyframes(),
                   tracker.NumPoints());
    }
  }
  tracker.Finish();
  for (FinalizedKeyframe& keyframe : tracker.TakeFinalized())
    keyframes.push_back(std::move(keyframe));
  stats.total_seconds = SecondsSince(start);
  if (tracker.NumKeyframes() < 2)
    throw InputError(o.drive, "images", "the SfM could not initialise (fewer than 2 keyframes)");

  const std::filesystem::path out(o.out);
  std::filesystem::create_directories(out / "stats");
  std::vector<StampedPose> poses;
  PointCloud cloud;
  for (const FinalizedKeyframe& keyframe : keyframes) {
    poses.push_back({keyframe.frame / o.frame_rate, keyframe.world_from_rig});
    for (const FinalizedPoint& point : keyframe.points) cloud.points.push_back(point.position);
  }
  // Point colours from the keyframe images (after the SfM, which reads grey images only).
  PointColorStats color_stats;
  cloud.colors = ColorPoints(
      rig, keyframes, [&drive](int frame, int camera) { return drive.LoadRgb(frame, camera); }, {},
      &color_stats);
  WriteTum(poses, out / "poses.tum");
  WritePlyPoints(cloud, out / "points.ply");
  const ColmapModelStats colmap = WriteColmapTextModel(
      rig, keyframes,
      [&drive](int frame, int camera) {
        return std::filesystem::relative(drive.ImagePath(frame, camera), drive.folder())
            .generic_string();
      },
      out / "sparse", cloud.colors);
  WriteTextFileAtomically(out / "stats" / "sfm_frames.csv", csv.str());

  // Time per stage and the summary (apps/pipeline/sfm_stats.h, shared with reconstruct).
  const TrackBuilder::Timings front = builder.StageTimings();
  const Tracker::Timings back = tracker.StageTimings();
  stats.front = front;
  stats.back = back;
  stats.keyframes = poses.size();
  stats.points = cloud.points.size();
  stats.colmap = colmap;
  stats.tracks = ComputeTrackStats(keyframes);
  WriteSfmStats(stats, out / "stats");

  spdlog::info(
      "sfm: {} keyframes, {} points, {} of {} frames not tracked, {:.1f} frames/s, "
      "written to {}",
      poses.size(), cloud.points.size(), stats.frames_not_tracked, num_frames,
      num_frames / std::max(stats.total_seconds, 1e-9), out.string());
  spdlog::info(
      "sfm: seconds per stage: detect {:.1f}, match {:.1f}, resect {:.1f}, triangulate "
      "{:.1f}, bundle adjustment {:.1f}, waiting for images {:.1f}, total {:.1f}; point colours "
      "{:.1f} s after",
      front.detect, front.match, back.resect, back.triangulate, back.bundle_adjustment,
      stats.load_seconds, stats.total_seconds, color_stats.seconds);
}

}  // namespace

void RegisterSfmCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<SfmCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "sfm", "Incremental rig SfM (Harris + ZNCC tracks, OpenGV, local bundle adjustment)");
  command->add_option("drive", o->drive, "Drive folder (rig.json, images/<camera>/...)")
      ->required();
  command->add_option("--out", o->out, "Output folder (poses.tum, points.ply, sparse/, stats/)");
  command->add_flag("--central", o->central, "Central approximation (default: rig.json)");
  command->add_flag("--non-central", o->non_central, "True camera offsets (default: rig.json)");
  command
      ->add_option("--downscale", o->tracks.harris.downscale,
                   "Shrink the images by this factor before detection (paper: 2)")
      ->capture_default_str();
  command->add_option("--corners", o->tracks.harris.max_corners, "Harris corners per image")
      ->capture_default_str();
  command
      ->add_option("--min-tracked-share", o->tracker.keyframes.min_tracked_share,
                   "Keyframe once fewer of the last keyframe's points are tracked")
      ->capture_default_str();
  command->add_option("--max-frames", o->max_frames, "0: the whole drive")->capture_default_str();
  command
      ->add_option("--prefetch", o->prefetch.frames_ahead,
                   "Frames whose images are decoded ahead of the SfM")
      ->capture_default_str();
  command
      ->add_option("--scene-depth", o->scene_depth,
                   "Typical scene depth (m), for the warning on large camera offsets in central "
                   "mode")
      ->capture_default_str();
  command->add_option("--frame-rate", o->frame_rate, "Timestamps of poses.tum: frame / rate")
      ->capture_default_str();
  command->callback([o, &global] { RunSfm(*o, global); });
}

}  // namespace omni
