#pragma once
// The SfM options that `omnisculpt sfm` and `omnisculpt reconstruct` share, registered once.

#include <CLI/CLI.hpp>
#include <string>

#include "calib/drive.h"
#include "calib/rig.h"
#include "pipeline/sfm_runner.h"
#include "sfm/keyframe_selection.h"

namespace omni {

struct SfmCommandLine {
  bool central = false;      // --central: force the central approximation
  bool non_central = false;  // --non-central: force the true camera offsets
  double frame_rate = 15.0;  // timestamps of poses.tum: frame index / frame_rate
  // --downscale; 0: from the image size (WorkingDownscale of the largest camera image).
  double downscale = 0.0;
  // --profile: how much work each frame gets (SfmProfile), for the options below left at 0.
  std::string profile = "realtime";
  // --corners; 0: from the rig and the profile, CornersPerImage(number of cameras, profile).
  int corners = 0;
  // --min-tracked-share; 0: from the profile (SfmProfile::min_tracked_share).
  double min_tracked_share = 0.0;
  // --continuation-pool; 0: SfmRunnerOptions' rule (the pool in non-central mode only).
  double continuation_pool = 0.0;
  // Central mode treats the camera centres as one point: a camera offset d seen at depth z
  // bends the rays by about d / z radians. The map's scale is unknown in central mode, so the
  // depth is the user's (metres; street facades are 5-20 m away); above this ratio of the
  // largest offset to it, the log says the non-central mode is the right one.
  double scene_depth = 10.0;
  double max_central_offset_ratio = 0.01;
  // --frame-ray-min-angle (degrees): TrackerOptions::frame_ray_min_angle.
  double frame_ray_min_angle_deg = 1.0;
  // --frames A:B: the drive's frames A to B-1 ("A:" to the end); empty: every frame.
  std::string frames;
  SfmRunnerOptions sfm;
};

// What --profile sets, where --corners and --min-tracked-share are not given. The front end's
// work per frame buys the map's density, and with it the surface's accuracy and the poses'
// (docs/figures.md F65, the demo drive on 2 cores, non-central):
// - realtime (the default): about 2100 corners per keyframe over the rig's cameras, a keyframe
//   once 70 % of the last one's points are lost; about 27 frames/s.
// - accurate: twice the corners; 1.7 times the time, the surface's pixel F@0.2 0.745 -> 0.786
//   and its tail 3.6 -> 3.0 %, the keyframes' error 2.70 -> 1.39 cm.
// - offline: twice the corners and a keyframe once half the last one's points are lost (nearly
//   every frame of a car's drive); 6.5 times the time, F@0.2 0.802, tail 2.6 %, and the
//   keyframes' error within twice COLMAP 3.8's on the short drive's 60 frames. A profile for
//   the poses: on the long paper drive its surface lost recall (F@0.5 0.857, accurate 0.888).
struct SfmProfile {
  int corner_budget_factor = 1;  // times the rig's corner budget (CornersPerImage)
  // KeyframeSelectionOptions::min_tracked_share (its default unless the profile changes it).
  double min_tracked_share = KeyframeSelectionOptions{}.min_tracked_share;
};
// The profile of that name (realtime, accurate, offline); InputError naming --profile otherwise.
SfmProfile SfmProfileNamed(const std::string& name);

// Harris corners per image when --corners is not given: a keyframe's budget of about 2100
// corners (the paper: about 2000 over six images) spread over the rig's cameras, between 350
// and 2000 per image, times the profile's factor, at most 2000. A single camera has 2000: with 350
// a phone photo kept too few matches, with 700 its steps' directions were 3.5 degrees off, and 2000
// instead of 1000 made its keyframes' error 0.75-0.83 times as large over 40 starts of two
// drives at 0.9 times the frames/s (docs/figures.md F85).
int CornersPerImage(int num_cameras, int budget_factor = 1);

// Adds the SfM group to `command` (the values land in *options, which must outlive it).
void AddSfmOptions(CLI::App* command, SfmCommandLine* options);
// Checks the group (InputError naming the option), sets the mode from the flags or the rig's
// own `central`, and logs the mode (a warning when the central mode bends the rays too much).
void ApplySfmOptions(const Rig& rig, const std::string& command_name, SfmCommandLine* options);
// Sets the run's frame range from --frames (InputError when it is not A:B with A < B, or does not
// start inside the drive; a range past the drive's end is cut to it, with a warning).
void ApplyFrameRange(const Drive& drive, SfmCommandLine* options);

}  // namespace omni
