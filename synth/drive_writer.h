#pragma once
// A synthetic drive: the city, the trajectory and the rig, and the writer of its
// drive folder (docs/design.md §4):
//   DRIVE/rig.json                       the rig used (scaled when render.image_scale != 1)
//   DRIVE/images/<camera>/<frame>.png    frames 000000, 000001, ... (with a frame step K:
//                                        000000, 0000K0, ..., named by trajectory index)
//   DRIVE/gt/poses.tum                   world_from_rig per frame written, at frame / frame_rate
//   DRIVE/frames.csv                     only with a frame step K > 1: frame,camera,timestamp_s
//   DRIVE/gt/mesh.ply                    exactly the triangles rendered, metres
//   DRIVE/gt/scene.json                  every parameter, the seed and the preset

#include <filesystem>
#include <string>
#include <vector>

#include "calib/rig.h"
#include "synth/city.h"
#include "synth/synth_options.h"
#include "synth/trajectory.h"

namespace omni::synth {

struct SyntheticDrive {
  SynthOptions options;
  Rig rig;  // as rendered: scaled by options.render.image_scale
  CityScene scene;
  Trajectory trajectory;
  std::vector<double> camera_gains;      // per camera
  std::vector<double> exposure_gains;    // per camera, 1 without render.exposure_spread
  std::vector<double> exposure_offsets;  // per camera, grey levels, 0 without exposure_offset
  // The trajectory indices written (every trajectory.frame_step-th), increasing.
  std::vector<size_t> written_frames;

  // Frames of the trajectory (written or not).
  size_t NumFrames() const { return trajectory.world_from_rig.size(); }
  // Capture time of trajectory frame `frame`: frame / frame_rate, seconds.
  double FrameTimestamp(size_t frame) const;
  // The gain and the offset (grey levels) that camera `camera` renders with.
  double RenderGain(size_t camera) const {
    return camera_gains.at(camera) * exposure_gains.at(camera);
  }
  // world_from_rig * rig_from_cam: the camera's true pose (non-central rendering).
  Rigid3d WorldFromCamera(size_t frame, size_t camera) const;
  // Seed of the jitter and noise of one image.
  uint64_t ImageSeed(size_t frame, size_t camera) const;
};

// Throws InputError when the options or the rig are invalid.
SyntheticDrive MakeSyntheticDrive(const SynthOptions& options, const Rig& rig);

// "000042".
std::string SynthFrameName(size_t frame);

// Every parameter, for gt/scene.json.
std::string SceneJson(const SyntheticDrive& drive);

struct SynthSummary {
  size_t frames = 0;  // written
  size_t cameras = 0;
  size_t triangles = 0;
  double loop_length = 0;  // metres
  double driven_length = 0;
  uint64_t rays = 0;
  double render_seconds = 0;  // rendering and PNG writing
  double total_seconds = 0;
};

struct SynthWriteOptions {
  bool force = false;    // replace an existing non-empty output folder (only at the end)
  bool progress = true;  // log progress lines (spdlog info)
};

// Renders and writes the drive into "<out>.partial", then renames it to `out`, so an
// interrupted run never leaves a folder that looks complete. Throws InputError when `out`
// exists and is not empty (without force) or cannot be written.
SynthSummary WriteSyntheticDrive(const SynthOptions& options, const Rig& rig,
                                 const std::filesystem::path& out,
                                 const SynthWriteOptions& write_options = {});

}  // namespace omni::synth
