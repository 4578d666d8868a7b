#include "pipeline/world_up.h"

#include <Eigen/Eigenvalues>
#include <cmath>

namespace omni {

Eigen::Vector3d EstimateWorldUp(const std::vector<Eigen::Vector3d>& camera_centres,
                                const std::vector<Eigen::Vector3d>& image_up) {
  Eigen::Vector3d mean_up = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& u : image_up) mean_up += u;
  if (camera_centres.size() < 2) {
    return mean_up.norm() > 0.0 ? Eigen::Vector3d(mean_up.normalized()) : Eigen::Vector3d::UnitZ();
  }
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& c : camera_centres) centroid += c;
  centroid /= static_cast<double>(camera_centres.size());
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& c : camera_centres) {
    covariance += (c - centroid) * (c - centroid).transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> solver(covariance);
  // Eigenvalues in increasing order: the normal of the best plane first, the drive direction
  // last.
  const Eigen::Vector3d spread = solver.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  const Eigen::Vector3d normal = solver.eigenvectors().col(0);
  const Eigen::Vector3d along = solver.eigenvectors().col(2);
  // A plane: the second spread at least a tenth of the first, the third below a third of the
  // second (a drive over hills stays well below that).
  const bool plane = spread(1) >= 0.1 * spread(2) && spread(0) <= spread(1) / 3.0;
  if (plane) {
    return normal.dot(mean_up) < 0.0 ? Eigen::Vector3d(-normal) : normal;
  }
  const Eigen::Vector3d across = mean_up - mean_up.dot(along) * along;
  if (across.norm() > 1e-6 * std::max(1.0, mean_up.norm())) return across.normalized();
  return Eigen::Vector3d::UnitZ();
}

}  // namespace omni
