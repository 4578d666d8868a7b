// --from-gt's pose noise (pipeline/gt_keyframes.h): none gives the exact keyframe centres
// and ray origins; σ gives an RMS centre deviation near σ√3, the rays of a keyframe moved with
// its centre, and the same points as without noise.
#include <gtest/gtest.h>

#include <cmath>

#include "pipeline/gt_keyframes.h"

namespace omni {
namespace {

TriangleMesh Street() {
  TriangleMesh m;
  auto quad = [&](Eigen::Vector3d a, Eigen::Vector3d b, Eigen::Vector3d c, Eigen::Vector3d d) {
    const int k = static_cast<int>(m.vertices.size());
    m.vertices.insert(m.vertices.end(), {a, b, c, d});
    m.triangles.emplace_back(k, k + 1, k + 2);
    m.triangles.emplace_back(k, k + 2, k + 3);
  };
  quad({-20, -8, 0}, {120, -8, 0}, {120, 8, 0}, {-20, 8, 0});
  quad({-20, -8, 0}, {-20, -8, 12}, {120, -8, 12}, {120, -8, 0});
  quad({-20, 8, 0}, {120, 8, 0}, {120, 8, 12}, {-20, 8, 12});
  return m;
}

TEST(GtKeyframes, PoseNoiseMovesCentresAndRaysByAboutSigma) {
  std::vector<Eigen::Vector3d> centres;
  for (int t = 0; t < 60; ++t) centres.emplace_back(1.9 * t, 0.3, 4.0);
  GtKeyframeOptions options;
  options.points_per_keyframe = 40;
  const auto exact = MakeGtKeyframes(Street(), centres, options);
  options.pose_noise = 0.2;
  const auto noisy = MakeGtKeyframes(Street(), centres, options);
  ASSERT_EQ(exact.size(), centres.size());
  ASSERT_EQ(noisy.size(), centres.size());
  double sum2 = 0;
  for (size_t t = 0; t < exact.size(); ++t) {
    EXPECT_EQ(exact[t].centre, centres[t]);  // no noise: the exact centres
    sum2 += (noisy[t].centre - centres[t]).squaredNorm();
    ASSERT_EQ(exact[t].points.size(), noisy[t].points.size());
    for (size_t i = 0; i < exact[t].points.size(); ++i) {
      const SurfacePoint &p = exact[t].points[i], &q = noisy[t].points[i];
      EXPECT_EQ(p.position, q.position);
      ASSERT_EQ(p.rays.size(), q.rays.size());
      for (size_t k = 0; k < p.rays.size(); ++k) {
        const size_t kf = p.rays[k].keyframe.value;
        EXPECT_EQ(p.rays[k].origin, centres[kf]);
        EXPECT_NEAR((q.rays[k].origin - noisy[kf].centre).norm(), 0.0, 1e-12);
      }
    }
  }
  const double rms = std::sqrt(sum2 / exact.size());
  EXPECT_NEAR(rms, 0.2 * std::sqrt(3.0), 0.2 * std::sqrt(3.0) * 0.25);
  GtKeyframeOptions bad;
  bad.pose_noise = -1;
  EXPECT_NE(bad.Check(), "");
}

}  // namespace
}  // namespace omni
