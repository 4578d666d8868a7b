#pragma once
// Internal to sfm/: the rig's cameras as OpenGV wants them, rig_from_cam (offset = camera
// centre in the rig frame, rotation = camera axes in the rig frame).

#include <opengv/types.hpp>

#include "calib/rig.h"

namespace omni::internal {

inline void ToOpengvRig(const Rig& rig, opengv::translations_t* cam_offsets,
                        opengv::rotations_t* cam_rotations) {
  cam_offsets->clear();
  cam_rotations->clear();
  for (const Camera& camera : rig.cameras) {
    cam_offsets->push_back(camera.cam_from_rig.Center());
    cam_rotations->push_back(camera.cam_from_rig.rotation.conjugate().toRotationMatrix());
  }
}

}  // namespace omni::internal
