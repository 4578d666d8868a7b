// The COLMAP text reader of `surface --colmap` refuses malformed models naming the file and line;
// frame_rays.txt adds its rays and frame points to the keyframes; the rig poses of a model's
// keyframes come back from a model made of known poses.

#include "pipeline/colmap_keyframes.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>
#include <set>
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
  // Point 1 seen from frame 3 too; a frame point seen from frames 3 and 4, after the last
  // keyframe.
  model.frame_rays =
      "# frame rays\n"
      "1 0 0 5 10 20 30 1 cam0/000003.png 3 0 0\n"
      "0 2 2 5 0 0 0 2 cam0/000003.png 0.25 0 0 cam0/000004.png 0.5 0 0\n";
  return model;
}

std::string ParseError(const ColmapTextModel& model) {
  try {
    ParseColmapKeyframes(model, "model");
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no InputError for\n"
                << model.cameras << model.images << model.points3d << model.frame_rays;
  return "";
}

TEST(ColmapKeyframes, ValidModelReads) {
  std::unordered_map<PointId, Rgb8> colors;
  const std::vector<SurfaceKeyframe> keyframes = ParseColmapKeyframes(ValidModel(), "m", &colors);
  ASSERT_EQ(keyframes.size(), 2u);
  EXPECT_EQ(keyframes[0].centre, Eigen::Vector3d::Zero());
  EXPECT_EQ(keyframes[1].centre, Eigen::Vector3d(1, 0, 0));
  // The observed point in its latest keyframe, with its frame ray; the frame point after it.
  ASSERT_EQ(keyframes[1].points.size(), 2u);
  EXPECT_EQ(keyframes[1].points[0].rays.size(), 3u);
  EXPECT_EQ(keyframes[1].points[0].rays[2].origin, Eigen::Vector3d(3, 0, 0));
  EXPECT_EQ(colors.at(PointId(1)), Rgb8(10, 20, 30));
  EXPECT_EQ(keyframes[1].points[1].id, PointId(3));  // after the model's ids
  EXPECT_EQ(keyframes[1].points[1].position, Eigen::Vector3d(2, 2, 5));
  ASSERT_EQ(keyframes[1].points[1].rays.size(), 2u);
  EXPECT_EQ(keyframes[1].points[1].rays[1].origin, Eigen::Vector3d(0.5, 0, 0));
  // Without the frame rays: the keyframes' rays only.
  ColmapTextModel without = ValidModel();
  without.frame_rays.clear();
  const std::vector<SurfaceKeyframe> plain = ParseColmapKeyframes(without, "m");
  ASSERT_EQ(plain[1].points.size(), 1u);
  EXPECT_EQ(plain[1].points[0].rays.size(), 2u);
  // The last image's (empty) line of 2D points may be missing at the end of the file.
  ColmapTextModel model = ValidModel();
  model.images.pop_back();
  EXPECT_EQ(ParseColmapKeyframes(model, "m").size(), 2u);
}

// The pixel of the finest camera: the first parameter is the focal length in every COLMAP model.
TEST(ColmapKeyframes, TheFinestPixelAngleIsThatOfTheLongestFocalLength) {
  ColmapTextModel text = ValidModel();
  EXPECT_DOUBLE_EQ(ColmapFinestPixelAngle(ParseColmapModel(text, "m")), 1.0 / 500.0);
  text.cameras += "2 SIMPLE_RADIAL 1024 768 800 512 384 0.01\n";
  EXPECT_DOUBLE_EQ(ColmapFinestPixelAngle(ParseColmapModel(text, "m")), 1.0 / 800.0);
  EXPECT_EQ(ColmapFinestPixelAngle(ColmapModel()), 0.0);
}

// A frame point goes to the latest keyframe at or before the last frame that saw it, the first
// keyframe when it was seen before any; the files' text comes back from the model.
TEST(ColmapKeyframes, AFramePointGoesToTheKeyframeBeforeItsLastFrame) {
  ColmapTextModel text = ValidModel();
  text.frame_rays +=
      "0 7 7 7 1 2 3 1 cam0/000001.png 0 0 0\n"        // at keyframe 0 (frame 1)
      "0 8 8 8 1 2 3 1 cam0/000000.png 0 0 0\n"        // before it: keyframe 0 too
      "0 9 9 9 1 2 3 1 other/cam0/000002.png 0 0 0\n"  // "other/000002.png" sorts after both
      "0 6 6 6 1 2 3 2 cam0/000001.png 0 0 0 cam0/000002.png 0 1 0\n";
  std::unordered_map<PointId, Rgb8> colors;
  const std::vector<SurfaceKeyframe> keyframes = ParseColmapKeyframes(text, "m", &colors);
  ASSERT_EQ(keyframes.size(), 2u);
  ASSERT_EQ(keyframes[0].points.size(), 2u);
  EXPECT_EQ(keyframes[0].points[0].position, Eigen::Vector3d(7, 7, 7));
  EXPECT_EQ(keyframes[0].points[1].position, Eigen::Vector3d(8, 8, 8));
  ASSERT_EQ(keyframes[1].points.size(), 4u);
  EXPECT_EQ(keyframes[1].points[2].position, Eigen::Vector3d(9, 9, 9));
  EXPECT_EQ(keyframes[1].points[3].position, Eigen::Vector3d(6, 6, 6));
  EXPECT_EQ(colors.at(keyframes[1].points[3].id), Rgb8(1, 2, 3));
  // Ids distinct from every point's.
  std::set<uint32_t> ids;
  for (const SurfaceKeyframe& keyframe : keyframes)
    for (const SurfacePoint& point : keyframe.points)
      EXPECT_TRUE(ids.insert(point.id.value).second);

  const ColmapModel model = ParseColmapModel(text, "m");
  ASSERT_EQ(model.frame_rays.size(), 6u);
  const ColmapModel again = ParseColmapModel(FormatColmapModel(model), "m");
  ASSERT_EQ(again.frame_rays.size(), model.frame_rays.size());
  for (size_t i = 0; i < model.frame_rays.size(); ++i) {
    EXPECT_EQ(again.frame_rays[i].point3d_id, model.frame_rays[i].point3d_id);
    EXPECT_EQ(again.frame_rays[i].xyz, model.frame_rays[i].xyz);
    EXPECT_EQ(again.frame_rays[i].color, model.frame_rays[i].color);
    ASSERT_EQ(again.frame_rays[i].rays.size(), model.frame_rays[i].rays.size());
    for (size_t r = 0; r < model.frame_rays[i].rays.size(); ++r) {
      EXPECT_EQ(again.frame_rays[i].rays[r].image_name, model.frame_rays[i].rays[r].image_name);
      EXPECT_EQ(again.frame_rays[i].rays[r].centre, model.frame_rays[i].rays[r].centre);
    }
  }
  // A model without frame rays writes no frame_rays.txt.
  ColmapModel plain = model;
  plain.frame_rays.clear();
  EXPECT_TRUE(FormatColmapModel(plain).frame_rays.empty());
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
      {&ColmapTextModel::frame_rays, "1 0 0 5 10 20 30 1", "3 0 0 5 10 20 30 1",
       "model/frame_rays.txt: line 2: POINT3D_ID 3 is not in points3D.txt"},
      {&ColmapTextModel::frame_rays, "0 2 2 5 0 0 0 2", "0 2 2 5 0 0 0 3",
       "model/frame_rays.txt: line 3: NUM_RAYS is 3 but the line holds 2 rays"},
      {&ColmapTextModel::frame_rays, "0 2 2 5 0 0 0 2", "0 2 2 5 0 0 0 0",
       "model/frame_rays.txt: line 3: NUM_RAYS: expected an integer in [1, 4294967295], got "
       "\"0\""},
      {&ColmapTextModel::frame_rays, "cam0/000004.png 0.5 0 0", "cam0/000004.png 0.5 0",
       "model/frame_rays.txt: line 3: expected POINT3D_ID X Y Z R G B NUM_RAYS RAYS[] (IMAGE_NAME "
       "CX CY CZ), got 15 fields"},
      {&ColmapTextModel::frame_rays, "cam0/000004.png 0.5 0 0", "cam0/000004.png 0.5 0 inf",
       "model/frame_rays.txt: line 3: CZ: expected a decimal number, got \"inf\""},
  };
  for (const Case& c : cases) {
    ColmapTextModel model = ValidModel();
    std::string& text = model.*c.file;
    ASSERT_NE(text.find(c.from), std::string::npos) << c.from;
    text.replace(text.find(c.from), c.from.size(), c.to);
    EXPECT_EQ(ParseError(model), c.expected) << c.to;
  }
}

