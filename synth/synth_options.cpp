#include "synth/synth_options.h"

#include <cmath>
#include <sstream>

#include "calib/error.h"

namespace omni {
namespace {

// Appends "field: problem" to `errors` when `bad`.
void Require(bool good, const std::string& field, const std::string& problem, std::string* errors) {
  if (good) return;
  if (!errors->empty()) *errors += "; ";
  *errors += field + ": " + problem;
}

}  // namespace

std::string SynthCityOptions::Check() const {
  std::string e;
  Require(block_size_x > 2 * sidewalk_width + 2.0 && block_size_y > 2 * sidewalk_width + 2.0,
          "city.block_size", "must leave at least 2 m between the sidewalks", &e);
  Require(block_jitter >= 0 && block_jitter < 0.5, "city.block_jitter", "must be in [0, 0.5)", &e);
  Require(loop_blocks_x >= 1 && loop_blocks_y >= 1, "city.loop_blocks", "must be at least 1", &e);
  Require(ring_blocks >= 0 && ring_blocks <= 4, "city.ring_blocks", "must be in [0, 4]", &e);
  Require(road_half_width >= 2.5, "city.road_half_width", "must be at least 2.5 m", &e);
  Require(sidewalk_width >= 1.5, "city.sidewalk_width", "must be at least 1.5 m", &e);
  Require(kerb_height >= 0 && kerb_height < 0.5, "city.kerb_height", "must be in [0, 0.5)", &e);
  Require(building_depth >= 2.0, "city.building_depth", "must be at least 2 m", &e);
  Require(building_min_width >= 3.0 && building_max_width >= building_min_width,
          "city.building_width", "need 3 <= min <= max", &e);
  Require(building_min_height >= 5.0 && building_max_height >= building_min_height,
          "city.building_height", "need 5 <= min <= max", &e);
  Require(floor_height_min >= 2.4 && floor_height_max >= floor_height_min, "city.floor_height",
          "need 2.4 <= min <= max", &e);
  Require(window_depth > 0 && window_depth < 1.0, "city.window_depth", "must be in (0, 1)", &e);
  Require(balcony_probability >= 0 && balcony_probability <= 1, "city.balcony_probability",
          "must be in [0, 1]", &e);
  Require(cornice_depth >= 0 && cornice_depth < 1.5, "city.cornice_depth", "must be in [0, 1.5)",
          &e);
  Require(pole_spacing > 1 && tree_spacing > 1 && parked_car_spacing > 5, "city.spacing",
          "poles and trees need > 1 m, cars > 5 m", &e);
  Require(tree_crown_subdivisions >= 0 && tree_crown_subdivisions <= 3,
          "city.tree_crown_subdivisions", "must be in [0, 3]", &e);
  return e;
}

std::string SynthTrajectoryOptions::Check() const {
  std::string e;
  Require(num_frames >= 2, "trajectory.num_frames", "must be at least 2", &e);
  Require(frame_rate > 0, "trajectory.frame_rate", "must be positive", &e);
  Require(rig_height > 0.5, "trajectory.rig_height", "must be above 0.5 m", &e);
  Require(lane_offset >= 0, "trajectory.lane_offset", "must not be negative", &e);
  Require(corner_radius >= 3.0, "trajectory.corner_radius", "must be at least 3 m", &e);
  Require(overlap >= 0, "trajectory.overlap", "must not be negative", &e);
  Require(speed_variation >= 0 && speed_variation < 0.9, "trajectory.speed_variation",
          "must be in [0, 0.9)", &e);
  Require(speed_cycles >= 0, "trajectory.speed_cycles", "must not be negative", &e);
  Require(std::abs(pitch_amplitude_deg) <= 10 && std::abs(roll_amplitude_deg) <= 10,
          "trajectory.pitch/roll_amplitude_deg", "must be within 10 degrees", &e);
  Require(std::abs(bounce_amplitude) <= 0.5, "trajectory.bounce_amplitude", "must be <= 0.5 m", &e);
  Require(suspension_period > 0, "trajectory.suspension_period", "must be positive", &e);
  Require(frame_step >= 1, "trajectory.frame_step", "must be at least 1", &e);
  Require(frame_step == 1 || (num_frames - 1) / frame_step >= 1, "trajectory.frame_step",
          "must leave at least 2 of the num_frames frames", &e);
  return e;
}

std::string SynthRenderOptions::Check() const {
  std::string e;
  Require(supersampling >= 1 && supersampling <= 8, "render.supersampling", "must be in [1, 8]",
          &e);
  Require(refine_contrast >= 0, "render.refine_contrast", "must not be negative", &e);
  Require(ambient >= 0 && diffuse >= 0 && ambient + diffuse <= 1.5, "render.ambient/diffuse",
          "must be >= 0 with a sum <= 1.5", &e);
  Require(sun_direction.size() == 3 && sun_direction[0] * sun_direction[0] +
                                               sun_direction[1] * sun_direction[1] +
                                               sun_direction[2] * sun_direction[2] >
                                           1e-12,
          "render.sun_direction", "expected 3 values, not all zero", &e);
  Require(sky_horizon >= 0 && sky_horizon <= 1 && sky_zenith >= 0 && sky_zenith <= 1,
          "render.sky_horizon/sky_zenith", "must be in [0, 1]", &e);
  Require(camera_gain_spread >= 0 && camera_gain_spread < 0.9, "render.camera_gain_spread",
          "must be in [0, 0.9)", &e);
  Require(exposure_spread >= 0 && exposure_spread < 0.9, "render.exposure_spread",
          "must be in [0, 0.9)", &e);
  Require(exposure_offset >= 0 && exposure_offset <= 64, "render.exposure_offset",
          "must be in [0, 64] grey levels", &e);
  Require(noise_sigma >= 0, "render.noise_sigma", "must not be negative", &e);
  Require(png_compression >= 0 && png_compression <= 9, "render.png_compression",
          "must be in [0, 9]", &e);
  Require(image_scale > 0.05 && image_scale <= 4, "render.image_scale", "must be in (0.05, 4]", &e);
  return e;
}

std::string SynthOptions::Check() const {
  std::string e;
  for (const std::string& part : {city.Check(), trajectory.Check(), render.Check()}) {
    if (part.empty()) continue;
    if (!e.empty()) e += "; ";
    e += part;
  }
  return e;
}

std::vector<SynthPreset> SynthPresets() {
  return {
      {"tiny", "30 frames around one small block (~98 m loop, ~3.6 m between frames): unit tests"},
      {"demo",
       "400 frames around one block (~170 m loop, ~0.45 m between frames): the README's drive"},
      {"paper",
       "1550 frames around 3x2 blocks (~600 m loop, ~0.4 m between frames): the paper's "
       "synthetic sequence"},
      {"short",
       "130 frames around the tiny block (~91 m loop) and 12 m past the start, ~0.8 m between "
       "frames: end-to-end tests of sfm and reconstruct"},
  };
}

SynthOptions SynthPresetOptions(const std::string& name) {
  SynthOptions options;
  options.preset = name;
  if (name == "tiny") {
    options.city.block_size_x = 16.0;
    options.city.block_size_y = 12.0;
    options.city.sidewalk_width = 2.5;
    options.city.building_depth = 6.0;
    options.city.building_min_width = 4.0;
    options.city.building_max_width = 9.0;
    options.city.building_max_height = 18.0;
    options.trajectory.num_frames = 30;
    options.trajectory.corner_radius = 6.0;
    options.trajectory.overlap = 6.0;
    options.trajectory.speed_cycles = 1;
  } else if (name == "short") {
    // The tiny city, driven slowly enough for the SfM to track every frame, once around and
    // past the start so that a loop closure has overlap to find.
    options = SynthPresetOptions("tiny");
    options.preset = name;
    options.trajectory.num_frames = 130;
    options.trajectory.overlap = 12.0;
    // Wide turns (the largest radius the block allows) and a steadier speed: about 4.5 degrees
    // of heading per frame in the turns instead of the tiny preset's abrupt 10.
    options.trajectory.corner_radius = 12.0;
    options.trajectory.speed_variation = 0.1;
  } else if (name == "demo") {
    options.city.block_size_x = 36.0;
    options.city.block_size_y = 28.0;
    options.trajectory.num_frames = 400;
  } else if (name == "paper") {
    // Paper section 5: 1553 frames on a 621 m closed loop, rig about 4 m above the ground.
    options.city.block_size_x = 44.0;
    options.city.block_size_y = 62.0;
    options.city.loop_blocks_x = 3;
    options.city.loop_blocks_y = 2;
    options.trajectory.num_frames = 1550;
    options.trajectory.speed_cycles = 8;
  } else {
    std::ostringstream list;
    for (const SynthPreset& preset : SynthPresets()) {
      list << (list.tellp() > 0 ? ", " : "") << preset.name;
    }
    throw InputError("", "--preset",
                     "unknown preset '" + name + "' (expected one of: " + list.str() + ")");
  }
  return options;
}

}  // namespace omni
