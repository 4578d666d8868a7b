#include "calib/rig_io.h"

#include <gtest/gtest.h>

#include <cmath>
#include <nlohmann/json.hpp>
#include <random>
#include <string>

#include "calib/error.h"
#include "tests/calib/io_temp_dir.h"

namespace omni {
namespace {

using Json = nlohmann::json;
using omni::testing::TempDir;

Eigen::Quaterniond RandomRotation(std::mt19937* rng) {
  std::normal_distribution<double> normal;
  Eigen::Quaterniond q(normal(*rng), normal(*rng), normal(*rng), normal(*rng));
  return q.normalized();
}

// Three cameras, one per model, with values that have no short decimal form.
Rig MakeRig() {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uniform(-1.0, 1.0);
  Rig rig;
  rig.name = "test rig";
  rig.central = false;
  const CameraModel models[] = {CameraModel::kPinhole, CameraModel::kOpenCV, CameraModel::kFisheye,
                                CameraModel::kOpenCV};
  int index = 0;
  for (CameraModel model : models) {
    Camera camera;
    camera.name = "cam" + std::to_string(index);
    camera.width = 384 + index;
    camera.height = 512 - index;
    camera.model = model;
    camera.params = {228.81669 + 1.0 / 3.0, 229.1 / 7.0 + 200.0, 191.5 + uniform(rng),
                     255.5 + uniform(rng)};
    while (static_cast<int>(camera.params.size()) < NumCameraParams(model)) {
      camera.params.push_back(0.01 * uniform(rng));
    }
    camera.cam_from_rig = Rigid3d(
        RandomRotation(&rng), Eigen::Vector3d(uniform(rng) * 0.1, uniform(rng) * 1e-7, -1.0 / 3.0));
    rig.cameras.push_back(camera);
    ++index;
  }
  return rig;
}

void ExpectRigsIdentical(const Rig& a, const Rig& b) {
  EXPECT_EQ(a.name, b.name);
  EXPECT_EQ(a.central, b.central);
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (size_t i = 0; i < a.cameras.size(); ++i) {
    SCOPED_TRACE("camera " + std::to_string(i));
    const Camera& ca = a.cameras[i];
    const Camera& cb = b.cameras[i];
    EXPECT_EQ(ca.name, cb.name);
    EXPECT_EQ(ca.width, cb.width);
    EXPECT_EQ(ca.height, cb.height);
    EXPECT_EQ(ca.model, cb.model);
    EXPECT_EQ(ca.params, cb.params);  // exact
    EXPECT_EQ(ca.cam_from_rig.rotation.coeffs(), cb.cam_from_rig.rotation.coeffs());
    EXPECT_EQ(ca.cam_from_rig.translation, cb.cam_from_rig.translation);
  }
}

// The message of the InputError that parsing `json` throws (fails the test if none).
std::string ParseError(const Json& json) {
  try {
    ParseRigJson(json.dump(2), "rig.json");
  } catch (const InputError& error) {
    return error.what();
  }
  ADD_FAILURE() << "no InputError for " << json.dump();
  return "";
}

Json ValidJson() { return Json::parse(RigToJson(MakeRig())); }

TEST(RigJson, RoundTripIsExactForAllModels) {
  const Rig rig = MakeRig();
  const std::string text = RigToJson(rig);
  const Rig parsed = ParseRigJson(text, "memory");
  ExpectRigsIdentical(rig, parsed);
  EXPECT_EQ(RigToJson(parsed), text);
}

TEST(RigJson, FileRoundTripIsExactAndAtomic) {
  TempDir dir;
  const Rig rig = MakeRig();
  const auto path = dir / "rig.json";
  WriteRigJson(rig, path);
  EXPECT_FALSE(std::filesystem::exists(dir / "rig.json.tmp"));
  ExpectRigsIdentical(rig, ReadRigJson(path));
}

TEST(RigJson, LayoutIsOrderedAndIndentedByTwo) {
  const std::string text = RigToJson(MakeRig());
  EXPECT_EQ(text.rfind("{\n  \"name\": \"test rig\",\n  \"central\": false,\n  \"cameras\": [", 0),
            0u)
      << text.substr(0, 200);
  EXPECT_LT(text.find("\"q_wxyz\""), text.find("\"t\""));
}

TEST(RigJson, SampleLadybugRigReadsAndRoundTrips) {
  const std::filesystem::path path =
      std::filesystem::path(OMNI_SOURCE_DIR) / "data" / "rigs" / "ladybug-like.json";
  const Rig rig = ReadRigJson(path);
  EXPECT_EQ(rig.name, "ladybug-like");
  EXPECT_FALSE(rig.central);
  ASSERT_EQ(rig.NumCameras(), 6u);
  const Json json = Json::parse(testing::ReadBytes(path));
  for (size_t i = 0; i < 6; ++i) {
    const Camera& camera = rig.cameras[i];
    const Json& expected = json["cameras"][i];
    EXPECT_EQ(camera.name, expected["name"].get<std::string>());
    EXPECT_EQ(camera.width, 384);
    EXPECT_EQ(camera.height, 512);
    EXPECT_EQ(camera.model, CameraModel::kPinhole);
    EXPECT_EQ(camera.params, expected["params"].get<std::vector<double>>());
    const auto q = expected["cam_from_rig"]["q_wxyz"].get<std::vector<double>>();
    // The file's quaternions have 12 digits; they are normalised on reading.
    EXPECT_NEAR(camera.cam_from_rig.rotation.w(), q[0], 1e-9);
    EXPECT_NEAR(camera.cam_from_rig.rotation.x(), q[1], 1e-9);
    EXPECT_NEAR(camera.cam_from_rig.rotation.y(), q[2], 1e-9);
    EXPECT_NEAR(camera.cam_from_rig.rotation.z(), q[3], 1e-9);
    EXPECT_NEAR(camera.cam_from_rig.rotation.norm(), 1.0, 1e-12);
    EXPECT_EQ(camera.cam_from_rig.translation,
              Eigen::Vector3d(expected["cam_from_rig"]["t"].get<std::vector<double>>().data()));
  }
  const Rig again = ParseRigJson(RigToJson(rig), "memory");
  ExpectRigsIdentical(rig, again);
  EXPECT_EQ(RigToJson(again), RigToJson(rig));
}

TEST(RigJson, CentralIsRequiredAndExtraFieldsAreIgnored) {
  Json json = ValidJson();
  json["comment"] = "made by hand";
  json["cameras"][0]["serial"] = 12345;
  const Rig rig = ParseRigJson(json.dump(), "rig.json");
  EXPECT_FALSE(rig.central);
  EXPECT_EQ(rig.NumCameras(), 4u);
  json.erase("central");
  EXPECT_EQ(ParseError(json),
            "rig.json: central: missing field (expected true (one central camera, the paper's "
            "approximation) or false)");
}

// Numbers too large for a double are bad input naming the file, not a parser's exception.
TEST(RigJson, NumberOverflowNamesTheFile) {
  const std::string valid = RigToJson(MakeRig());
  const std::string width = "\"width\": 384";  // cameras[0].width
  ASSERT_NE(valid.find(width), std::string::npos);
  for (const std::string& number : {std::string("1e309"), std::string(400, '9')}) {
    std::string text = valid;
    text.replace(text.find(width), width.size(), "\"width\": " + number);
    try {
      ParseRigJson(text, "my/rig.json");
      ADD_FAILURE() << "accepted " << number.substr(0, 20);
    } catch (const InputError& error) {
      const std::string message = error.what();
      EXPECT_EQ(message.rfind("my/rig.json: invalid JSON: number overflow", 0), 0u) << message;
    }
  }
}

// Finite values no real camera or rig has are refused, naming the field and the range.
TEST(RigJson, ImplausibleValuesAreRefused) {
  Json json = ValidJson();  // camera 0: 384x512
  json["cameras"][0]["params"][0] = 1e20;
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[0].params[0]: expected a focal length fx in [5.12, 51200] pixels "
            "for a camera of 384x512, got 1e+20");
  json = ValidJson();
  json["cameras"][1]["params"][1] = 1.0;
  EXPECT_NE(ParseError(json).find("cameras[1].params[1]: expected a focal length fy in"),
            std::string::npos);
  json = ValidJson();
  json["cameras"][0]["params"][2] = 1e39;
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[0].params[2]: expected a principal point cx in [-384, 768] "
            "pixels for a camera of 384x512, got 1e+39");
  json = ValidJson();
  json["cameras"][0]["params"][3] = -600;
  EXPECT_NE(ParseError(json).find("cameras[0].params[3]: expected a principal point cy in "
                                  "[-512, 1024]"),
            std::string::npos);
  json = ValidJson();
  json["cameras"][1]["params"][4] = 5e3;  // k1 of an opencv camera
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[1].params[4]: expected a distortion coefficient in [-1000, 1000], "
            "got 5000");
  json = ValidJson();
  json["cameras"][2]["cam_from_rig"]["t"] = {1e308, 0, 0};
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[2].cam_from_rig.t: expected a camera within 100 m of the rig's "
            "origin, got [1e+308, 0, 0]");
  json = ValidJson();
  json["cameras"][3]["width"] = 100000;
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[3].width: expected at most 65536 pixels, got 100000");
}