// A rig of three cameras with distinct centres (5 to 8 cm apart, as the Ladybug-like rig's) and
// orientations.
Rig ThreeCameraRig() {
  Rig rig;
  const Eigen::Vector3d centres[3] = {{0.05, 0.0, 0.0}, {-0.03, 0.04, 0.0}, {0.0, -0.02, 0.06}};
  for (int c = 0; c < 3; ++c) {
    Camera camera;
    camera.name = "cam" + std::to_string(c);
    camera.width = 640;
    camera.height = 480;
    camera.params = {500, 500, 320, 240};
    const Eigen::Quaterniond rotation(
        Eigen::AngleAxisd(0.4 + 2.0 * c, Eigen::Vector3d(0.2, 1.0, 0.1 * c).normalized()));
    camera.cam_from_rig = Rigid3d(rotation, -(rotation * centres[c]));
    rig.cameras.push_back(camera);
  }
  return rig;
}

// Frames f = 0..4 of a drive along a curve, world_from_rig in metres.
Rigid3d TrueWorldFromRig(int f) {
  const Eigen::Quaterniond rotation(Eigen::AngleAxisd(0.15 * f, Eigen::Vector3d::UnitZ()) *
                                    Eigen::AngleAxisd(0.02 * f, Eigen::Vector3d::UnitX()));
  return Rigid3d(rotation, Eigen::Vector3d(0.8 * f, 0.1 * f * f, 1.5 + 0.03 * f));
}

