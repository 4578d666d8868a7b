#include "calib/rig_io.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <limits>
#include <nlohmann/json.hpp>
#include <set>
#include <sstream>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/input_file.h"

namespace omni {
namespace {

using Json = nlohmann::json;

// A quaternion whose norm is within this of 1 is accepted and normalised; others are rejected
// (a typo, not rounding).
constexpr double kQuaternionNormTolerance = 1e-3;
// Within this of 1 the quaternion is kept exactly as written, so that writing a rig and reading
// it back gives the same bits (renormalising an already unit quaternion can move the last bit).
constexpr double kQuaternionExactTolerance = 1e-12;

// The ranges a real camera and rig can have; values outside are typos or corrupt files.
// Image sides up to this many pixels.
constexpr int kMaxImageSide = 1 << 16;
// Focal lengths in pixels within these multiples of the image's longer side: a 360-degree
// fisheye has about 0.16, a 1000 mm lens on a full-frame sensor about 28.
constexpr double kMinFocalPerSide = 0.01;
constexpr double kMaxFocalPerSide = 100.0;
// The principal point within the image widened by this many image sizes on each side.
constexpr double kPrincipalPointMargin = 1.0;
// Distortion coefficients up to this magnitude.
constexpr double kMaxDistortion = 1000.0;
// A camera at most this far (metres) from the rig's origin.
constexpr double kMaxCameraOffset = 100.0;

const CameraModel kAllModels[] = {CameraModel::kPinhole, CameraModel::kOpenCV,
                                  CameraModel::kFisheye};

// "pinhole, opencv or fisheye".
std::string ModelList() {
  std::string list;
  const size_t count = std::size(kAllModels);
  for (size_t i = 0; i < count; ++i) {
    if (i > 0) list += (i + 1 == count) ? " or " : ", ";
    list += std::string(CameraModelName(kAllModels[i]));
  }
  return list;
}

// How a value is shown in "got ...": numbers and short strings as written, containers by type.
std::string Describe(const Json& value) {
  if (value.is_number() || value.is_boolean() || value.is_null()) return value.dump();
  if (value.is_string()) {
    std::string text = value.dump();
    if (text.size() > 40) text = text.substr(0, 37) + "...\"";
    return "string " + text;
  }
  return std::string(value.type_name());
}

class Parser {
 public:
  explicit Parser(const std::filesystem::path& source) : source_(source) {}

  [[noreturn]] void Fail(const std::string& field, const std::string& problem) const {
    throw InputError(source_, field, problem);
  }

  // The member `key` of `object`, which must exist.
  const Json& Member(const Json& object, const std::string& key, const std::string& field,
                     const std::string& expected) const {
    auto it = object.find(key);
    if (it == object.end()) Fail(field, "missing field (expected " + expected + ")");
    return *it;
  }

  std::string String(const Json& value, const std::string& field) const {
    if (!value.is_string()) Fail(field, "expected a string, got " + Describe(value));
    return value.get<std::string>();
  }

  bool Bool(const Json& value, const std::string& field) const {
    if (!value.is_boolean()) Fail(field, "expected true or false, got " + Describe(value));
    return value.get<bool>();
  }

  double Number(const Json& value, const std::string& field) const {
    if (!value.is_number()) Fail(field, "expected a number, got " + Describe(value));
    const double number = value.get<double>();
    if (!std::isfinite(number)) Fail(field, "expected a finite number, got " + Describe(value));
    return number;
  }

  int PositiveInt(const Json& value, const std::string& field) const {
    const std::string expected = "expected a positive integer, got ";
    if (!value.is_number()) Fail(field, expected + Describe(value));
    const double number = value.get<double>();
    if (!(number >= 1.0 && number <= std::numeric_limits<int>::max()) ||
        number != std::floor(number)) {
      Fail(field, expected + Describe(value));
    }
    return static_cast<int>(number);
  }

  // An array of numbers; `count` < 0 accepts any length.
  std::vector<double> Numbers(const Json& value, const std::string& field, int count,
                              const std::string& what) const {
    const std::string expected =
        count >= 0 ? "expected " + std::to_string(count) + " values (" + what + ")" : what;
    if (!value.is_array()) Fail(field, expected + ", got " + Describe(value));
    if (count >= 0 && static_cast<int>(value.size()) != count) {
      Fail(field, expected + ", got " + std::to_string(value.size()));
    }
    std::vector<double> numbers;
    numbers.reserve(value.size());
    for (size_t i = 0; i < value.size(); ++i) {
      numbers.push_back(Number(value[i], field + "[" + std::to_string(i) + "]"));
    }
    return numbers;
  }

