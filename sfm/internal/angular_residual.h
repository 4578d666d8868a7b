#pragma once
// INTERNAL to sfm/*.cpp (and its tests): the bundle adjustment's angular residual of one
// observation with its Jacobians in closed form.

#include <Eigen/Core>

namespace omni::internal {

// One observation as the adjustment sees it: the bearing b (unit) in its frame (the observing
// camera in non-central mode, the rig's central camera in central mode), and that frame's pose in
// the rig frame, frame_from_rig = (A, c), c scaled by the offsets' scale s.
//
//   x_rig   = conj(q) (X − t)        the point X in the rig frame; world_from_rig = (q, t), q an
//                                    Eigen quaternion (x y z w), rotated as Eigen rotates
//   x_frame = A x_rig + s c
//   p       = x_frame / ‖x_frame‖
//   r       = 2 [u·p, v·p] / (1 + b·p)   (u, v) an orthonormal basis of b's tangent plane
//
// r is the stereographic projection of p from −b onto b's tangent plane: ‖r‖ = 2 tan(θ/2) for
// the angle θ between p and b, so r ≈ the two components of the angular error (radians) for
// small errors, grows without bound as p turns away from b (a point behind is never cheap), and
// is smooth everywhere except at p = −b.
class AngularResidualModel {
 public:
  AngularResidualModel() = default;  // a placeholder, to be assigned
  AngularResidualModel(const Eigen::Matrix3d& frame_from_rig_rotation,
                       const Eigen::Vector3d& frame_from_rig_translation,
                       const Eigen::Vector3d& bearing);

  // r, and the Jacobians asked for (null: not wanted), row-major as Ceres wants them: d r /
  // d q (2×4, q's ambient coordinates x y z w: the derivative of the formula above, not of a
  // normalised q), d r / d t (2×3), d r / d X (2×3), d r / d s (2×1).
  void Evaluate(const double* world_from_rig_q, const double* world_from_rig_t, const double* point,
                double offset_scale, double* residual, double* jacobian_q, double* jacobian_t,
                double* jacobian_point, double* jacobian_scale) const;

 private:
  Eigen::Matrix3d frame_from_rig_rotation_ = Eigen::Matrix3d::Identity();
  Eigen::Vector3d frame_from_rig_translation_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d bearing_ = Eigen::Vector3d::UnitZ(), tangent_u_ = Eigen::Vector3d::UnitX(),
                  tangent_v_ = Eigen::Vector3d::UnitY();
};

}  // namespace omni::internal
