#include "calib/colmap_text.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>
#include <unordered_map>
#include <unordered_set>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/input_file.h"
#include "calib/number_text.h"

namespace omni {
namespace {

// A quaternion of images.txt within this of unit norm is normalised; others are rejected.
constexpr double kQuaternionNormTolerance = 1e-3;
// COLMAP's identifiers are unsigned 32-bit.
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
  uint32_t Id(size_t index, const char* name) const {
    return static_cast<uint32_t>(Integer(index, name, 0, kMaxColmapId));
  }
  // X Y Z R G B from `index` on (points3D.txt, frame_rays.txt).
  void PointAndColour(size_t index, Eigen::Vector3d* xyz, Rgb8* color) const {
    *xyz = Eigen::Vector3d(Number(index, "X"), Number(index + 1, "Y"), Number(index + 2, "Z"));
    *color = Rgb8(static_cast<uint8_t>(Integer(index + 3, "R", 0, 255)),
                  static_cast<uint8_t>(Integer(index + 4, "G", 0, 255)),
                  static_cast<uint8_t>(Integer(index + 5, "B", 0, 255)));
  }

 private:
  const std::filesystem::path& path_;
  const DataLine& line_;
};

}  // namespace

ColmapModel ParseColmapModel(const ColmapTextModel& text, const std::filesystem::path& model) {
  ColmapModel result;
  // Cameras: CAMERA_ID MODEL WIDTH HEIGHT PARAMS[].
  const std::filesystem::path cameras_path = model / "cameras.txt";
  std::unordered_set<uint32_t> camera_ids;
  for (const DataLine& line : DataLines(text.cameras, false)) {
    const LineReader in(cameras_path, line);
    if (line.tokens.size() < 5) in.Fail("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]");
    ColmapCamera camera;
    camera.id = in.Id(0, "CAMERA_ID");
    camera.model = in.Token(1);
    camera.width = static_cast<int>(in.Integer(2, "WIDTH", 1, 1 << 16));
    camera.height = static_cast<int>(in.Integer(3, "HEIGHT", 1, 1 << 16));
    for (size_t k = 4; k < line.tokens.size(); ++k) camera.params.push_back(in.Number(k, "PARAMS"));
    if (!camera_ids.insert(camera.id).second) in.Fail("repeated CAMERA_ID " + in.Token(0));
    result.cameras.push_back(std::move(camera));
  }

  // Images: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then a line of 2D points
  // (X Y POINT3D_ID, POINT3D_ID -1 when the point has no 3D point).
  const std::filesystem::path images_path = model / "images.txt";
  const std::vector<DataLine> image_lines = DataLines(text.images, true);
  std::unordered_set<uint32_t> image_ids;
  for (size_t i = 0; i < image_lines.size(); ++i) {
    const DataLine& line = image_lines[i];
    if (line.tokens.empty()) continue;
    const LineReader in(images_path, line);
    if (line.tokens.size() != 10) {
      in.Fail("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got " +
              std::to_string(line.tokens.size()) + " fields");
    }
    ColmapImage image;
    image.id = in.Id(0, "IMAGE_ID");
    const Eigen::Quaterniond cam_from_world_q(in.Number(1, "QW"), in.Number(2, "QX"),
                                              in.Number(3, "QY"), in.Number(4, "QZ"));
    if (!(std::abs(cam_from_world_q.norm() - 1.0) <= kQuaternionNormTolerance)) {
      std::ostringstream problem;
      problem << "QW QX QY QZ: expected a unit quaternion, norm is " << cam_from_world_q.norm();
      in.Fail(problem.str());
    }
    image.cam_from_world =
        Rigid3d(cam_from_world_q.normalized(),
                Eigen::Vector3d(in.Number(5, "TX"), in.Number(6, "TY"), in.Number(7, "TZ")));
    image.camera_id = in.Id(8, "CAMERA_ID");
    if (camera_ids.count(image.camera_id) == 0) {
      in.Fail("CAMERA_ID " + in.Token(8) + " is not in " + cameras_path.filename().string());
    }
    image.name = in.Token(9);
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
      ColmapPoint2D point;
      point.xy = Eigen::Vector2d(points_in.Number(k, "X"), points_in.Number(k + 1, "Y"));
      point.point3d_id =
          static_cast<int64_t>(points_in.Integer(k + 2, "POINT3D_ID", -1, kMaxColmapId));
      image.points2d.push_back(point);
    }
    if (!image_ids.insert(image.id).second) in.Fail("repeated IMAGE_ID " + in.Token(0));
    result.images.push_back(std::move(image));
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
    ColmapPoint3D point;
    point.id = in.Id(0, "POINT3D_ID");
    if (!point_ids.insert(point.id).second) in.Fail("repeated POINT3D_ID " + in.Token(0));
    in.PointAndColour(1, &point.xyz, &point.color);
    point.error = in.Number(7, "ERROR");
    for (size_t k = 8; k < line.tokens.size(); k += 2) {
      ColmapTrackElement element;
      element.image_id = in.Id(k, "IMAGE_ID");
      element.point2d_idx = in.Id(k + 1, "POINT2D_IDX");
      if (image_ids.count(element.image_id) == 0) in.Fail("unknown IMAGE_ID " + in.Token(k));
      point.track.push_back(element);
    }
    result.points.push_back(std::move(point));
  }

  // Frame rays: POINT3D_ID X Y Z R G B NUM_RAYS RAYS[] as (IMAGE_NAME CX CY CZ).
  const std::filesystem::path frame_rays_path = model / "frame_rays.txt";
  for (const DataLine& line : DataLines(text.frame_rays, false)) {
    const LineReader in(frame_rays_path, line);
    if (line.tokens.size() < 12 || (line.tokens.size() - 8) % 4 != 0) {
      in.Fail("expected POINT3D_ID X Y Z R G B NUM_RAYS RAYS[] (IMAGE_NAME CX CY CZ), got " +
              std::to_string(line.tokens.size()) + " fields");
    }
    ColmapFrameRayPoint point;
    point.point3d_id = in.Id(0, "POINT3D_ID");
    if (point.point3d_id != 0 && point_ids.count(point.point3d_id) == 0)
      in.Fail("POINT3D_ID " + in.Token(0) + " is not in " + points_path.filename().string());
    in.PointAndColour(1, &point.xyz, &point.color);
    const size_t num_rays = static_cast<size_t>(in.Integer(7, "NUM_RAYS", 1, kMaxColmapId));
    if (line.tokens.size() != 8 + 4 * num_rays)
      in.Fail("NUM_RAYS is " + in.Token(7) + " but the line holds " +
              std::to_string((line.tokens.size() - 8) / 4) + " rays");
    for (size_t k = 8; k < line.tokens.size(); k += 4) {
      point.rays.push_back(
          {in.Token(k), Eigen::Vector3d(in.Number(k + 1, "CX"), in.Number(k + 2, "CY"),
                                        in.Number(k + 3, "CZ"))});
    }
    result.frame_rays.push_back(std::move(point));
  }
  return result;
}

