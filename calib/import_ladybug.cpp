// Ladybug SDK calibration text (.conf) -> Rig (the convention is in calib/import.h).

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <fstream>
#include <optional>
#include <sstream>

#include "calib/error.h"
#include "calib/import.h"
#include "calib/input_file.h"
#include "calib/number_text.h"
#include "calib/rig_io.h"

namespace omni {
namespace {

std::string Lower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

struct CameraBlock {
  int begin_line = 0;
  std::optional<Eigen::Vector2d> focal;                             // fu fv (focal / W, focal / H)
  std::optional<Eigen::Matrix<double, 6, 1>> euler_zyx_and_centre;  // rx ry rz tx ty tz
  std::optional<Eigen::Vector2d> principal;                         // U V (normalised)
};

// head_from_cam of one block: R = Rz(rz) Ry(ry) Rx(rx), t = the camera centre in the head.
Rigid3d HeadFromCam(const Eigen::Matrix<double, 6, 1>& values) {
  const Eigen::Quaterniond rotation(Eigen::AngleAxisd(values[2], Eigen::Vector3d::UnitZ()) *
                                    Eigen::AngleAxisd(values[1], Eigen::Vector3d::UnitY()) *
                                    Eigen::AngleAxisd(values[0], Eigen::Vector3d::UnitX()));
  return Rigid3d(rotation.normalized(), values.tail<3>());
}

}  // namespace

Rig ImportLadybug(const std::filesystem::path& conf, const LadybugImportOptions& options) {
  return ParseLadybug(ReadInputFile(conf), conf, options);
}

Rig ParseLadybug(const std::string& text, const std::filesystem::path& conf,
                 const LadybugImportOptions& options) {
  std::istringstream stream(text);

  std::optional<Eigen::Vector2i> resolution;
  std::vector<CameraBlock> blocks;
  bool in_block = false;

  std::string line;
  int line_number = 0;
  while (std::getline(stream, line)) {
    ++line_number;
    if (const size_t hash = line.find('#'); hash != std::string::npos) line.erase(hash);
    std::istringstream tokens(line);
    std::string keyword;
    if (!(tokens >> keyword)) continue;
    const std::string key = Lower(keyword);
    const std::string field = "line " + std::to_string(line_number);

    // The values after the keyword, all numbers, exactly `count` of them.
    auto numbers = [&](int count, const std::string& description) {
      std::vector<double> values;
      std::string token;
      bool numeric = true;
      while (tokens >> token) {
        double value = 0.0;
        if (!ParseDecimal(token, &value)) numeric = false;
        values.push_back(value);
      }
      if (!numeric || static_cast<int>(values.size()) != count) {
        throw InputError(conf, field,
                         keyword + ": expected " + std::to_string(count) + " numbers (" +
                             description + "), got '" + line + "'");
      }
      return values;
    };
    auto block = [&]() -> CameraBlock& {
      if (!in_block) throw InputError(conf, field, keyword + " outside BeginCamera ... EndCamera");
      return blocks.back();
    };
    auto once = [&](bool already_set) {
      if (already_set) throw InputError(conf, field, keyword + " given twice in the camera block");
    };

    if (key == "resolution") {
      const std::vector<double> values = numbers(2, "width height");
      for (const double size : values) {
        if (!(size >= 1 && size <= kMaxImportedImageSide) || size != std::floor(size)) {
          throw InputError(conf, field,
                           "Resolution: expected two positive integers up to " +
                               std::to_string(kMaxImportedImageSide));
        }
      }
      resolution = Eigen::Vector2i(static_cast<int>(values[0]), static_cast<int>(values[1]));
    } else if (key == "begincamera") {
      if (in_block) throw InputError(conf, field, "BeginCamera inside a camera block");
      numbers(0, "none");
      blocks.push_back(CameraBlock{});
      blocks.back().begin_line = line_number;
      in_block = true;
    } else if (key == "endcamera") {
      block();
      numbers(0, "none");
      in_block = false;
    } else if (key == "focallength") {
      CameraBlock& current = block();
      once(current.focal.has_value());
      const std::vector<double> values = numbers(2, "fu fv");
      current.focal = Eigen::Vector2d(values[0], values[1]);
    } else if (key == "camtoladybugeulerzyx") {
      CameraBlock& current = block();
      once(current.euler_zyx_and_centre.has_value());
      const std::vector<double> values = numbers(6, "rx ry rz tx ty tz");
      current.euler_zyx_and_centre = Eigen::Map<const Eigen::Matrix<double, 6, 1>>(values.data());
    } else if (key == "center") {
      CameraBlock& current = block();
      once(current.principal.has_value());
      const std::vector<double> values = numbers(5, "X Y Z U V");
      current.principal = Eigen::Vector2d(values[3], values[4]);
    }
    // Other lines (serial numbers, distortion maps of the raw images, ...) are not needed for
    // rectified pinhole images.
  }
  if (in_block) {
    throw InputError(conf, "line " + std::to_string(blocks.back().begin_line),
                     "BeginCamera without EndCamera");
  }
  if (!resolution) throw InputError(conf, "Resolution", "missing (expected 'Resolution W H')");
  if (blocks.empty()) throw InputError(conf, "BeginCamera", "missing: no camera block");

  const int width = resolution->x();
  const int height = resolution->y();
  Rig rig;
  rig.name = conf.stem().string();
  // The Ladybug head is built to be nearly central (centres a few centimetres from its axis),
  // which the paper's central approximation relies on.
  rig.central = true;
  for (size_t index = 0; index < blocks.size(); ++index) {
    const CameraBlock& block = blocks[index];
    const std::string field = "camera block at line " + std::to_string(block.begin_line);
    if (!block.focal) throw InputError(conf, field, "missing focalLength");
    if (!block.euler_zyx_and_centre) throw InputError(conf, field, "missing CamToLadybugEulerZYX");
    if (!block.principal) throw InputError(conf, field, "missing Center");

    Camera camera;
    camera.name = "cam" + std::to_string(index);
    camera.model = CameraModel::kPinhole;
    camera.width = width;
    camera.height = height;
    const double fx = block.focal->x() * width;
    const double fy = block.focal->y() * height;
    const double cx = block.principal->x() * width - 0.5;
    const double cy = block.principal->y() * height - 0.5;
    camera.cam_from_rig = HeadFromCam(*block.euler_zyx_and_centre).Inverse();
    if (!options.upright) {
      camera.params = {fx, fy, cx, cy};
    } else {
      // Upright pixel (u', v') = (H - 1 - v, u). With the upright camera frame x' = -y, y' = x,
      // z' = z (a rotation by +90 degrees about z), u' = fy x'/z' + (H - 1 - cy) and
      // v' = fx y'/z' + cx.
      camera.width = height;
      camera.height = width;
      camera.params = {fy, fx, height - 1 - cy, cx};
      const Rigid3d upright_from_cam(
          Eigen::Quaterniond(Eigen::AngleAxisd(M_PI / 2.0, Eigen::Vector3d::UnitZ())),
          Eigen::Vector3d::Zero());
      camera.cam_from_rig = upright_from_cam * camera.cam_from_rig;
    }
    if (const std::string problem = camera.Check(); !problem.empty()) {
      throw InputError(conf, field, problem);
    }
    rig.cameras.push_back(camera);
  }
  // The checks of rig.json, ranges included: what is imported reads back.
  return ParseRigJson(RigToJson(rig), conf);
}

}  // namespace omni
