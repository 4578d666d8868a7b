// `omnisculpt sfm DRIVE --out OUT [--central|--non-central]` (issue 8): the incremental rig SfM
// of sfm/ on a drive's images, writing the keyframe poses (poses.tum), the points (points.ply)
// and per-frame statistics (stats/sfm_frames.csv). A first version: frame-to-frame ZNCC tracks
// per camera (sfm/track_builder.h) feeding sfm/tracker.h; no COLMAP export, no re-localisation
// after a tracking failure yet.

#include <spdlog/spdlog.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <sstream>
#include <string>

#include "apps/commands.h"
#include "calib/atomic_file.h"
#include "calib/drive.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "calib/tum.h"
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
  TrackBuilderOptions tracks;
  TrackerOptions tracker;
};

void RunSfm(SfmCommandOptions& o, const GlobalOptions& global) {
  if (o.out.empty()) throw InputError("", "--out", "an output folder is required");
  if (o.central && o.non_central)
    throw InputError("", "--central, --non-central", "give at most one of them");
  if (!(o.frame_rate > 0.0)) throw InputError("", "--frame-rate", "expected a positive rate");
  const Drive drive = Drive::Open(o.drive);
  const Rig& rig = drive.rig();
  o.tracker.central = o.central ? true : o.non_central ? false : rig.central;
  for (const std::string& problem : {o.tracks.Check(), o.tracker.Check()})
    if (!problem.empty()) throw InputError("", "options", problem);
  spdlog::info("sfm: {} frames, {} cameras, {} mode (largest camera offset {:.3f} m)",
               drive.NumFrames(), rig.NumCameras(), o.tracker.central ? "central" : "non-central",
               rig.MaxCenterOffset());

  TrackBuilder builder(rig, o.tracks);
  Tracker tracker(rig, o.tracker);
  const size_t num_frames =
      o.max_frames > 0 ? std::min<size_t>(drive.NumFrames(), o.max_frames) : drive.NumFrames();
  std::ostringstream csv;
  csv << "frame,name,corners,matched,tracked,keyframe,inliers,status\n";
  const auto start = std::chrono::steady_clock::now();
  int untracked = 0;
  for (size_t f = 0; f < num_frames; ++f) {
    std::vector<cv::Mat> images;
    for (size_t c = 0; c < rig.NumCameras(); ++c) images.push_back(drive.LoadGray(f, c));
    const TrackedFrame frame = builder.AddFrame(images);
    const FrameResult result = tracker.AddFrame(frame.observations);
    untracked += result.tracked ? 0 : 1;
    csv << f << ',' << drive.FrameName(f) << ',' << frame.num_corners << ',' << frame.num_matched
        << ',' << result.tracked << ',' << result.keyframe << ',' << result.inliers << ','
        << result.status << '\n';
    if (!result.tracked)
      spdlog::warn("frame {}: not tracked ({})", drive.FrameName(f), result.status);
    if (!global.quiet && ((f + 1) % 25 == 0 || f + 1 == num_frames)) {
      const double seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const double rate = (f + 1) / std::max(seconds, 1e-9);
      spdlog::info("sfm: frame {}/{}, {:.1f} frames/s, ETA {:.0f} s, {} keyframes, {} points",
                   f + 1, num_frames, rate, (num_frames - f - 1) / rate, tracker.NumKeyframes(),
                   tracker.NumPoints());
    }
  }
  tracker.Finish();
  std::vector<FinalizedKeyframe> keyframes = tracker.TakeFinalized();
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
  WriteTum(poses, out / "poses.tum");
  WritePlyPoints(cloud, out / "points.ply");
  WriteTextFileAtomically(out / "stats" / "sfm_frames.csv", csv.str());
  spdlog::info("sfm: {} keyframes, {} points, {} of {} frames not tracked, written to {}",
               poses.size(), cloud.points.size(), untracked, num_frames, out.string());
}

}  // namespace

void RegisterSfmCommand(CLI::App& app, const GlobalOptions& global) {
  auto o = std::make_shared<SfmCommandOptions>();
  CLI::App* command = app.add_subcommand(
      "sfm", "Incremental rig SfM (Harris + ZNCC tracks, OpenGV, local bundle adjustment)");
  command->add_option("drive", o->drive, "Drive folder (rig.json, images/<camera>/...)")
      ->required();
  command->add_option("--out", o->out, "Output folder (poses.tum, points.ply, stats/)");
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
  command->add_option("--frame-rate", o->frame_rate, "Timestamps of poses.tum: frame / rate")
      ->capture_default_str();
  command->callback([o, &global] { RunSfm(*o, global); });
}

}  // namespace omni