  Rigid3d Transform(const Json& value, const std::string& field) const {
    if (!value.is_object()) {
      Fail(field, "expected an object {\"q_wxyz\": [w, x, y, z], \"t\": [x, y, z]}, got " +
                      Describe(value));
    }
    const std::string q_field = field + ".q_wxyz";
    const std::string q_expected = "a unit quaternion [w, x, y, z]";
    const std::vector<double> q =
        Numbers(Member(value, "q_wxyz", q_field, q_expected), q_field, 4, "w x y z");
    Eigen::Quaterniond rotation(q[0], q[1], q[2], q[3]);
    const double norm = rotation.norm();
    if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) {
      std::ostringstream problem;
      problem << "expected " << q_expected << ", norm is " << norm;
      Fail(q_field, problem.str());
    }
    if (std::abs(norm - 1.0) > kQuaternionExactTolerance) rotation.normalize();

    const std::string t_field = field + ".t";
    const std::vector<double> t =
        Numbers(Member(value, "t", t_field, "a translation [x, y, z]"), t_field, 3, "x y z");
    return Rigid3d(rotation, Eigen::Vector3d(t[0], t[1], t[2]));
  }

  // The ranges above, each failure naming the field and the range.
  void CheckPlausible(const Camera& camera, const std::string& field) const {
    auto range = [](double low, double high) {
      std::ostringstream text;
      text << "[" << low << ", " << high << "]";
      return text.str();
    };
    auto describe = [](double value) {
      std::ostringstream text;
      text << value;
      return text.str();
    };
    if (camera.width > kMaxImageSide) {
      Fail(field + ".width", "expected at most " + std::to_string(kMaxImageSide) + " pixels, got " +
                                 std::to_string(camera.width));
    }
    if (camera.height > kMaxImageSide) {
      Fail(field + ".height", "expected at most " + std::to_string(kMaxImageSide) +
                                  " pixels, got " + std::to_string(camera.height));
    }
    const double side = std::max(camera.width, camera.height);
    const char* names[4] = {"fx", "fy", "cx", "cy"};
    for (int i = 0; i < 2; ++i) {
      const double focal = camera.params[i];
      if (!(focal >= kMinFocalPerSide * side && focal <= kMaxFocalPerSide * side)) {
        Fail(field + ".params[" + std::to_string(i) + "]",
             std::string("expected a focal length ") + names[i] + " in " +
                 range(kMinFocalPerSide * side, kMaxFocalPerSide * side) +
                 " pixels for a camera of " + std::to_string(camera.width) + "x" +
                 std::to_string(camera.height) + ", got " + describe(focal));
      }
    }
    for (int i = 2; i < 4; ++i) {
      const double size = i == 2 ? camera.width : camera.height;
      const double low = -kPrincipalPointMargin * size;
      const double high = (1.0 + kPrincipalPointMargin) * size;
      const double value = camera.params[i];
      if (!(value >= low && value <= high)) {
        Fail(field + ".params[" + std::to_string(i) + "]",
             std::string("expected a principal point ") + names[i] + " in " + range(low, high) +
                 " pixels for a camera of " + std::to_string(camera.width) + "x" +
                 std::to_string(camera.height) + ", got " + describe(value));
      }
    }
    for (size_t i = 4; i < camera.params.size(); ++i) {
      if (!(std::abs(camera.params[i]) <= kMaxDistortion)) {
        Fail(field + ".params[" + std::to_string(i) + "]",
             "expected a distortion coefficient in " + range(-kMaxDistortion, kMaxDistortion) +
                 ", got " + describe(camera.params[i]));
      }
    }
    const Eigen::Vector3d& t = camera.cam_from_rig.translation;
    // The largest component first: the norm of [1e308, 0, 0] overflows.
    if (!(t.cwiseAbs().maxCoeff() <= kMaxCameraOffset && t.norm() <= kMaxCameraOffset)) {
      Fail(field + ".cam_from_rig.t", "expected a camera within " + describe(kMaxCameraOffset) +
                                          " m of the rig's origin, got [" + describe(t.x()) + ", " +
                                          describe(t.y()) + ", " + describe(t.z()) + "]");
    }
  }

