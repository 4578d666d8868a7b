// The COLMAP text reader of `surface --colmap` refuses malformed models naming the file and line.

#include "pipeline/colmap_keyframes.h"

#include <gtest/gtest.h>

#include <string>

#include "calib/error.h"

namespace omni {
namespace {

ColmapTextModel ValidModel() {
  ColmapTextModel model;
  model.cameras = "# CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]\n1 PINHOLE 640 480 500 500 320 240\n";
  model.images =
      "# two lines per image\n"
      "1 1 0 0 0 0 0 0 1 cam0/000001.png\n"
      "10 20 -1 30 40 1\n"
      "2 1 0 0 0 -1 0 0 1 cam0/000002.png\n"
      "\n";
  model.points3d = "# points\n1 0 0 5 10 20 30 0.5 1 0 2 0\n2 1 1 5 0 0 0 0.5\n";
  return model;
}

std::string ParseError(const ColmapTextModel& model) {
  try {
    ParseColmapKeyframes(model, "model");
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no InputError for\n" << model.cameras << model.images << model.points3d;
  return "";
}

TEST(ColmapKeyframes, ValidModelReads) {
  std::unordered_map<PointId, Rgb8> colors;
  const std::vector<SurfaceKeyframe> keyframes = ParseColmapKeyframes(ValidModel(), "m", &colors);
  ASSERT_EQ(keyframes.size(), 2u);
  EXPECT_EQ(keyframes[0].centre, Eigen::Vector3d::Zero());
  EXPECT_EQ(keyframes[1].centre, Eigen::Vector3d(1, 0, 0));
  ASSERT_EQ(keyframes[1].points.size(), 1u);  // the observed point, in its latest keyframe
  EXPECT_EQ(keyframes[1].points[0].rays.size(), 2u);
  EXPECT_EQ(colors.at(PointId(1)), Rgb8(10, 20, 30));
  // The last image's (empty) line of 2D points may be missing at the end of the file.
  ColmapTextModel model = ValidModel();
  model.images.pop_back();
  EXPECT_EQ(ParseColmapKeyframes(model, "m").size(), 2u);
}

TEST(ColmapKeyframes, MalformedLinesNameTheFileAndLine) {
  struct Case {
    std::string ColmapTextModel::*file;
    std::string from, to, expected;
  };
  const Case cases[] = {
      {&ColmapTextModel::images, "1 1 0 0 0 0 0 0 1 cam0", "1 0x1 0 0 0 0 0 0 1 cam0",
       "model/images.txt: line 2: QW: expected a decimal number, got \"0x1\""},
      {&ColmapTextModel::images, "1 1 0 0 0 0 0 0 1 cam0", "1 1 0 0 0 1e309 0 0 1 cam0",
       "model/images.txt: line 2: TX: number out of range (too large for a double): \"1e309\""},
      {&ColmapTextModel::images, "1 1 0 0 0 0 0 0 1 cam0", "1 2 0 0 0 0 0 0 1 cam0",
       "model/images.txt: line 2: QW QX QY QZ: expected a unit quaternion, norm is 2"},
      {&ColmapTextModel::images, "1 1 0 0 0 0 0 0 1 cam0", "1 1 0 0 0 0 0 0 7 cam0",
       "model/images.txt: line 2: CAMERA_ID 7 is not in cameras.txt"},
      {&ColmapTextModel::images, "2 1 0 0 0 -1", "1 1 0 0 0 -1",
       "model/images.txt: line 4: repeated IMAGE_ID 1"},
      {&ColmapTextModel::images, "1 1 0 0 0 0 0 0 1 cam0", "-1 1 0 0 0 0 0 0 1 cam0",
       "model/images.txt: line 2: IMAGE_ID: expected an integer in [0, 4294967295], got \"-1\""},
      {&ColmapTextModel::images, "10 20 -1 30 40 1", "10 20 -1 30 40",
       "model/images.txt: line 3: expected 2D points as X Y POINT3D_ID triples, got 5 values"},
      {&ColmapTextModel::images, "cam0/000001.png", "cam0/000001.png extra",
       "model/images.txt: line 2: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got 11 "
       "fields"},
      {&ColmapTextModel::points3d, "1 0 0 5 10 20 30", "1 0 0 nan 10 20 30",
       "model/points3D.txt: line 2: Z: expected a decimal number, got \"nan\""},
      {&ColmapTextModel::points3d, "1 0 0 5 10 20 30", "1 0 0 5 10 256 30",
       "model/points3D.txt: line 2: G: expected an integer in [0, 255], got \"256\""},
      {&ColmapTextModel::points3d, "0.5 1 0 2 0", "0.5 1 0 2",
       "model/points3D.txt: line 2: expected POINT3D_ID X Y Z R G B ERROR TRACK[] (IMAGE_ID "
       "POINT2D_IDX pairs), got 11 fields"},
      {&ColmapTextModel::points3d, "0.5 1 0 2 0", "0.5 1 0 3 0",
       "model/points3D.txt: line 2: unknown IMAGE_ID 3"},
      {&ColmapTextModel::points3d, "2 1 1 5", "1 1 1 5",
       "model/points3D.txt: line 3: repeated POINT3D_ID 1"},
      {&ColmapTextModel::points3d, "2 1 1 5", "99999999999 1 1 5",
       "model/points3D.txt: line 3: POINT3D_ID: expected an integer in [0, 4294967295], got "
       "\"99999999999\""},
      {&ColmapTextModel::cameras, "640 480", "640 0",
       "model/cameras.txt: line 2: HEIGHT: expected an integer in [1, 65536], got \"0\""},
  };
  for (const Case& c : cases) {
    ColmapTextModel model = ValidModel();
    std::string& text = model.*c.file;
    ASSERT_NE(text.find(c.from), std::string::npos) << c.from;
    text.replace(text.find(c.from), c.from.size(), c.to);
    EXPECT_EQ(ParseError(model), c.expected) << c.to;
  }
}

}  // namespace
}  // namespace omni