// The project's rigs and the real drives' rigs are within the ranges.
TEST(RigJson, ProjectAndRealRigsAreAccepted) {
  const std::filesystem::path source(OMNI_SOURCE_DIR);
  for (const char* name : {"ladybug-like", "pinhole", "car", "fisheye5"}) {
    EXPECT_NO_THROW(ReadRigJson(source / "data" / "rigs" / (std::string(name) + ".json"))) << name;
  }
  const std::filesystem::path real = source.parent_path() / "shared" / "data" / "real";
  ASSERT_TRUE(std::filesystem::is_directory(real)) << real;
  int read = 0;
  for (const auto& entry : std::filesystem::directory_iterator(real)) {
    if (!std::filesystem::exists(entry.path() / "rig.json")) continue;
    EXPECT_NO_THROW(ReadRigJson(entry.path() / "rig.json")) << entry.path();
    ++read;
  }
  EXPECT_GE(read, 2);
}

TEST(RigJson, NearlyUnitQuaternionIsNormalised) {
  Json json = ValidJson();
  json["cameras"][1]["cam_from_rig"]["q_wxyz"] = {1.0005, 0.0, 0.0, 0.0};
  const Rig rig = ParseRigJson(json.dump(), "rig.json");
  EXPECT_EQ(rig.cameras[1].cam_from_rig.rotation.w(), 1.0);
  EXPECT_EQ(rig.cameras[1].cam_from_rig.rotation.vec(), Eigen::Vector3d::Zero());
}

