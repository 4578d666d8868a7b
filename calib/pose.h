#pragma once
// Rigid and similarity transforms named by their frames: b_from_a maps coordinates in frame a
// to frame b, and c_from_a = c_from_b * b_from_a (docs/design.md §3).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

namespace omni {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& r, const Eigen::Vector3d& t) : rotation(r), translation(t) {}

  Eigen::Vector3d operator*(const Eigen::Vector3d& point_in_a) const {
    return rotation * point_in_a + translation;
  }
  Rigid3d Inverse() const;
  Eigen::Matrix<double, 3, 4> ToMatrix() const;
  // From a 3x4 or 4x4 matrix [R t]; R is projected to the nearest rotation.
  static Rigid3d FromMatrix(const Eigen::Matrix<double, 3, 4>& matrix);
  // For b_from_a: the origin of frame b expressed in frame a, -R^T t (for cam_from_rig, the
  // camera centre in the rig frame).
  Eigen::Vector3d Center() const { return -(rotation.conjugate() * translation); }
};

// c_from_a = c_from_b * b_from_a.
Rigid3d operator*(const Rigid3d& c_from_b, const Rigid3d& b_from_a);

struct Sim3d {
  double scale = 1.0;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Sim3d() = default;
  Sim3d(double s, const Eigen::Quaterniond& r, const Eigen::Vector3d& t)
      : scale(s), rotation(r), translation(t) {}

  Eigen::Vector3d operator*(const Eigen::Vector3d& point_in_a) const {
    return scale * (rotation * point_in_a) + translation;
  }
  Sim3d Inverse() const;
  Eigen::Matrix<double, 3, 4> ToMatrix() const;
};

Sim3d operator*(const Sim3d& c_from_b, const Sim3d& b_from_a);

// Applies a change of world frame to a pose: given new_from_old and old_from_rig, returns
// new_from_rig. The rig frame itself is not scaled (its cameras stay where rig.json puts them,
// in metres): rotation R_s R, translation s R_s t + t_s.
Rigid3d TransformPose(const Sim3d& new_from_old, const Rigid3d& old_from_rig);

// Least-squares transform dst ≈ S * src (Umeyama 1991, via Eigen::umeyama). With
// estimate_scale false the result is rigid (scale 1). Needs at least 3 non-collinear pairs
// (2 suffice without rotation ambiguity only in degenerate cases); asserts equal sizes.
Sim3d EstimateSim3Umeyama(const std::vector<Eigen::Vector3d>& src,
                          const std::vector<Eigen::Vector3d>& dst, bool estimate_scale = true);

// Root mean square of ‖S * src_i − dst_i‖.
double AlignmentRms(const Sim3d& dst_from_src, const std::vector<Eigen::Vector3d>& src,
                    const std::vector<Eigen::Vector3d>& dst);

}  // namespace omni
