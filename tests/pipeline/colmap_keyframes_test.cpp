// The COLMAP text reader of `surface --colmap` refuses malformed models naming the file and line;
// the rig poses of a model's keyframes come back from a model made of known poses.

#include "pipeline/colmap_keyframes.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <random>
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