TEST(RigJson, MissingField) {
  Json json = ValidJson();
  json["cameras"][1].erase("height");
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[1].height: missing field (expected a positive integer)");
  json = ValidJson();
  json["cameras"][0]["cam_from_rig"].erase("t");
  EXPECT_NE(ParseError(json).find("rig.json: cameras[0].cam_from_rig.t: missing field"),
            std::string::npos);
  json = ValidJson();
  json.erase("cameras");
  EXPECT_NE(ParseError(json).find("rig.json: cameras: missing field"), std::string::npos);
}

TEST(RigJson, WrongType) {
  Json json = ValidJson();
  json["cameras"][0]["width"] = "384";
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[0].width: expected a positive integer, got string \"384\"");
  json = ValidJson();
  json["cameras"][3]["name"] = 3;
  EXPECT_EQ(ParseError(json), "rig.json: cameras[3].name: expected a string, got 3");
  json = ValidJson();
  json["central"] = "yes";
  EXPECT_EQ(ParseError(json), "rig.json: central: expected true or false, got string \"yes\"");
  json = ValidJson();
  json["cameras"][2]["params"][1] = "x";
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[2].params[1]: expected a number, got string \"x\"");
  json = ValidJson();
  json["cameras"] = Json::object();
  EXPECT_EQ(ParseError(json), "rig.json: cameras: expected an array of cameras, got object");
  EXPECT_EQ(ParseError(Json::array()),
            "rig.json: expected a JSON object at the top level, got array");
}

