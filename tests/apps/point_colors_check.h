#pragma once
// End-to-end check of the point colours of `omnisculpt sfm` / `reconstruct`: the
// colour of each point of sparse/points3D.txt is, within rounding, the mean over its track of
// the drive image's pixel (bilinear) at the 2-D point of sparse/images.txt, and points.ply
// carries the same colours in the same order.

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "calib/ply.h"

namespace omni::testing {

inline void ExpectPointColoursAreImageMeans(const std::filesystem::path& drive,
                                            const std::filesystem::path& rec,
                                            size_t max_points_checked) {
  // images.txt: "ID QW QX QY QZ TX TY TZ CAMERA NAME" then "X Y POINT3D ..." per image.
  struct Image {
    std::string name;
    std::vector<Eigen::Vector2d> points2d;
  };
  std::map<long, Image> images;
  {
    std::ifstream in(rec / "sparse" / "images.txt");
    std::string line;
    std::vector<std::string> data;
    while (std::getline(in, line))
      if (line.empty() || line[0] != '#') data.push_back(line);
    ASSERT_EQ(data.size() % 2, 0u);
    for (size_t i = 0; i < data.size(); i += 2) {
      std::istringstream header(data[i]);
      long id, camera;
      double pose[7];
      Image image;
      ASSERT_TRUE(header >> id >> pose[0] >> pose[1] >> pose[2] >> pose[3] >> pose[4] >> pose[5] >>
                  pose[6] >> camera >> image.name);
      std::istringstream points(data[i + 1]);
      double x, y;
      long point3d;
      while (points >> x >> y >> point3d) image.points2d.emplace_back(x, y);
      images[id] = image;
    }
  }
  std::map<std::string, cv::Mat> loaded;
  auto pixel = [&](const std::string& name, const Eigen::Vector2d& colmap_xy) {
    cv::Mat& image = loaded[name];
    if (image.empty()) image = cv::imread((drive / name).string(), cv::IMREAD_COLOR);
    EXPECT_FALSE(image.empty()) << name;
    // COLMAP puts pixel centres at +0.5; bilinear over the four neighbours (BGR in OpenCV).
    const double x = std::clamp(colmap_xy.x() - 0.5, 0.0, image.cols - 1.0);
    const double y = std::clamp(colmap_xy.y() - 0.5, 0.0, image.rows - 1.0);
    const int x0 = std::min(static_cast<int>(x), image.cols - 2);
    const int y0 = std::min(static_cast<int>(y), image.rows - 2);
    const double ax = x - x0, ay = y - y0;
    Eigen::Vector3d rgb;
    for (int k = 0; k < 3; ++k) {
      auto at = [&](int r, int c) { return double(image.at<cv::Vec3b>(r, c)[2 - k]); };
      rgb[k] = (1 - ay) * ((1 - ax) * at(y0, x0) + ax * at(y0, x0 + 1)) +
               ay * ((1 - ax) * at(y0 + 1, x0) + ax * at(y0 + 1, x0 + 1));
    }
    return rgb;
  };

  std::ifstream points(rec / "sparse" / "points3D.txt");
  std::string line;
  struct Point {
    Eigen::Vector3d position;
    Eigen::Vector3i rgb;
  };
  std::vector<Point> colmap_points;
  size_t checked = 0, not_grey128 = 0;
  while (std::getline(points, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::istringstream in(line);
    long id;
    Point point;
    double error;
    ASSERT_TRUE(in >> id >> point.position.x() >> point.position.y() >> point.position.z() >>
                point.rgb[0] >> point.rgb[1] >> point.rgb[2] >> error)
        << line;
    colmap_points.push_back(point);
    not_grey128 += point.rgb != Eigen::Vector3i(128, 128, 128);
    if (checked >= max_points_checked) continue;
    long image_id, index;
    Eigen::Vector3d sum = Eigen::Vector3d::Zero();
    int count = 0;
    while (in >> image_id >> index) {
      ASSERT_EQ(images.count(image_id), 1u) << line;
      const Image& image = images[image_id];
      ASSERT_LT(static_cast<size_t>(index), image.points2d.size()) << line;
      sum += pixel(image.name, image.points2d[index]);
      ++count;
    }
    ASSERT_GT(count, 0) << line;
    const Eigen::Vector3d mean = sum / count;
    for (int k = 0; k < 3; ++k)
      EXPECT_LE(std::abs(point.rgb[k] - mean[k]), 0.5 + 1e-3) << "point " << id << ": " << line;
    ++checked;
  }
  ASSERT_GT(checked, 0u);
  EXPECT_GT(not_grey128, colmap_points.size() / 2) << "the points are not coloured";

  // points.ply: the same colours, in the same order (the COLMAP model leaves out the points
  // with no observation that projects: match by position).
  const PointCloud cloud = ReadPlyPoints(rec / "points.ply");
  ASSERT_EQ(cloud.colors.size(), cloud.points.size());
  size_t j = 0;
  for (const Point& point : colmap_points) {
    while (j < cloud.points.size() &&
           (cloud.points[j] - point.position).norm() > 1e-4 * (1.0 + point.position.norm()))
      ++j;
    ASSERT_LT(j, cloud.points.size()) << "a COLMAP point missing in points.ply";
    EXPECT_EQ(cloud.colors[j].cast<int>(), point.rgb);
    ++j;
  }
}

}  // namespace omni::testing
