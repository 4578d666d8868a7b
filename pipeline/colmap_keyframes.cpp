#include "pipeline/colmap_keyframes.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "calib/error.h"
#include "calib/input_file.h"
#include "calib/number_text.h"
#include "pipeline/world_up.h"

namespace omni {
namespace {

// A quaternion of images.txt within this of unit norm is normalised; others are rejected.
constexpr double kQuaternionNormTolerance = 1e-3;
// COLMAP's identifiers are unsigned 32-bit; a point id is also a PointId.
constexpr double kMaxColmapId = std::numeric_limits<uint32_t>::max();

struct DataLine {
  int number = 0;
  std::vector<std::string> tokens;
};

// The non-comment lines of a COLMAP text file, with their line numbers, split into tokens.
// images.txt keeps its empty lines: an image's second line (its 2D points) may be empty.
std::vector<DataLine> DataLines(const std::string& text, bool keep_empty) {
  std::vector<DataLine> lines;
  std::istringstream stream(text);
  std::string line;
  int number = 0;
  while (std::getline(stream, line)) {
    ++number;
    const size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) {
      if (keep_empty) lines.push_back({number, {}});
      continue;
    }
    if (line[first] == '#') continue;
    DataLine data{number, {}};
    std::istringstream words(line);
    for (std::string word; words >> word;) data.tokens.push_back(word);
    lines.push_back(std::move(data));
  }
  return lines;
}

// Reads the tokens of one line, each error naming the file, the line and the field.
class LineReader {
 public:
  LineReader(const std::filesystem::path& path, const DataLine& line) : path_(path), line_(line) {}

  [[noreturn]] void Fail(const std::string& problem) const {
    throw InputError(path_, "line " + std::to_string(line_.number), problem);
  }
  const std::string& Token(size_t index) const { return line_.tokens.at(index); }

  double Number(size_t index, const char* name) const {
    double value = 0.0;
    if (!ParseDecimal(Token(index), &value))
      Fail(std::string(name) + ": " + DecimalProblem(Token(index)));
    return value;
  }
  // An integer in [low, high].
  double Integer(size_t index, const char* name, double low, double high) const {
    double value = 0.0;
    if (!IsDecimalInteger(Token(index)) || !ParseDecimal(Token(index), &value) || value < low ||
        value > high) {
      std::ostringstream problem;
      problem << std::fixed << std::setprecision(0) << name << ": expected an integer in [" << low
              << ", " << high << "], got \"" << Token(index).substr(0, 40) << "\"";
      Fail(problem.str());
    }
    return value;
  }

 private:
  const std::filesystem::path& path_;
  const DataLine& line_;
};

struct Image {
  Eigen::Vector3d centre;
  Eigen::Vector3d up;  // the image's up axis (−y of the camera) in the world
  std::string frame;   // the file name without its folder
};

}  // namespace

std::vector<SurfaceKeyframe> LoadColmapKeyframes(const std::filesystem::path& model,
                                                 std::unordered_map<PointId, Rgb8>* point_colors,
                                                 Eigen::Vector3d* world_up) {
  if (!std::filesystem::exists(model / "cameras.txt")) {
    throw InputError(model / "cameras.txt", "", "cannot open (a COLMAP text model is expected)");
  }
  ColmapTextModel text;
  text.cameras = ReadInputFile(model / "cameras.txt");
  text.images = ReadInputFile(model / "images.txt");
  text.points3d = ReadInputFile(model / "points3D.txt");
  return ParseColmapKeyframes(text, model, point_colors, world_up);
}