ColmapTextModel ReadColmapText(const std::filesystem::path& folder) {
  if (!std::filesystem::exists(folder / "cameras.txt")) {
    throw InputError(folder / "cameras.txt", "", "cannot open (a COLMAP text model is expected)");
  }
  ColmapTextModel text;
  text.cameras = ReadInputFile(folder / "cameras.txt");
  text.images = ReadInputFile(folder / "images.txt");
  text.points3d = ReadInputFile(folder / "points3D.txt");
  if (std::filesystem::exists(folder / "frame_rays.txt"))
    text.frame_rays = ReadInputFile(folder / "frame_rays.txt");
  return text;
}

double ColmapFinestPixelAngle(const ColmapModel& model) {
  double focal = 0.0;
  for (const ColmapCamera& camera : model.cameras) {
    if (!camera.params.empty()) focal = std::max(focal, camera.params[0]);
  }
  return focal > 0.0 ? 1.0 / focal : 0.0;
}

ColmapModel ReadColmapModel(const std::filesystem::path& folder) {
  return ParseColmapModel(ReadColmapText(folder), folder);
}

ColmapTextModel FormatColmapModel(const ColmapModel& model) {
  ColmapTextModel text;
  std::ostringstream cameras;
  cameras << std::setprecision(17);
  cameras << "# Camera list with one line of data per camera:\n"
          << "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
          << "# Number of cameras: " << model.cameras.size() << "\n";
  for (const ColmapCamera& camera : model.cameras) {
    cameras << camera.id << ' ' << camera.model << ' ' << camera.width << ' ' << camera.height;
    for (double p : camera.params) cameras << ' ' << p;
    cameras << '\n';
  }
  text.cameras = cameras.str();
  std::ostringstream images;
  images << std::setprecision(17);
  images << "# Image list with two lines of data per image:\n"
         << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
         << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
         << "# Number of images: " << model.images.size() << "\n";
  for (const ColmapImage& image : model.images) {
    const Eigen::Quaterniond& q = image.cam_from_world.rotation;
    const Eigen::Vector3d& t = image.cam_from_world.translation;
    images << image.id << ' ' << q.w() << ' ' << q.x() << ' ' << q.y() << ' ' << q.z() << ' '
           << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << image.camera_id << ' ' << image.name
           << '\n';
    std::ostringstream line;
    line << std::setprecision(10);
    for (size_t i = 0; i < image.points2d.size(); ++i)
      line << (i ? " " : "") << image.points2d[i].xy.x() << ' ' << image.points2d[i].xy.y() << ' '
           << image.points2d[i].point3d_id;
    images << line.str() << '\n';
  }
  text.images = images.str();
  std::ostringstream points;
  points << std::setprecision(10);
  points << "# 3D point list with one line of data per point:\n"
         << "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
         << "# Number of points: " << model.points.size() << "\n";
  for (const ColmapPoint3D& point : model.points) {
    points << point.id << ' ' << point.xyz.x() << ' ' << point.xyz.y() << ' ' << point.xyz.z()
           << ' ' << int{point.color[0]} << ' ' << int{point.color[1]} << ' ' << int{point.color[2]}
           << ' ' << point.error;
    for (const ColmapTrackElement& element : point.track)
      points << ' ' << element.image_id << ' ' << element.point2d_idx;
    points << '\n';
  }
  text.points3d = points.str();
  if (!model.frame_rays.empty()) text.frame_rays = FormatColmapFrameRays(model.frame_rays);
  return text;
}

