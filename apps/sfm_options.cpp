#include "apps/sfm_options.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

#include "calib/error.h"
#include "sfm/harris.h"

namespace omni {

void AddSfmOptions(CLI::App* command, SfmCommandLine* o) {
  command->add_flag("--central", o->central, "Central approximation (default: rig.json)");
  command->add_flag("--non-central", o->non_central, "True camera offsets (default: rig.json)");
  command
      ->add_option("--downscale", o->downscale,
                   "Shrink the images by this factor before detection (paper: 2; default 0: "
                   "from the image size, the longest side to about 640 pixels)")
      ->capture_default_str();
  command->add_option("--corners", o->sfm.tracks.harris.max_corners, "Harris corners per image")
      ->capture_default_str();
  command
      ->add_option("--min-tracked-share", o->sfm.tracker.keyframes.min_tracked_share,
                   "Keyframe once fewer of the last keyframe's points are tracked")
      ->capture_default_str();
  command->add_option("--max-frames", o->sfm.max_frames, "0: the whole drive")
      ->capture_default_str();
  command
      ->add_option("--prefetch", o->sfm.prefetch.frames_ahead,
                   "Frames whose images are decoded ahead of the SfM")
      ->capture_default_str();
  command->add_flag("!--no-loop-closure", o->sfm.loop_closure,
                    "Do not detect revisits nor correct the drift");
  command->add_flag("!--no-global-ba", o->sfm.loop.global_bundle_adjustment,
                    "After a loop closure, correct with the pose graph only");
  command->add_flag("!--no-final-ba", o->sfm.final_bundle_adjustment,
                    "No global bundle adjustment when the drive ends");
  command
      ->add_option("--scene-depth", o->scene_depth,
                   "Typical scene depth (m), for the warning on large camera offsets in central "
                   "mode")
      ->capture_default_str();
  command
      ->add_option("--frame-rate", o->frame_rate,
                   "Timestamps of poses.tum: frame / rate (when the drive has no frames.csv)")
      ->capture_default_str();
}

void ApplySfmOptions(const Rig& rig, const std::string& command_name, SfmCommandLine* o) {
  if (o->central && o->non_central)
    throw InputError("", "--central, --non-central", "give at most one of them");
  if (!(o->frame_rate > 0.0) || !std::isfinite(o->frame_rate))
    throw InputError("", "--frame-rate", "expected a positive rate");
  if (o->sfm.max_frames < 0) throw InputError("", "--max-frames", "expected 0 or a positive count");
  if (!(o->scene_depth > 0.0)) throw InputError("", "--scene-depth", "expected a positive depth");
  if (!(o->downscale >= 0.0) || !std::isfinite(o->downscale))
    throw InputError("", "--downscale",
                     "expected 0 (from the image size) or a factor of 1 or more");
  o->sfm.tracker.central = o->central ? true : o->non_central ? false : rig.central;
  if (o->downscale > 0.0) {
    o->sfm.tracks.harris.downscale = o->downscale;
  } else {
    int width = 0, height = 0;
    for (const Camera& camera : rig.cameras) {
      width = std::max(width, camera.width);
      height = std::max(height, camera.height);
    }
    o->sfm.tracks.harris.downscale = WorkingDownscale(width, height);
    if (o->sfm.tracks.harris.downscale > 1.0)
      spdlog::info("{}: images of {}x{} pixels, shrunk by {:.2f} for the SfM (--downscale)",
                   command_name, width, height, o->sfm.tracks.harris.downscale);
  }
  ThrowIfInvalid(o->sfm.Check(), "SfmRunnerOptions");
  const double offset_ratio = rig.MaxCenterOffset() / o->scene_depth;
  if (o->sfm.tracker.central && offset_ratio > o->max_central_offset_ratio)
    spdlog::warn(
        "{}: central mode, but the cameras are up to {:.2f} m from their mean centre, {:.1f} % "
        "of a {:.0f} m scene depth (--scene-depth): rays bent by up to {:.2f} degrees; the "
        "non-central mode (--non-central) is the right one for this rig",
        command_name, rig.MaxCenterOffset(), 100.0 * offset_ratio, o->scene_depth,
        offset_ratio * 180.0 / M_PI);
}

}  // namespace omni
