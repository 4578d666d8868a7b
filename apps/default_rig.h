#pragma once
// The built-in default rig: data/rigs/ladybug-like.json, compiled in.

#include "calib/rig.h"

namespace omni {

const char* DefaultRigJson();
Rig DefaultRig();

}  // namespace omni
