#pragma once
// The vertical direction of a world frame whose axes mean nothing (a COLMAP model: any rotation,
// scale and origin), for the ground filter of the sculptor (SculptorOptions::up), from the
// cameras alone.

#include <Eigen/Core>
#include <vector>

namespace omni {

// camera_centres: the optical centres of the images; image_up: for each image, its up axis in
// the world (−y of the camera, the image rows running downwards), unit vectors.
//
// A vehicle's cameras move over the ground: when their centres spread in two directions and
// hardly in the third, the normal of the plane they lie in is the up direction, turned to the
// side the images' up axes point to on average. Along a straight drive (no plane), the images'
// mean up axis made orthogonal to the drive direction (the tilt of an upward-looking camera,
// whose up axis points along the drive, drops out). Returns a unit vector; +z when neither
// exists (no image, or up axes that cancel on a straight drive).
Eigen::Vector3d EstimateWorldUp(const std::vector<Eigen::Vector3d>& camera_centres,
                                const std::vector<Eigen::Vector3d>& image_up);

}  // namespace omni
