#pragma once
// The rig presets of the synthetic drives: the rig.json files of data/rigs/, compiled in (so
// the executable does not need the source tree), imitating the rigs users bring:
//   ladybug   data/rigs/ladybug-like.json  the default: five side cameras and one up, 5 cm
//   pinhole   data/rigs/pinhole.json       one forward phone-like camera, 1024x768, 65 degrees
//   car       data/rigs/car.json           six 1920x1200 pinholes around a car roof, 1-1.5 m
//   fisheye5  data/rigs/fisheye5.json      five 720x540 equidistant fisheyes: a forward stereo
//                                          pair 10 cm apart, left, right and up
// scripts/make_ladybug_like_rig.py and scripts/make_preset_rigs.py write the files;
// data/README.md says where their numbers come from.

#include <string>
#include <vector>

#include "calib/rig.h"

namespace omni::synth {

struct RigPreset {
  std::string name;
  std::string file;  // under data/rigs/
  std::string description;
};

std::vector<RigPreset> RigPresets();
// The preset's rig.json text. Throws InputError(field "--rig-preset") listing the presets
// when `name` is unknown.
const char* RigPresetJson(const std::string& name);
// The preset's rig, parsed.
Rig RigPresetRig(const std::string& name);

}  // namespace omni::synth
