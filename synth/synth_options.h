#pragma once
// Options of a synthetic city drive: the city, the trajectory and the renderer, with
// the presets `tiny`, `demo` and `paper`. Every number the generator uses lives here, so that
// gt/scene.json can record all of them.

#include <cstdint>
#include <string>
#include <vector>

namespace omni {

// The city: a grid of blocks separated by streets; the drive loops around `loop_blocks_x` x
// `loop_blocks_y` blocks, and `ring_blocks` rings of blocks surround the loop so that both
// sides of every street driven have buildings.
struct SynthCityOptions {
  double block_size_x = 44.0;  // kerb to kerb along x, metres (includes the sidewalks)
  double block_size_y = 34.0;  // kerb to kerb along y
  double block_jitter = 0.15;  // each block size varies by up to this fraction
  int loop_blocks_x = 1;
  int loop_blocks_y = 1;
  int ring_blocks = 1;
  double road_half_width = 5.0;  // centre line to kerb
  double sidewalk_width = 3.0;   // kerb to facade line
  double kerb_height = 0.15;
  double building_depth = 11.0;  // deepest footprint across the facade line
  double building_min_width = 6.0;
  double building_max_width = 18.0;
  double building_min_height = 7.0;
  double building_max_height = 26.0;
  double floor_height_min = 2.9;
  double floor_height_max = 3.6;
  double window_depth = 0.25;         // recess of windows and doors behind the facade
  double balcony_probability = 0.25;  // per window above the ground floor
  double cornice_depth = 0.35;        // protrusion of the roof cornice
  double pole_spacing = 18.0;         // mean distance between poles along a sidewalk
  double tree_spacing = 22.0;         // mean distance between trees along a sidewalk
  double parked_car_spacing = 16.0;   // mean distance between parked cars along a kerb
  int tree_crown_subdivisions = 1;    // icosahedron subdivisions of a crown

  std::string Check() const;
};

// The loop: a rounded rectangle along the street centre lines around the loop blocks, driven
// counter-clockwise in the right lane, a little more than once so that the end overlaps the
// beginning.
struct SynthTrajectoryOptions {
  int num_frames = 400;
  double frame_rate = 15.0;          // frames per second (timestamps of gt/poses.tum)
  double rig_height = 4.0;           // rig origin above the road, metres (paper: about 4 m)
  double lane_offset = 1.5;          // right of the centre line
  double corner_radius = 10.0;       // radius of the turns, metres
  double overlap = 12.0;             // metres driven past the start at the end of the loop
  double speed_variation = 0.2;      // relative speed varies by up to this fraction
  int speed_cycles = 3;              // speed oscillations over the drive
  double pitch_amplitude_deg = 0.5;  // suspension pitch
  double roll_amplitude_deg = 0.5;   // suspension roll
  double bounce_amplitude = 0.02;    // suspension height, metres
  double suspension_period = 1.7;    // seconds
  // Low frame rates: only one frame in frame_step of the num_frames above is written, keeping
  // its trajectory index as its name (000000, 000010, ...) and its capture time index /
  // frame_rate; with frame_step > 1 the drive gets a frames.csv of those times.
  int frame_step = 1;

  std::string Check() const;
};

struct SynthRenderOptions {
  // Adaptive anti-aliasing: one ray through each pixel centre, then pixels whose value differs
  // from a neighbour by more than `refine_contrast` (or whose neighbours hit another object or
  // surface) are rendered again with supersampling x supersampling jittered rays. Textures are
  // band-limited by the pixel footprint, so the edges of geometry are what needs the rays.
  int supersampling = 2;
  bool adaptive = true;          // false: every pixel gets supersampling^2 rays
  double refine_contrast = 0.2;  // in [0, 1] intensity
  double ambient = 0.65;         // shading: ambient + diffuse * max(0, n . sun)
  double diffuse = 0.4;
  std::vector<double> sun_direction = {0.45, 0.3, 0.84};  // towards the sun, world frame
  // The sky (rays that hit nothing): a smooth gradient from the horizon to the zenith, in
  // [0, 1]. Mid grey keeps silhouettes against the sky from dwarfing the texture corners in the
  // Harris quality threshold (0 and 0 give a black sky).
  double sky_horizon = 0.62;
  double sky_zenith = 0.45;
  double camera_gain_spread = 0.1;  // each camera's gain is 1 +- this, uniform
  // Exposure differences between the cameras, on top of camera_gain_spread: each camera's
  // exposure gain is drawn uniformly in [1 - exposure_spread, 1 + exposure_spread] and its
  // offset in [-exposure_offset, exposure_offset] grey levels, from the seed; applied to the
  // rendered intensity before the noise and the quantisation. 0 and 0 change nothing.
  double exposure_spread = 0.0;
  double exposure_offset = 0.0;  // 8-bit grey levels
  double noise_sigma = 1.5;      // sensor noise, 8-bit grey levels
  // Colour images (8-bit BGR PNGs): the walls, doors and trim of each building tinted by a
  // colour drawn from the seed and the building (its shaded albedo times the tint, channel by
  // channel, one sensor noise for the three); road, sidewalk, glass, roofs and the sky stay grey.
  // false: grey images (the default, as the drives have always been).
  bool colour = false;
  int png_compression = 1;   // 0..9, cv::IMWRITE_PNG_COMPRESSION
  double image_scale = 1.0;  // scales each camera's size and intrinsics (tests)

  std::string Check() const;
};

struct SynthOptions {
  std::string preset = "demo";
  uint64_t seed = 1;
  SynthCityOptions city;
  SynthTrajectoryOptions trajectory;
  SynthRenderOptions render;

  std::string Check() const;
};

struct SynthPreset {
  std::string name;
  std::string description;
};

std::vector<SynthPreset> SynthPresets();
// Throws InputError(field "--preset") listing the presets when `name` is unknown.
SynthOptions SynthPresetOptions(const std::string& name);

}  // namespace omni
