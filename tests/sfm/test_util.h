#pragma once
// Helpers shared by the sfm tests.

#include <gtest/gtest.h>

#include <vector>

namespace omni::test {

// Expects at least min_share of the true inliers kept and at most 1 − min_share of the true
// outliers kept by a RANSAC inlier mask.
inline void ExpectMaskMatchesTruth(const std::vector<char>& mask,
                                   const std::vector<char>& is_outlier, double min_share) {
  ASSERT_EQ(mask.size(), is_outlier.size());
  int true_inliers = 0, kept_true_inliers = 0, outliers = 0, kept_outliers = 0;
  for (size_t i = 0; i < mask.size(); ++i) {
    if (is_outlier[i]) {
      ++outliers;
      kept_outliers += mask[i] ? 1 : 0;
    } else {
      ++true_inliers;
      kept_true_inliers += mask[i] ? 1 : 0;
    }
  }
  ASSERT_GT(outliers, 0);
  EXPECT_GE(kept_true_inliers, min_share * true_inliers);
  EXPECT_LE(kept_outliers, (1.0 - min_share) * outliers);
}

}  // namespace omni::test
