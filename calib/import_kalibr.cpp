// Kalibr camchain.yaml / camchain-imucam.yaml -> Rig (calib/import.h).
//
// Each camera is a top-level map `camN` (N = 0, 1, ... without gaps) with camera_model
// (pinhole only), intrinsics [fu fv pu pv], distortion_model (radtan, equidistant or none),
// distortion_coeffs, resolution [w h], optionally rostopic, and the extrinsics T_cn_cnm1
// (cam_n_from_cam_n-1, 4x4) and/or T_cam_imu (cam_from_imu, 4x4).

#include <yaml-cpp/yaml.h>

#include <Eigen/Core>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#include "calib/error.h"
#include "calib/import.h"
#include "calib/input_file.h"
#include "calib/rig_io.h"

namespace omni {
namespace {

std::string LineSuffix(const YAML::Node& node) {
  const YAML::Mark mark = node.Mark();
  if (mark.is_null()) return "";
  return " (line " + std::to_string(mark.line + 1) + ")";
}

std::vector<double> ReadNumbers(const std::filesystem::path& file, const YAML::Node& node,
                                const std::string& field, int expected_count,
                                const std::string& description) {
  const std::string expected = "expected " + std::to_string(expected_count) + " numbers [" +
                               description + "]" + LineSuffix(node);
  if (!node.IsSequence() || static_cast<int>(node.size()) != expected_count) {
    throw InputError(file, field, expected);
  }
  std::vector<double> values;
  for (const YAML::Node& item : node) {
    double value = 0.0;
    if (!item.IsScalar() || !YAML::convert<double>::decode(item, value) || !std::isfinite(value)) {
      throw InputError(file, field, expected);
    }
    values.push_back(value);
  }
  return values;
}

// A rigid 4x4 transform [R t; 0 0 0 1].
Rigid3d ReadTransform(const std::filesystem::path& file, const YAML::Node& node,
                      const std::string& field, const KalibrImportOptions& options) {
  const std::string expected = "expected a 4x4 rigid transform (4 rows of 4 numbers)";
  if (!node.IsSequence() || node.size() != 4) {
    throw InputError(file, field, expected + LineSuffix(node));
  }
  Eigen::Matrix4d matrix;
  for (int row = 0; row < 4; ++row) {
    const std::vector<double> values =
        ReadNumbers(file, node[row], field + " row " + std::to_string(row), 4, "4 numbers");
    for (int col = 0; col < 4; ++col) matrix(row, col) = values[col];
  }
  const Eigen::Matrix3d rotation = matrix.topLeftCorner<3, 3>();
  const double orthonormality_error =
      (rotation.transpose() * rotation - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  const double bottom_row_error =
      (matrix.row(3) - Eigen::RowVector4d(0.0, 0.0, 0.0, 1.0)).cwiseAbs().maxCoeff();
  if (orthonormality_error > options.rotation_tolerance || rotation.determinant() < 0.0 ||
      bottom_row_error > options.rotation_tolerance) {
    std::ostringstream problem;
    problem << "not a rigid transform (|R^T R - I| = " << orthonormality_error
            << ", det R = " << rotation.determinant() << ", bottom row must be 0 0 0 1)"
            << LineSuffix(node);
    throw InputError(file, field, problem.str());
  }
  return Rigid3d::FromMatrix(matrix.topRows<3>());
}

bool IsFolderName(const std::string& name) {
  if (name.empty() || name == "." || name == "..") return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

// The camera's name from its rostopic: the last path component that names the camera rather
// than the image stream ("/stereo/left/image_raw" -> "left"), or "" when there is none.
std::string NameFromRostopic(const std::string& rostopic) {
  std::vector<std::string> parts;
  std::stringstream stream(rostopic);
  std::string part;
  while (std::getline(stream, part, '/')) {
    if (!part.empty()) parts.push_back(part);
  }
  for (auto it = parts.rbegin(); it != parts.rend(); ++it) {
    const bool image_stream = it->rfind("image", 0) == 0 || *it == "compressed";
    if (!image_stream) return IsFolderName(*it) ? *it : "";
  }
  return "";
}

Rig ParseKalibrYaml(const std::string& text, const std::filesystem::path& camchain_yaml,
                    const KalibrImportOptions& options);

}  // namespace

std::string KalibrImportOptions::Check() const {
  if (!(central_max_center_offset_m >= 0.0)) return "central_max_center_offset_m: must be >= 0";
  if (!(rotation_tolerance > 0.0)) return "rotation_tolerance: must be > 0";
  return "";
}

Rig ImportKalibr(const std::filesystem::path& camchain_yaml) {
  return ImportKalibr(camchain_yaml, KalibrImportOptions{});
}

Rig ImportKalibr(const std::filesystem::path& camchain_yaml, const KalibrImportOptions& options) {
  ThrowIfInvalid(options.Check(), "KalibrImportOptions");
  if (!std::filesystem::is_regular_file(camchain_yaml)) {
    throw InputError(camchain_yaml, "", "no such file");
  }
  return ParseKalibr(ReadInputFile(camchain_yaml), camchain_yaml, options);
}

Rig ParseKalibr(const std::string& text, const std::filesystem::path& camchain_yaml,
                const KalibrImportOptions& options) {
  ThrowIfInvalid(options.Check(), "KalibrImportOptions");
  try {
    return ParseKalibrYaml(text, camchain_yaml, options);
  } catch (const YAML::Exception& error) {
    // A node of an unexpected kind (a map where a name is expected, ...).
    throw InputError(camchain_yaml, "", std::string("malformed YAML: ") + error.what());
  }
}

namespace {

Rig ParseKalibrYaml(const std::string& text, const std::filesystem::path& camchain_yaml,
                    const KalibrImportOptions& options) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::Exception& error) {
    throw InputError(camchain_yaml, "", std::string("malformed YAML: ") + error.what());
  }
  if (!root.IsMap()) {
    throw InputError(camchain_yaml, "", "expected a map of cameras cam0, cam1, ...");
  }

  // cam0, cam1, ... in numeric order (a YAML map has no order of its own).
  std::map<int, YAML::Node> camera_nodes;
  for (const auto& entry : root) {
    const std::string key = entry.first.as<std::string>();
    // At most 4 digits: cam0 to cam9999.
    if (key.size() > 3 && key.size() <= 7 && key.compare(0, 3, "cam") == 0 &&
        std::all_of(key.begin() + 3, key.end(),
                    [](char c) { return std::isdigit(static_cast<unsigned char>(c)); })) {
      camera_nodes[std::stoi(key.substr(3))] = entry.second;
    }
  }
  if (camera_nodes.empty()) throw InputError(camchain_yaml, "cam0", "missing: no camera found");
  for (int index = 0; index < static_cast<int>(camera_nodes.size()); ++index) {
    if (camera_nodes.count(index) == 0) {
      throw InputError(camchain_yaml, "cam" + std::to_string(index),
                       "missing: cameras must be numbered cam0, cam1, ... without gaps");
    }
  }

  Rig rig;
  rig.name = camchain_yaml.stem().string();
  std::vector<std::string> topic_names;
  std::vector<YAML::Node> chain_nodes, imu_nodes;
  for (const auto& entry : camera_nodes) {
    // Not a structured binding: C++17 lambdas (below) cannot capture one.
    const int index = entry.first;
    const YAML::Node& node = entry.second;
    const std::string key = "cam" + std::to_string(index);
    if (!node.IsMap()) throw InputError(camchain_yaml, key, "expected a map" + LineSuffix(node));
    auto field = [&](const char* name) { return key + "." + name; };
    auto require = [&](const char* name) {
      const YAML::Node value = node[name];
      if (!value) throw InputError(camchain_yaml, field(name), "missing");
      return value;
    };
    auto read_string = [&](const char* name) {
      const YAML::Node value = require(name);
      if (!value.IsScalar()) {
        throw InputError(camchain_yaml, field(name), "expected a string" + LineSuffix(value));
      }
      return value.as<std::string>();
    };

    Camera camera;
    const std::string camera_model = read_string("camera_model");
    if (camera_model != "pinhole") {
      throw InputError(camchain_yaml, field("camera_model"),
                       "unsupported model '" + camera_model + "' (only pinhole is imported)");
    }
    const std::vector<double> intrinsics =
        ReadNumbers(camchain_yaml, require("intrinsics"), field("intrinsics"), 4, "fu fv pu pv");
    const std::vector<double> resolution =
        ReadNumbers(camchain_yaml, require("resolution"), field("resolution"), 2, "width height");
    for (double size : resolution) {
      if (!(size >= 1.0 && size <= kMaxImportedImageSide) || size != std::floor(size)) {
        throw InputError(
            camchain_yaml, field("resolution"),
            "expected two positive integers up to " + std::to_string(kMaxImportedImageSide));
      }
    }
    camera.width = static_cast<int>(resolution[0]);
    camera.height = static_cast<int>(resolution[1]);
    camera.params = intrinsics;

    const std::string distortion_model =
        node["distortion_model"] ? read_string("distortion_model") : "none";
    if (distortion_model == "radtan") {
      const std::vector<double> coeffs = ReadNumbers(camchain_yaml, require("distortion_coeffs"),
                                                     field("distortion_coeffs"), 4, "k1 k2 r1 r2");
      camera.model = CameraModel::kOpenCV;
      camera.params.insert(camera.params.end(), coeffs.begin(), coeffs.end());
      camera.params.push_back(0.0);  // k3: radtan has none
    } else if (distortion_model == "equidistant") {
      const std::vector<double> coeffs = ReadNumbers(camchain_yaml, require("distortion_coeffs"),
                                                     field("distortion_coeffs"), 4, "k1 k2 k3 k4");
      camera.model = CameraModel::kFisheye;
      camera.params.insert(camera.params.end(), coeffs.begin(), coeffs.end());
    } else if (distortion_model == "none") {
      camera.model = CameraModel::kPinhole;
    } else {
      throw InputError(
          camchain_yaml, field("distortion_model"),
          "unsupported model '" + distortion_model + "' (expected radtan, equidistant or none)");
    }

    topic_names.push_back(node["rostopic"] && node["rostopic"].IsScalar()
                              ? NameFromRostopic(node["rostopic"].as<std::string>())
                              : "");
    camera.name = key;
    chain_nodes.push_back(node["T_cn_cnm1"]);
    imu_nodes.push_back(node["T_cam_imu"]);
    rig.cameras.push_back(camera);
  }

  // Names from the rostopics only when every camera has one and they are all different.
  const std::set<std::string> distinct(topic_names.begin(), topic_names.end());
  const bool use_topic_names = distinct.size() == topic_names.size() && distinct.count("") == 0;
  if (use_topic_names) {
    for (size_t i = 0; i < rig.cameras.size(); ++i) rig.cameras[i].name = topic_names[i];
  }

  // Extrinsics: cam0 defines the rig frame; cam_n_from_rig = cam_n_from_cam_n-1 *
  // cam_n-1_from_rig, or, without T_cn_cnm1, cam_n_from_imu * (cam0_from_imu)^-1.
  const bool all_have_imu =
      std::all_of(imu_nodes.begin(), imu_nodes.end(), [](const YAML::Node& n) { return bool(n); });
  for (size_t i = 1; i < rig.cameras.size(); ++i) {
    const std::string key = "cam" + std::to_string(i);
    if (chain_nodes[i]) {
      const Rigid3d cam_n_from_cam_nm1 =
          ReadTransform(camchain_yaml, chain_nodes[i], key + ".T_cn_cnm1", options);
      rig.cameras[i].cam_from_rig = cam_n_from_cam_nm1 * rig.cameras[i - 1].cam_from_rig;
    } else if (all_have_imu) {
      const Rigid3d cam_from_imu =
          ReadTransform(camchain_yaml, imu_nodes[i], key + ".T_cam_imu", options);
      const Rigid3d cam0_from_imu =
          ReadTransform(camchain_yaml, imu_nodes[0], "cam0.T_cam_imu", options);
      rig.cameras[i].cam_from_rig = cam_from_imu * cam0_from_imu.Inverse();
    } else {
      throw InputError(camchain_yaml, key + ".T_cn_cnm1",
                       "missing (and not every camera has T_cam_imu to fall back on)");
    }
  }

  rig.central = rig.MaxCenterOffset() <= options.central_max_center_offset_m;
  // The checks of rig.json, ranges included: what is imported reads back.
  return ParseRigJson(RigToJson(rig), camchain_yaml);
}

}  // namespace

}  // namespace omni
