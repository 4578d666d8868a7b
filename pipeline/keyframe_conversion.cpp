#include "pipeline/keyframe_conversion.h"

namespace omni {

SurfaceKeyframe ToSurfaceKeyframe(const FinalizedKeyframe& keyframe) {
  SurfaceKeyframe result;
  result.id = KeyframeId(static_cast<uint32_t>(keyframe.keyframe));
  result.centre = keyframe.center;
  result.points.reserve(keyframe.points.size());
  for (const FinalizedPoint& point : keyframe.points) {
    SurfacePoint surface_point;
    surface_point.id = PointId(static_cast<uint32_t>(point.point));
    surface_point.position = point.position;
    surface_point.rays.reserve(point.rays.size() + point.frame_rays.size());
    for (const FinalizedRay& ray : point.rays)
      surface_point.rays.push_back({KeyframeId(static_cast<uint32_t>(ray.keyframe)), ray.center});
    for (const FinalizedFrameRay& ray : point.frame_rays)
      surface_point.rays.push_back({KeyframeId(static_cast<uint32_t>(ray.keyframe)), ray.center});
    result.points.push_back(std::move(surface_point));
  }
  return result;
}

std::vector<SurfaceKeyframe> ToSurfaceKeyframes(const std::vector<FinalizedKeyframe>& keyframes) {
  std::vector<SurfaceKeyframe> result;
  result.reserve(keyframes.size());
  for (const FinalizedKeyframe& keyframe : keyframes) result.push_back(ToSurfaceKeyframe(keyframe));
  return result;
}

}  // namespace omni
