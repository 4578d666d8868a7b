#pragma once
// The SfM options that `omnisculpt sfm` and `omnisculpt reconstruct` share, registered once.

#include <CLI/CLI.hpp>
#include <string>

#include "calib/drive.h"
#include "calib/rig.h"
#include "pipeline/sfm_runner.h"

namespace omni {

struct SfmCommandLine {
  bool central = false;      // --central: force the central approximation
  bool non_central = false;  // --non-central: force the true camera offsets
  double frame_rate = 15.0;  // timestamps of poses.tum: frame index / frame_rate
  // --downscale; 0: from the image size (WorkingDownscale of the largest camera image).
  double downscale = 0.0;
  // --corners; 0: from the rig, CornersPerImage(number of cameras).
  int corners = 0;
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

// Harris corners per image when --corners is not given: a keyframe's budget of about 2100
// corners (the paper: about 2000 over six images) spread over the rig's cameras, between 350
// and 1000 per image (a single camera has 1000: with 350 a phone photo kept too few matches,
// with 700 its steps' directions were 3.5 degrees off).
int CornersPerImage(int num_cameras);

// Adds the SfM group to `command` (the values land in *options, which must outlive it).
void AddSfmOptions(CLI::App* command, SfmCommandLine* options);
// Checks the group (InputError naming the option), sets the mode from the flags or the rig's
// own `central`, and logs the mode (a warning when the central mode bends the rays too much).
void ApplySfmOptions(const Rig& rig, const std::string& command_name, SfmCommandLine* options);
// Sets the run's frame range from --frames (InputError when it is not A:B with A < B, or does not
// start inside the drive; a range past the drive's end is cut to it, with a warning).
void ApplyFrameRange(const Drive& drive, SfmCommandLine* options);

}  // namespace omni