  Camera ParseCamera(const Json& value, const std::string& field) const {
    if (!value.is_object()) Fail(field, "expected a camera object, got " + Describe(value));
    Camera camera;
    camera.name = String(Member(value, "name", field + ".name", "a string"), field + ".name");
    if (camera.name.empty()) Fail(field + ".name", "expected a non-empty name");
    // The name is also the camera's image folder in a drive (images/<name>/).
    if (camera.name.find_first_of("/\\") != std::string::npos || camera.name == "." ||
        camera.name == "..") {
      Fail(field + ".name",
           "expected a name usable as a folder name (no '/' or '\\'), got \"" + camera.name + "\"");
    }
    camera.width = PositiveInt(Member(value, "width", field + ".width", "a positive integer"),
                               field + ".width");
    camera.height = PositiveInt(Member(value, "height", field + ".height", "a positive integer"),
                                field + ".height");

    const std::string model_field = field + ".model";
    const std::string model_name =
        String(Member(value, "model", model_field, ModelList()), model_field);
    const std::optional<CameraModel> model = CameraModelFromName(model_name);
    if (!model) {
      Fail(model_field,
           "unknown camera model \"" + model_name + "\" (expected " + ModelList() + ")");
    }
    camera.model = *model;

    const std::string params_field = field + ".params";
    const std::string params_description(CameraParamsDescription(camera.model));
    camera.params =
        Numbers(Member(value, "params", params_field, "an array [" + params_description + "]"),
                params_field, NumCameraParams(camera.model), params_description);

    camera.cam_from_rig =
        Transform(Member(value, "cam_from_rig", field + ".cam_from_rig",
                         "an object {\"q_wxyz\": [w, x, y, z], \"t\": [x, y, z]}"),
                  field + ".cam_from_rig");

    CheckPlausible(camera, field);

    // Semantic checks of the camera model. Camera::Check names the field relative to the
    // camera ("params: ..."); prefix it with this camera's path.
    const std::string problem = camera.Check();
    if (!problem.empty()) {
      const size_t colon = problem.find(": ");
      const std::string head = colon == std::string::npos ? "" : problem.substr(0, colon);
      if (!head.empty() && std::isalpha(static_cast<unsigned char>(head[0]))) {
        Fail(field + "." + head, problem.substr(colon + 2));
      }
      Fail(field, problem);
    }
    return camera;
  }

  Rig ParseRig(const Json& root) const {
    if (!root.is_object()) {
      Fail("", "expected a JSON object at the top level, got " + Describe(root));
    }
    Rig rig;
    rig.name = String(Member(root, "name", "name", "a string"), "name");
    // Whether the SfM may treat the rig as one central camera: a choice the file states.
    rig.central = Bool(Member(root, "central", "central",
                              "true (one central camera, the paper's approximation) or false"),
                       "central");

    const Json& cameras = Member(root, "cameras", "cameras", "an array of cameras");
    if (!cameras.is_array()) {
      Fail("cameras", "expected an array of cameras, got " + Describe(cameras));
    }
    if (cameras.empty()) Fail("cameras", "expected at least one camera, got none");
    std::set<std::string> names;
    for (size_t i = 0; i < cameras.size(); ++i) {
      const std::string field = "cameras[" + std::to_string(i) + "]";
      Camera camera = ParseCamera(cameras[i], field);
      if (!names.insert(camera.name).second) {
        Fail(field + ".name", "duplicate camera name \"" + camera.name + "\"");
      }
      rig.cameras.push_back(std::move(camera));
    }
    const std::string problem = rig.Check();
    if (!problem.empty()) Fail("", problem);
    return rig;
  }

 private:
  const std::filesystem::path& source_;
};

nlohmann::ordered_json TransformToJson(const Rigid3d& transform) {
  nlohmann::ordered_json json;
  const Eigen::Quaterniond& q = transform.rotation;
  json["q_wxyz"] = {q.w(), q.x(), q.y(), q.z()};
  const Eigen::Vector3d& t = transform.translation;
  json["t"] = {t.x(), t.y(), t.z()};
  return json;
}

}  // namespace

Rig ParseRigJson(const std::string& text, const std::filesystem::path& source) {
  Json root;
  try {
    root = Json::parse(text);
  } catch (const Json::parse_error& error) {
    // what() is "[json.exception.parse_error.101] parse error at line L, column C: ...".
    std::string message = error.what();
    const size_t bracket = message.find("] ");
    if (bracket != std::string::npos) message = message.substr(bracket + 2);
    throw InputError(source, "",
                     "invalid JSON at byte " + std::to_string(error.byte) + ": " + message);
  } catch (const Json::exception& error) {
    // A number too large for a double (out_of_range.406 "number overflow parsing '1e309'").
    std::string message = error.what();
    const size_t bracket = message.find("] ");
    if (bracket != std::string::npos) message = message.substr(bracket + 2);
    throw InputError(source, "", "invalid JSON: " + message);
  }
  return Parser(source).ParseRig(root);
}

Rig ReadRigJson(const std::filesystem::path& path) {
  return ParseRigJson(ReadInputFile(path), path);
}

std::string RigToJson(const Rig& rig) {
  nlohmann::ordered_json root;
  root["name"] = rig.name;
  root["central"] = rig.central;
  root["cameras"] = nlohmann::ordered_json::array();
  for (const Camera& camera : rig.cameras) {
    nlohmann::ordered_json json;
    json["name"] = camera.name;
    json["width"] = camera.width;
    json["height"] = camera.height;
    json["model"] = std::string(CameraModelName(camera.model));
    json["params"] = camera.params;
    json["cam_from_rig"] = TransformToJson(camera.cam_from_rig);
    root["cameras"].push_back(std::move(json));
  }
  // nlohmann writes doubles with the shortest text that reads back to the same bits.
  return root.dump(2) + "\n";
}

void WriteRigJson(const Rig& rig, const std::filesystem::path& path) {
  WriteTextFileAtomically(path, RigToJson(rig));
}

}  // namespace omni
