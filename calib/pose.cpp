#include "calib/pose.h"

#include <Eigen/SVD>
#include <cassert>
#include <cmath>

namespace omni {
namespace {

// The rotation nearest to `m` in the Frobenius norm: U diag(1, 1, det(U V^T)) V^T.
Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Vector3d signs(1.0, 1.0, 1.0);
  if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0) signs.z() = -1.0;
  return svd.matrixU() * signs.asDiagonal() * svd.matrixV().transpose();
}

Eigen::Matrix<double, 3, Eigen::Dynamic> ToColumns(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Matrix<double, 3, Eigen::Dynamic> columns(3, points.size());
  for (size_t i = 0; i < points.size(); ++i) columns.col(i) = points[i];
  return columns;
}

}  // namespace

Rigid3d Rigid3d::Inverse() const {
  const Eigen::Quaterniond inverse_rotation = rotation.conjugate();
  return Rigid3d(inverse_rotation, -(inverse_rotation * translation));
}

Eigen::Matrix<double, 3, 4> Rigid3d::ToMatrix() const {
  Eigen::Matrix<double, 3, 4> matrix;
  matrix.leftCols<3>() = rotation.toRotationMatrix();
  matrix.col(3) = translation;
  return matrix;
}

Rigid3d Rigid3d::FromMatrix(const Eigen::Matrix<double, 3, 4>& matrix) {
  const Eigen::Quaterniond rotation(NearestRotation(matrix.leftCols<3>()));
  return Rigid3d(rotation.normalized(), matrix.col(3));
}

Rigid3d operator*(const Rigid3d& c_from_b, const Rigid3d& b_from_a) {
  return Rigid3d((c_from_b.rotation * b_from_a.rotation).normalized(),
                 c_from_b.rotation * b_from_a.translation + c_from_b.translation);
}

Sim3d Sim3d::Inverse() const {
  const Eigen::Quaterniond inverse_rotation = rotation.conjugate();
  return Sim3d(1.0 / scale, inverse_rotation, -(inverse_rotation * translation) / scale);
}

Eigen::Matrix<double, 3, 4> Sim3d::ToMatrix() const {
  Eigen::Matrix<double, 3, 4> matrix;
  matrix.leftCols<3>() = scale * rotation.toRotationMatrix();
  matrix.col(3) = translation;
  return matrix;
}

Sim3d operator*(const Sim3d& c_from_b, const Sim3d& b_from_a) {
  return Sim3d(c_from_b.scale * b_from_a.scale,
               (c_from_b.rotation * b_from_a.rotation).normalized(),
               c_from_b.scale * (c_from_b.rotation * b_from_a.translation) + c_from_b.translation);
}

Rigid3d TransformPose(const Sim3d& new_from_old, const Rigid3d& old_from_rig) {
  return Rigid3d((new_from_old.rotation * old_from_rig.rotation).normalized(),
                 new_from_old * old_from_rig.translation);
}

Sim3d EstimateSim3Umeyama(const std::vector<Eigen::Vector3d>& src,
                          const std::vector<Eigen::Vector3d>& dst, bool estimate_scale) {
  assert(src.size() == dst.size());
  assert(!src.empty());
  const Eigen::Matrix4d dst_from_src =
      Eigen::umeyama(ToColumns(src), ToColumns(dst), estimate_scale);
  const Eigen::Matrix3d scaled_rotation = dst_from_src.topLeftCorner<3, 3>();
  // umeyama returns c R with det R = +1, so det(c R) = c³.
  const double scale = estimate_scale ? std::cbrt(scaled_rotation.determinant()) : 1.0;
  const Eigen::Quaterniond rotation(NearestRotation(scaled_rotation / scale));
  return Sim3d(scale, rotation.normalized(), dst_from_src.topRightCorner<3, 1>());
}

double AlignmentRms(const Sim3d& dst_from_src, const std::vector<Eigen::Vector3d>& src,
                    const std::vector<Eigen::Vector3d>& dst) {
  assert(src.size() == dst.size());
  if (src.empty()) return 0.0;
  double sum = 0.0;
  for (size_t i = 0; i < src.size(); ++i) sum += (dst_from_src * src[i] - dst[i]).squaredNorm();
  return std::sqrt(sum / src.size());
}

}  // namespace omni
