#include "apps/default_rig.h"

#include "synth/rig_presets.h"

namespace omni {

const char* DefaultRigJson() { return synth::RigPresetJson("ladybug"); }

Rig DefaultRig() { return synth::RigPresetRig("ladybug"); }

}  // namespace omni