std::string FormatColmapFrameRays(const std::vector<ColmapFrameRayPoint>& points) {
  std::ostringstream text;
  text << std::setprecision(10);
  text << "# Rays of the tracked frames between keyframes, one line per point with such rays:\n"
       << "#   POINT3D_ID, X, Y, Z, R, G, B, NUM_RAYS, RAYS[] as (IMAGE_NAME, CX, CY, CZ)\n"
       << "# POINT3D_ID 0: a frame point, not in points3D.txt. CX CY CZ: the ray's optical "
          "centre.\n"
       << "# Number of points: " << points.size() << "\n";
  for (const ColmapFrameRayPoint& point : points) {
    text << point.point3d_id << ' ' << point.xyz.x() << ' ' << point.xyz.y() << ' ' << point.xyz.z()
         << ' ' << int{point.color[0]} << ' ' << int{point.color[1]} << ' ' << int{point.color[2]}
         << ' ' << point.rays.size();
    for (const ColmapFrameRay& ray : point.rays)
      text << ' ' << ray.image_name << ' ' << ray.centre.x() << ' ' << ray.centre.y() << ' '
           << ray.centre.z();
    text << '\n';
  }
  return text.str();
}

void WriteColmapModel(const ColmapModel& model, const std::filesystem::path& folder) {
  std::filesystem::create_directories(folder);
  const ColmapTextModel text = FormatColmapModel(model);
  WriteTextFileAtomically(folder / "cameras.txt", text.cameras);
  WriteTextFileAtomically(folder / "images.txt", text.images);
  WriteTextFileAtomically(folder / "points3D.txt", text.points3d);
  // A frame_rays.txt of an earlier model would not match these points.
  if (!text.frame_rays.empty())
    WriteTextFileAtomically(folder / "frame_rays.txt", text.frame_rays);
  else
    std::filesystem::remove(folder / "frame_rays.txt");
}

}  // namespace omni