std::vector<SurfaceKeyframe> ParseColmapKeyframes(const ColmapTextModel& text,
                                                  const std::filesystem::path& model,
                                                  std::unordered_map<PointId, Rgb8>* point_colors,
                                                  Eigen::Vector3d* world_up) {
  // Cameras: CAMERA_ID MODEL WIDTH HEIGHT PARAMS[].
  const std::filesystem::path cameras_path = model / "cameras.txt";
  std::unordered_set<uint32_t> camera_ids;
  for (const DataLine& line : DataLines(text.cameras, false)) {
    const LineReader in(cameras_path, line);
    if (line.tokens.size() < 5) in.Fail("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    const auto id = static_cast<uint32_t>(in.Integer(0, "CAMERA_ID", 0, kMaxColmapId));
    in.Integer(2, "WIDTH", 1, 1 << 16);
    in.Integer(3, "HEIGHT", 1, 1 << 16);
    for (size_t k = 4; k < line.tokens.size(); ++k) in.Number(k, "PARAMS");
    if (!camera_ids.insert(id).second) in.Fail("repeated CAMERA_ID " + in.Token(0));
  }

  // Images: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a line of 2D points
  // (X Y POINT3D_ID, POINT3D_ID -1 when the point has no 3D point).
  const std::filesystem::path images_path = model / "images.txt";
  const std::vector<DataLine> image_lines = DataLines(text.images, true);
  std::unordered_map<long, Image> images;
  std::map<std::string, std::vector<long>> frames;  // frame name -> image ids
  for (size_t i = 0; i < image_lines.size(); ++i) {
    const DataLine& line = image_lines[i];
    if (line.tokens.empty()) continue;
    const LineReader in(images_path, line);
    if (line.tokens.size() != 10) {
      in.Fail("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got " +
              std::to_string(line.tokens.size()) + " fields");
    }
    const long id = static_cast<long>(in.Integer(0, "IMAGE_ID", 0, kMaxColmapId));
    const Eigen::Quaterniond cam_from_world_q(in.Number(1, "QW"), in.Number(2, "QX"),
                                              in.Number(3, "QY"), in.Number(4, "QZ"));
    if (!(std::abs(cam_from_world_q.norm() - 1.0) <= kQuaternionNormTolerance)) {
      std::ostringstream problem;
      problem << "QW QX QY QZ: expected a unit quaternion, norm is " << cam_from_world_q.norm();
      in.Fail(problem.str());
    }
    const Eigen::Vector3d translation(in.Number(5, "TX"), in.Number(6, "TY"), in.Number(7, "TZ"));
    const auto camera_id = static_cast<uint32_t>(in.Integer(8, "CAMERA_ID", 0, kMaxColmapId));
    if (camera_ids.count(camera_id) == 0) {
      in.Fail("CAMERA_ID " + in.Token(8) + " is not in " + cameras_path.filename().string());
    }
    // The 2D points line (it may be empty, and is then kept as an empty line; the last one may
    // be missing altogether at the end of the file).
    static const DataLine kNoPoints;
    const DataLine& points_line = i + 1 < image_lines.size() ? image_lines[++i] : kNoPoints;
    const LineReader points_in(images_path, points_line);
    if (points_line.tokens.size() % 3 != 0) {
      points_in.Fail("expected 2D points as X Y POINT3D_ID triples, got " +
                     std::to_string(points_line.tokens.size()) + " values");
    }
    for (size_t k = 0; k < points_line.tokens.size(); k += 3) {
      points_in.Number(k, "X");
      points_in.Number(k + 1, "Y");
      points_in.Integer(k + 2, "POINT3D_ID", -1, kMaxColmapId);
    }
    const Eigen::Matrix3d r = cam_from_world_q.normalized().toRotationMatrix();
    Image image;
    image.centre = -r.transpose() * translation;
    image.up = -r.row(1).transpose();
    image.frame = std::filesystem::path(in.Token(9)).filename().string();
    if (!images.emplace(id, image).second) in.Fail("repeated IMAGE_ID " + in.Token(0));
    frames[image.frame].push_back(id);
  }
  if (world_up) {
    std::vector<Eigen::Vector3d> centres, ups;
    for (const auto& [id, image] : images) {
      centres.push_back(image.centre);
      ups.push_back(image.up);
    }
    *world_up = EstimateWorldUp(centres, ups);
  }
  // Keyframes by frame name; the centre is the mean of the camera centres.
  std::vector<SurfaceKeyframe> keyframes;
  std::unordered_map<long, size_t> keyframe_of;  // image id -> keyframe index
  for (const auto& [frame, ids] : frames) {
    SurfaceKeyframe kf;
    kf.id = KeyframeId(static_cast<uint32_t>(keyframes.size()));
    for (long id : ids) {
      kf.centre += images.at(id).centre;
      keyframe_of[id] = keyframes.size();
    }
    kf.centre /= static_cast<double>(ids.size());
    keyframes.push_back(kf);
  }
  // Points: POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX).
  const std::filesystem::path points_path = model / "points3D.txt";
  std::unordered_set<uint32_t> point_ids;
  for (const DataLine& line : DataLines(text.points3d, false)) {
    const LineReader in(points_path, line);
    if (line.tokens.size() < 8 || (line.tokens.size() - 8) % 2 != 0) {
      in.Fail("expected POINT3D_ID X Y Z R G B ERROR TRACK[] (IMAGE_ID POINT2D_IDX pairs), got " +
              std::to_string(line.tokens.size()) + " fields");
    }
    const auto id = static_cast<uint32_t>(in.Integer(0, "POINT3D_ID", 0, kMaxColmapId));
    if (!point_ids.insert(id).second) in.Fail("repeated POINT3D_ID " + in.Token(0));
    SurfacePoint point;
    point.id = PointId(id);
    point.position = Eigen::Vector3d(in.Number(1, "X"), in.Number(2, "Y"), in.Number(3, "Z"));
    const Rgb8 color(static_cast<uint8_t>(in.Integer(4, "R", 0, 255)),
                     static_cast<uint8_t>(in.Integer(5, "G", 0, 255)),
                     static_cast<uint8_t>(in.Integer(6, "B", 0, 255)));
    in.Number(7, "ERROR");
    if (point_colors) (*point_colors)[point.id] = color;
    size_t latest = 0;
    for (size_t k = 8; k < line.tokens.size(); k += 2) {
      const auto image_id = static_cast<long>(in.Integer(k, "IMAGE_ID", 0, kMaxColmapId));
      // POINT2D_IDX is not matched against the image's 2D points: the surface needs only the
      // image (models written by other tools often leave the 2D points out).
      in.Integer(k + 1, "POINT2D_IDX", 0, kMaxColmapId);
      const auto it = images.find(image_id);
      if (it == images.end()) in.Fail("unknown IMAGE_ID " + in.Token(k));
      const size_t kf = keyframe_of.at(image_id);
      latest = std::max(latest, kf);
      point.rays.push_back({keyframes[kf].id, it->second.centre});
    }
    if (point.rays.empty()) continue;  // no observation: no ray
    keyframes[latest].points.push_back(std::move(point));
  }
  return keyframes;
}

}  // namespace omni
