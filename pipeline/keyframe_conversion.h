#pragma once
// The sfm→surface contract of docs/design.md §7 in code: a keyframe finalised by the tracker (its
// pose and points no longer move) as the keyframe the incremental sculptor takes. The one
// conversion between the two modules; sfm/ and surface/ never include each other.

#include <vector>

#include "sfm/tracker.h"
#include "surface/sculptor.h"

namespace omni {

// Keyframe id, centre c_t, and for each point created with the keyframe its position and its
// rays (observing keyframe, optical centre), then the rays of the tracked frames between
// keyframes (FinalizedPoint::frame_rays, each under the id of the keyframe before its frame). Ids
// are the tracker's keyframe and point indices.
SurfaceKeyframe ToSurfaceKeyframe(const FinalizedKeyframe& keyframe);
std::vector<SurfaceKeyframe> ToSurfaceKeyframes(const std::vector<FinalizedKeyframe>& keyframes);

}  // namespace omni
