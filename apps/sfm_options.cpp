#include "apps/sfm_options.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <string>

#include "calib/error.h"
#include "sfm/harris.h"
#include "sfm/ransac.h"

namespace omni {

int CornersPerImage(int num_cameras, int budget_factor) {
  return std::min(
      2000, std::max(1, budget_factor) * std::clamp(2100 / std::max(1, num_cameras), 350, 2000));
}

SfmProfile SfmProfileNamed(const std::string& name) {
  SfmProfile profile;  // realtime: the defaults
  if (name == "realtime") return profile;
  if (name != "accurate" && name != "offline")
    throw InputError("", "--profile", "expected realtime, accurate or offline, got '" + name + "'");
  profile.corner_budget_factor = 2;
  if (name == "offline") profile.min_tracked_share = 0.5;
  return profile;
}

void AddSfmOptions(CLI::App* command, SfmCommandLine* o) {
  command->add_flag("--central", o->central, "Central approximation (default: rig.json)");
  command->add_flag("--non-central", o->non_central, "True camera offsets (default: rig.json)");
  command
      ->add_option("--downscale", o->downscale,
                   "Shrink the images by this factor before detection (paper: 2; default 0: "
                   "from the image size, the longest side to about 640 pixels)")
      ->capture_default_str();
  command
      ->add_option(
          "--profile", o->profile,
          "How much work each frame gets: realtime (capture rate on 2 cores), accurate "
          "(twice the corners: about 1.7 times the time, a denser map and a more "
          "accurate surface) or offline (twice the corners and nearly every frame a "
          "keyframe: about 6.5 times the time, the most accurate poses, for sfm); --corners and "
          "--min-tracked-share, when given, win")
      ->capture_default_str();
  command
      ->add_option("--corners", o->corners,
                   "Harris corners per image (default 0: 2100 over the rig's cameras, between 350 "
                   "and 2000; twice that with --profile accurate or offline, at most 2000)")
      ->capture_default_str();
  command
      ->add_option("--corner-quality", o->sfm.tracks.harris.quality_level,
                   "A corner's Harris response is at least this share of the image's strongest "
                   "(lower: more corners in weak texture)")
      ->capture_default_str();
  command
      ->add_option("--continuation-pool", o->continuation_pool,
                   "The frame before's tracks are continued among this many times --corners "
                   "corners of each image; the frame keeps those that continue a track, then the "
                   "strongest others, up to --corners (1: none; default 0: 2)")
      ->capture_default_str();
  command
      ->add_option("--epipolar-min-depth", o->sfm.tracks.epipolar_min_depth,
                   "Corners the image-motion model leaves unmatched are searched again along "
                   "their epipolar segment, given the predicted motion, down to this many times "
                   "the camera's step between frames: near structure (parked cars, poles) gets "
                   "tracked (0: off)")
      ->capture_default_str();
  command
      ->add_option("--epipolar-search-radius", o->sfm.tracks.epipolar_search_radius,
                   "Half width of the band around each epipolar segment, pixels of the working "
                   "image, where the motion was predicted exactly: the band widens by the "
                   "prediction's error on the frame before (wider: more look-alikes)")
      ->capture_default_str();
  command
      ->add_option("--epipolar-max-search-radius", o->sfm.tracks.epipolar_max_search_radius,
                   "The widest band (pixels of the working image); a camera whose predicted "
                   "rotation was off by more than half of it is not searched along")
      ->capture_default_str();
  command->add_flag(
      "--no-frame-points{false}", o->sfm.tracker.frame_points,
      "No frame points: the tracks that end between two keyframes give the surface nothing "
      "(default: triangulated from the tracked frames' poses and handed to the surface and "
      "points.ply, not to the map)");
  command
      ->add_option("--min-tracked-share", o->min_tracked_share,
                   "Keyframe once fewer than this share of the last keyframe's points are tracked "
                   "(default 0: 0.3, or 0.5 with --profile offline)")
      ->capture_default_str();
  command
      ->add_option("--min-followed-share", o->sfm.tracker.keyframes.min_followed_track_share,
                   "Keyframe also once fewer than this share of the last keyframe's tracks (its "
                   "observations, with or without a point) are still followed, so that short "
                   "tracks reach a second keyframe and the map (0: off)")
      ->capture_default_str();
  auto* max_frames = command->add_option("--max-frames", o->sfm.max_frames, "0: the whole drive")
                         ->capture_default_str();
  command
      ->add_option("--frames", o->frames,
                   "A:B: the drive's frames A to B-1 only (0-based, \"A:\" to the end), named "
                   "and stamped as in the whole drive (segments of a drive; see `merge`)")
      ->excludes(max_frames);
  command
      ->add_option("--resection-prior-share", o->sfm.tracker.resection_prior_share,
                   "A frame's pose predicted by the motion model is taken without the "
                   "resection's RANSAC when, refined, it explains this share of the frame's "
                   "observations of map points (1: always the RANSAC)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  const std::map<std::string, NoncentralHypotheses> hypotheses = {
      {"gp3p", NoncentralHypotheses::kGp3p},
      {"camera-p3p", NoncentralHypotheses::kCameraP3p},
      {"rig-centre-p3p", NoncentralHypotheses::kRigCentreP3p}};
  command
      ->add_option("--resection-hypotheses", o->sfm.tracker.noncentral_resection_hypotheses,
                   "Non-central mode: the resection's RANSAC hypotheses: gp3p (GP3P on any "
                   "three correspondences), camera-p3p (the P3P of three correspondences of one "
                   "camera, taken to the rig by its offset) or rig-centre-p3p (the P3P from the "
                   "cameras' mean centre, an approximation); each scored and the best refined "
                   "with the true offsets")
      ->transform(CLI::CheckedTransformer(hypotheses, CLI::ignore_case))
      ->option_text("TEXT=gp3p");
  command
      ->add_option("--resection-consensus", o->sfm.tracker.resection_consensus_angle_factor,
                   "The resection's RANSAC counts and refines on the correspondences within this "
                   "times its angle, then keeps as inliers those within the angle (1: one angle "
                   "for all; default 0: 3 in non-central mode, 1 in central mode)")
      ->capture_default_str();
  command->add_flag("--resection-prior-after-search", o->sfm.tracker.resection_prior_after_search,
                    "After the map-point search, the frame's first pose is kept without the "
                    "RANSAC when it keeps at least its inliers");
  command
      ->add_option("--frame-ray-step", o->sfm.tracker.frame_ray_step,
                   "The points handed to the surface also carry the rays of every N-th tracked "
                   "frame between keyframes (0: keyframe rays only)")
      ->capture_default_str();
  command
      ->add_option("--frame-ray-min-angle", o->frame_ray_min_angle_deg,
                   "--frame-ray-step: a frame ray only when at least this many degrees from the "
                   "point's rays before it (0: all)")
      ->capture_default_str();
  command
      ->add_option("--prefetch", o->sfm.prefetch.frames_ahead,
                   "Frames whose images are decoded ahead of the SfM")
      ->capture_default_str();
  command
      ->add_option("--prefetch-nice", o->sfm.prefetch.thread_nice,
                   "The thread that decodes the images and finds their corners ahead of the SfM "
                   "runs this much nicer than it (0 to 19; 0: the same priority)")
      ->capture_default_str();
  command->add_flag("!--no-loop-closure", o->sfm.loop_closure,
                    "Do not detect revisits nor correct the drift");
  command->add_flag("!--no-global-ba", o->sfm.loop.global_bundle_adjustment,
                    "After a loop closure, correct with the pose graph only");
  command->add_flag("!--no-final-ba", o->sfm.final_bundle_adjustment,
                    "No global bundle adjustment when the drive ends");
  command->add_flag("!--final-ba-whole-map", o->sfm.final_bundle_adjustment_tail,
                    "The final adjustment frees every keyframe, even right after a loop "
                    "closure's global adjustment (default: then only the keyframes since and "
                    "the local window before them)");
  command->add_flag("!--no-final-ba-frames", o->sfm.final_bundle_adjustment_frames,
                    "The final adjustment leaves out the tracked frames between keyframes "
                    "(default: it adjusts them with the keyframes, more rays for every point)");
  command
      ->add_option("--final-ba-frames-max-keyframes",
                   o->sfm.final_bundle_adjustment_frames_max_keyframes,
                   "The final adjustment adjusts the frames only when it frees at most this many "
                   "keyframes (0: any number; each frame adds to its time)")
      ->check(CLI::Range(0, 1000000))
      ->capture_default_str();
  command->add_flag("--final-ba-true-offsets", o->sfm.final_bundle_adjustment_true_offsets,
                    "Central mode: the final adjustment with the cameras' true offsets, their "
                    "scale estimated (default: the central approximation)");
  command
      ->add_option("--final-ba-merge-angle", o->sfm.final_bundle_adjustment_merge_angle,
                   "Before the final adjustment, fuse the points that one point fits within this "
                   "angle (radians; 0: none)")
      ->capture_default_str();
  command->add_flag("!--no-final-frame-refinement", o->sfm.final_frame_refinement,
                    "Frames between keyframes keep their pose between their keyframes (default: "
                    "each posed again against the final map)");
  command->add_flag("!--no-detect-ahead", o->sfm.detect_ahead,
                    "Detect each frame's corners on the SfM thread (default: on the image "
                    "prefetch thread, ahead of the frame's tracking; the same result)");
  command->add_flag("!--no-frames-between-keyframes", o->sfm.frame_poses_between_keyframes,
                    "A tracked frame follows only the keyframe it was tracked from (default: "
                    "both keyframes around it)");
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
  if (o->sfm.tracker.frame_ray_step < 0)
    throw InputError("", "--frame-ray-step", "expected 0 (off) or a step of 1 or more");
  if (!(o->frame_ray_min_angle_deg >= 0.0 && o->frame_ray_min_angle_deg < 180.0))
    throw InputError("", "--frame-ray-min-angle", "expected an angle in [0, 180) degrees");
  o->sfm.tracker.frame_ray_min_angle = o->frame_ray_min_angle_deg * M_PI / 180.0;
  if (!(o->scene_depth > 0.0)) throw InputError("", "--scene-depth", "expected a positive depth");
  if (!(o->downscale >= 0.0) || !std::isfinite(o->downscale))
    throw InputError("", "--downscale",
                     "expected 0 (from the image size) or a factor of 1 or more");
  o->sfm.tracker.central = o->central ? true : o->non_central ? false : rig.central;
  if (o->corners < 0) throw InputError("", "--corners", "expected 0 (from the rig) or a count");
  const double corner_quality = o->sfm.tracks.harris.quality_level;
  if (!(corner_quality >= 0.0 && corner_quality < 1.0))
    throw InputError("", "--corner-quality", "expected a share in [0, 1)");
  const double consensus = o->sfm.tracker.resection_consensus_angle_factor;
  if (consensus != 0.0 && !ValidConsensusAngleFactor(consensus))
    throw InputError("", "--resection-consensus", "expected 0 (from the mode) or 1 to 100");
  if (o->continuation_pool != 0.0) {
    if (!(o->continuation_pool >= 1.0 && o->continuation_pool <= 10.0))
      throw InputError("", "--continuation-pool",
                       "expected 0 (from the mode) or a factor in [1, 10]");
    o->sfm.tracks.continuation_pool = o->continuation_pool;
    o->sfm.continuation_pool_in_central_mode = true;
  }
  if (!(o->sfm.tracks.epipolar_min_depth >= 0.0) ||
      !std::isfinite(o->sfm.tracks.epipolar_min_depth))
    throw InputError("", "--epipolar-min-depth", "expected 0 (off) or a positive number of steps");
  if (!(o->sfm.tracks.epipolar_search_radius > 0.0) ||
      !std::isfinite(o->sfm.tracks.epipolar_search_radius))
    throw InputError("", "--epipolar-search-radius", "expected a positive number of pixels");
  if (!(o->sfm.tracks.epipolar_max_search_radius >= o->sfm.tracks.epipolar_search_radius) ||
      !std::isfinite(o->sfm.tracks.epipolar_max_search_radius))
    throw InputError("", "--epipolar-max-search-radius",
                     "expected a number of pixels at least --epipolar-search-radius");
  const SfmProfile profile = SfmProfileNamed(o->profile);
  o->sfm.tracks.harris.max_corners =
      o->corners > 0 ? o->corners : CornersPerImage(rig.NumCameras(), profile.corner_budget_factor);
  if (!(o->min_tracked_share >= 0.0 && o->min_tracked_share < 1.0))
    throw InputError("", "--min-tracked-share",
                     "expected 0 (from the profile) or a share in (0, 1)");
  o->sfm.tracker.keyframes.min_tracked_share =
      o->min_tracked_share > 0.0 ? o->min_tracked_share : profile.min_tracked_share;
  const double followed = o->sfm.tracker.keyframes.min_followed_track_share;
  if (!(followed >= 0.0 && followed < 1.0))
    throw InputError("", "--min-followed-share", "expected 0 (off) or a share in (0, 1)");
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

void ApplyFrameRange(const Drive& drive, SfmCommandLine* o) {
  if (o->frames.empty()) return;
  const size_t colon = o->frames.find(':');
  const auto bad = [&](const std::string& why) {
    throw InputError(drive.folder().string(), "--frames", "'" + o->frames + "': " + why);
  };
  if (colon == std::string::npos) bad("expected A:B (frames A to B-1) or A: (A to the end)");
  const auto parse = [&](const std::string& text, long fallback) -> long {
    if (text.empty()) return fallback;
    size_t used = 0;
    long value = -1;
    try {
      value = std::stol(text, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used != text.size() || value < 0) bad("'" + text + "' is not a frame index (0 or more)");
    return value;
  };
  const long frames = static_cast<long>(drive.NumFrames());
  const long first = parse(o->frames.substr(0, colon), 0);
  long end = parse(o->frames.substr(colon + 1), frames);
  if (end <= first) bad("the range is empty (B must be above A)");
  if (first >= frames)
    bad("starts at frame " + std::to_string(first) + " but the drive has " +
        std::to_string(frames) + " frames");
  if (end > frames) {
    spdlog::warn("--frames {}: the drive has {} frames; the range ends at its last frame ({})",
                 o->frames, frames, drive.FrameName(static_cast<size_t>(frames - 1)));
    end = frames;
  }
  o->sfm.first_frame = static_cast<int>(first);
  o->sfm.max_frames = static_cast<int>(end - first);
  spdlog::info("frames {} to {} of {} ({} to {})", first, end - 1, frames,
               drive.FrameName(static_cast<size_t>(first)),
               drive.FrameName(static_cast<size_t>(end - 1)));
}

}  // namespace omni
