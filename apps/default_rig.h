#pragma once
// The built-in default rig: data/rigs/ladybug-like.json, compiled in (the rig preset
// "ladybug" of synth/rig_presets.h).

#include "calib/rig.h"

namespace omni {

const char* DefaultRigJson();
Rig DefaultRig();

}  // namespace omni