TEST(RigJson, NegativeOrFractionalSize) {
  Json json = ValidJson();
  json["cameras"][2]["width"] = -384;
  EXPECT_EQ(ParseError(json), "rig.json: cameras[2].width: expected a positive integer, got -384");
  json = ValidJson();
  json["cameras"][0]["height"] = 511.5;
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[0].height: expected a positive integer, got 511.5");
}

TEST(RigJson, BadQuaternion) {
  Json json = ValidJson();
  json["cameras"][0]["cam_from_rig"]["q_wxyz"] = {0, 0, 0, 0};
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[0].cam_from_rig.q_wxyz: expected a unit quaternion [w, x, y, z], "
            "norm is 0");
  json = ValidJson();
  json["cameras"][0]["cam_from_rig"]["q_wxyz"] = {1.0, 0.0, 0.0, 0.1};
  EXPECT_NE(ParseError(json).find("cameras[0].cam_from_rig.q_wxyz: expected a unit quaternion"),
            std::string::npos);
  json = ValidJson();
  json["cameras"][0]["cam_from_rig"]["q_wxyz"] = {1.0, 0.0, 0.0};
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[0].cam_from_rig.q_wxyz: expected 4 values (w x y z), got 3");
}

TEST(RigJson, WrongParamCount) {
  Json json = ValidJson();
  json["cameras"][0]["model"] = "opencv";  // camera 0 has the 4 pinhole params
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[0].params: expected 9 values (fx fy cx cy k1 k2 p1 p2 k3), got 4");
}

TEST(RigJson, UnknownModel) {
  Json json = ValidJson();
  json["cameras"][1]["model"] = "fishey";
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[1].model: unknown camera model \"fishey\" (expected pinhole, "
            "opencv or fisheye)");
}

TEST(RigJson, SemanticCheckOfCameraNamesTheCamera) {
  Json json = ValidJson();
  json["cameras"][2]["params"][0] = -5.0;  // fx
  const std::string message = ParseError(json);
  EXPECT_EQ(message.rfind("rig.json: cameras[2].params[0]", 0), 0u) << message;
}

TEST(RigJson, JsonSyntaxErrorGivesItsPlace) {
  const std::string text = "{\n  \"name\": \"x\",\n  \"cameras\": [ }\n";
  try {
    ParseRigJson(text, "rig.json");
    FAIL() << "no error";
  } catch (const InputError& error) {
    const std::string message = error.what();
    EXPECT_EQ(message.rfind("rig.json: invalid JSON at byte ", 0), 0u) << message;
    EXPECT_NE(message.find("line 3"), std::string::npos) << message;
  }
}

TEST(RigJson, EmptyCameras) {
  Json json = ValidJson();
  json["cameras"] = Json::array();
  EXPECT_EQ(ParseError(json), "rig.json: cameras: expected at least one camera, got none");
}

TEST(RigJson, DuplicateNames) {
  Json json = ValidJson();
  json["cameras"][2]["name"] = "cam0";
  EXPECT_EQ(ParseError(json), "rig.json: cameras[2].name: duplicate camera name \"cam0\"");
}

TEST(RigJson, CameraNameMustBeAFolderName) {
  Json json = ValidJson();
  json["cameras"][1]["name"] = "../up";
  EXPECT_EQ(ParseError(json),
            "rig.json: cameras[1].name: expected a name usable as a folder name (no '/' or '\\'), "
            "got \"../up\"");
}

TEST(RigJson, MissingFileNamesIt) {
  TempDir dir;
  const auto path = dir / "nowhere" / "rig.json";
  try {
    ReadRigJson(path);
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_EQ(std::string(error.what()), path.string() + ": cannot open");
    EXPECT_EQ(error.file(), path);
  }
}

TEST(RigJson, FileErrorsNameTheFile) {
  TempDir dir;
  const auto path = dir / "my_rig.json";
  Json json = ValidJson();
  json["cameras"][3]["width"] = 0;
  testing::WriteBytes(path, json.dump());
  try {
    ReadRigJson(path);
    FAIL() << "no error";
  } catch (const InputError& error) {
    EXPECT_EQ(std::string(error.what()),
              path.string() + ": cameras[3].width: expected a positive integer, got 0");
    EXPECT_EQ(error.field(), "cameras[3].width");
  }
}

}  // namespace
}  // namespace omni