// The model of those frames seen in a world moved by a similarity (scale `scale`): each camera's
// cam_from_world with its rig offset scaled; `flat` names the images f<frame>_c<camera>.png,
// otherwise cam<c>/<frame>.png. Frame 2 lacks camera 1 (not registered).
ColmapModel ModelOfKnownPoses(const Rig& rig, double scale, bool flat) {
  const Eigen::Quaterniond world_rotation(
      Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()));
  const Eigen::Vector3d world_translation(4.0, -7.5, 2.25);
  ColmapModel model;
  model.cameras.resize(1);
  model.cameras[0].id = 1;
  uint32_t id = 1;
  for (int f = 0; f < 5; ++f) {
    const Rigid3d world_from_rig = TrueWorldFromRig(f);
    for (int c = 0; c < 3; ++c) {
      if (f == 2 && c == 1) continue;
      const Camera& camera = rig.cameras[static_cast<size_t>(c)];
      const Eigen::Vector3d centre =
          scale * (world_rotation * (world_from_rig * camera.CenterInRig())) + world_translation;
      const Eigen::Quaterniond world_from_cam =
          world_rotation * world_from_rig.rotation * camera.cam_from_rig.rotation.conjugate();
      ColmapImage image;
      image.id = id++;
      image.camera_id = 1;
      image.cam_from_world.rotation = world_from_cam.conjugate();
      image.cam_from_world.translation = -(image.cam_from_world.rotation * centre);
      char name[64];
      if (flat) {
        std::snprintf(name, sizeof(name), "f%06d_c%d.png", f, c);
      } else {
        std::snprintf(name, sizeof(name), "images/cam%d/%06d.png", c, f);
      }
      image.name = name;
      model.images.push_back(image);
    }
  }
  return model;
}

TEST(ColmapKeyframeRigPoses, KnownRigPosesComeBackUpToTheModelsSimilarity) {
  const Rig rig = ThreeCameraRig();
  for (const bool flat : {true, false}) {
    SCOPED_TRACE(flat ? "f<frame>_c<camera> names" : "camera folder names");
    const double scale = 0.37;
    const ColmapModel model = ModelOfKnownPoses(rig, scale, flat);
    ASSERT_EQ(ColmapKeyframes(model).size(), 5u);  // one keyframe per frame
    const ColmapRigPoses poses = ColmapKeyframeRigPoses(model, rig);
    EXPECT_NEAR(poses.model_units_per_metre, scale, 1e-9);
    EXPECT_EQ(poses.camera_pairs, 4u * 3u + 1u);
    ASSERT_EQ(poses.keyframes.size(), 5u);
    const Eigen::Quaterniond world_rotation(
        Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()));
    const Eigen::Vector3d world_translation(4.0, -7.5, 2.25);
    const Eigen::Vector3d rig_centre = rig.CentralCenterInRig();
    for (int f = 0; f < 5; ++f) {
      const ColmapKeyframePose& pose = poses.keyframes[static_cast<size_t>(f)];
      char frame_name[16];
      std::snprintf(frame_name, sizeof(frame_name), "%06d", f);
      EXPECT_EQ(pose.frame_name, frame_name);
      EXPECT_EQ(pose.images, f == 2 ? 2u : 3u);
      const Rigid3d truth = TrueWorldFromRig(f);
      // The orientation, up to the model's rotation.
      const Eigen::Quaterniond expected_rotation = world_rotation * truth.rotation;
      EXPECT_LT(pose.world_from_rig.rotation.angularDistance(expected_rotation), 1e-9) << f;
      // The rig's centre, moved by the model's similarity, and each camera centre on its image.
      const Eigen::Vector3d expected_centre =
          scale * (world_rotation * (truth * rig_centre)) + world_translation;
      EXPECT_LT((pose.world_from_rig * rig_centre - expected_centre).norm(), 1e-9) << f;
    }
  }
}

TEST(ColmapKeyframeRigPoses, AnImageWhoseCameraIsNotInTheRigIsNamed) {
  const Rig rig = ThreeCameraRig();
  ColmapModel model = ModelOfKnownPoses(rig, 1.0, true);
  model.images[4].name = "f000001_c7.png";
  try {
    ColmapKeyframeRigPoses(model, rig);
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& error) {
    EXPECT_STREQ(error.what(), "f000001_c7.png: camera index 7 is not in the rig (3 cameras)");
  }
  model = ModelOfKnownPoses(rig, 1.0, false);
  model.images[0].name = "images/left/000000.png";
  try {
    ColmapKeyframeRigPoses(model, rig);
    ADD_FAILURE() << "no InputError";
  } catch (const InputError& error) {
    EXPECT_NE(std::string(error.what())
                  .find("images/left/000000.png: no rig camera is named "
                        "after its folder 'left'"),
              std::string::npos)
        << error.what();
  }
}

}  // namespace
}  // namespace omni
