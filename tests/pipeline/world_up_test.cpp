// EstimateWorldUp: the up direction of a world frame from its cameras alone.

#include "pipeline/world_up.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <vector>

namespace omni {
namespace {

// Images of a rig driving with `world_from_drive` applied: four horizontal cameras (image up
// along the drive's z) and one looking up (image up along the drive direction of its frame).
struct Images {
  std::vector<Eigen::Vector3d> centres, ups;
};
Images Drive(const std::vector<Eigen::Vector2d>& path, const Eigen::Matrix3d& world_from_drive) {
  Images images;
  for (size_t i = 0; i < path.size(); ++i) {
    const Eigen::Vector2d next = path[std::min(i + 1, path.size() - 1)];
    const Eigen::Vector2d previous = path[i > 0 ? i - 1 : 0];
    const Eigen::Vector2d heading = (next - previous).normalized();
    const Eigen::Vector3d centre(path[i].x(), path[i].y(), 2.0);
    for (int c = 0; c < 5; ++c) {
      images.centres.push_back(world_from_drive * centre);
      const Eigen::Vector3d up =
          c < 4 ? Eigen::Vector3d::UnitZ() : Eigen::Vector3d(heading.x(), heading.y(), 0.0);
      images.ups.push_back(world_from_drive * up);
    }
  }
  return images;
}

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 / M_PI;
}

const Eigen::Matrix3d kTurned =
    Eigen::AngleAxisd(2.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();

TEST(WorldUp, TheNormalOfThePlaneOfATurningDriveTurnedToTheImagesUp) {
  std::vector<Eigen::Vector2d> loop;
  for (int i = 0; i < 40; ++i) {
    const double a = 2.0 * M_PI * i / 40.0;
    loop.emplace_back(30.0 * std::cos(a), 12.0 * std::sin(a));
  }
  const Images images = Drive(loop, kTurned);
  const Eigen::Vector3d up = EstimateWorldUp(images.centres, images.ups);
  EXPECT_LT(AngleDeg(up, kTurned * Eigen::Vector3d::UnitZ()), 1e-6);
  // The images' mean up alone is off by the upward camera (here nearly cancelled over the loop);
  // the sign follows the images.
  std::vector<Eigen::Vector3d> down = images.ups;
  for (Eigen::Vector3d& u : down) u = -u;
  EXPECT_LT(AngleDeg(EstimateWorldUp(images.centres, down), -(kTurned * Eigen::Vector3d::UnitZ())),
            1e-6);
}

TEST(WorldUp, AStraightDriveTakesTheImagesUpAcrossTheDriveDirection) {
  std::vector<Eigen::Vector2d> line;
  for (int i = 0; i < 30; ++i) line.emplace_back(0.4 * i, 0.0);
  const Images images = Drive(line, kTurned);
  const Eigen::Vector3d truth = kTurned * Eigen::Vector3d::UnitZ();
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& u : images.ups) mean += u;
  EXPECT_GT(AngleDeg(mean, truth), 5.0);  // the upward camera tilts the mean up axis forwards
  EXPECT_LT(AngleDeg(EstimateWorldUp(images.centres, images.ups), truth), 1e-6);
}

TEST(WorldUp, WithoutImagesOrMotionTheDefaultsHold) {
  EXPECT_EQ(EstimateWorldUp({}, {}), Eigen::Vector3d::UnitZ());
  EXPECT_LT(AngleDeg(EstimateWorldUp({Eigen::Vector3d::Zero()}, {Eigen::Vector3d(0, 2, 0)}),
                     Eigen::Vector3d::UnitY()),
            1e-9);
}

}  // namespace
}  // namespace omni
