#include "export/viewer_bundle.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>
#include <unordered_map>
#include <vector>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "calib/tum.h"
#include "export/gltf.h"

namespace omni {
namespace {

namespace fs = std::filesystem;

constexpr const char* kSceneFile = "scene.js";
constexpr double kDefaultFrameRate = 15.0;  // poses.tum's stamps: frame index / 15 s
constexpr double kMaxFovDeg = 120.0;        // a fisheye's view is shown as a wide pinhole

std::string Base64(const std::string& bytes) {
  static const char* const kAlphabet =
      "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  size_t i = 0;
  for (; i + 2 < bytes.size(); i += 3) {
    const uint32_t v = (static_cast<uint8_t>(bytes[i]) << 16) |
                       (static_cast<uint8_t>(bytes[i + 1]) << 8) |
                       static_cast<uint8_t>(bytes[i + 2]);
    for (int k = 3; k >= 0; --k) out.push_back(kAlphabet[(v >> (6 * k)) & 63]);
  }
  if (i < bytes.size()) {
    const bool two = i + 1 < bytes.size();
    const uint32_t v = (static_cast<uint8_t>(bytes[i]) << 16) |
                       (two ? static_cast<uint8_t>(bytes[i + 1]) << 8 : 0);
    out.push_back(kAlphabet[(v >> 18) & 63]);
    out.push_back(kAlphabet[(v >> 12) & 63]);
    out.push_back(two ? kAlphabet[(v >> 6) & 63] : '=');
    out.push_back('=');
  }
  return out;
}

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", "cannot be read");
  std::ostringstream text;
  text << in.rdbuf();
  return text.str();
}

// A data file: a classic script that stores `value` (JSON) as window.OMNI_DATA[key].
void WriteDataScript(const fs::path& path, const std::string& key, const std::string& value,
                     size_t* bytes) {
  const std::string text = "window.OMNI_DATA = window.OMNI_DATA || {};\nwindow.OMNI_DATA[" +
                           nlohmann::json(key).dump() + "] = " + value + ";\n";
  WriteTextFileAtomically(path, text);
  *bytes += text.size();
}

// ---- The COLMAP text model of sparse/ ------------------------------------------------------

struct ColmapImage {
  int camera = -1;
  std::string camera_name;  // the image's folder: "cam0" of "images/cam0/000123.png"
  std::string frame_name;   // "000123"
  Rigid3d cam_from_world;
};

struct ColmapModel {
  std::map<int, double> fov_y_deg, aspect;  // per camera id
  std::map<int, ColmapImage> images;        // by image id
  std::vector<std::string> frame_names;     // distinct, in the order of images.txt
  std::vector<Eigen::Vector3d> points;
  std::vector<Rgb8> colors;
  std::vector<int> point_first_image;  // the smallest image id of each point's track
};

// The data lines of a COLMAP text file (comments dropped; empty lines kept: an image's list
// of 2-D points may be empty).
std::vector<std::string> DataLines(const fs::path& path) {
  std::istringstream in(ReadText(path));
  std::vector<std::string> lines;
  std::string line;
  while (std::getline(in, line)) {
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!line.empty() && line[0] == '#') continue;
    lines.push_back(line);
  }
  while (!lines.empty() && lines.back().empty()) lines.pop_back();
  return lines;
}

ColmapModel ReadColmapModel(const fs::path& sparse) {
  ColmapModel model;
  const fs::path cameras = sparse / "cameras.txt";
  size_t line_number = 0;
  for (const std::string& line : DataLines(cameras)) {
    ++line_number;
    if (line.empty()) continue;
    std::istringstream fields(line);
    int id = 0, width = 0, height = 0;
    std::string name;
    double fx = 0, fy = 0;
    if (!(fields >> id >> name >> width >> height >> fx) || width <= 0 || height <= 0 || fx <= 0)
      throw InputError(cameras, "camera " + std::to_string(line_number),
                       "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS");
    // SIMPLE_* models have one focal length, the others fx fy.
    if (name.rfind("SIMPLE_", 0) == 0 || !(fields >> fy) || fy <= 0) fy = fx;
    double fov = 2.0 * std::atan(0.5 * height / fy) * 180.0 / M_PI;
    if (name.find("FISHEYE") != std::string::npos) fov = kMaxFovDeg;
    model.fov_y_deg[id] = std::min(fov, kMaxFovDeg);
    model.aspect[id] = static_cast<double>(width) / height;
  }
  const fs::path images = sparse / "images.txt";
  const std::vector<std::string> lines = DataLines(images);
  std::unordered_map<std::string, size_t> frame_index;
  for (size_t i = 0; i < lines.size(); i += 2) {
    std::istringstream fields(lines[i]);
    int id = 0;
    double qw, qx, qy, qz, tx, ty, tz;
    ColmapImage image;
    std::string name;
    if (!(fields >> id >> qw >> qx >> qy >> qz >> tx >> ty >> tz >> image.camera >> name))
      throw InputError(images, "line " + std::to_string(i + 1),
                       "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    image.cam_from_world =
        Rigid3d(Eigen::Quaterniond(qw, qx, qy, qz).normalized(), Eigen::Vector3d(tx, ty, tz));
    const fs::path image_path(name);
    image.frame_name = image_path.stem().string();
    image.camera_name = image_path.parent_path().filename().string();
    if (frame_index.emplace(image.frame_name, model.frame_names.size()).second)
      model.frame_names.push_back(image.frame_name);
    model.images[id] = image;
  }
  const fs::path points = sparse / "points3D.txt";
  line_number = 0;
  for (const std::string& line : DataLines(points)) {
    ++line_number;
    if (line.empty()) continue;
    std::istringstream fields(line);
    long id;
    double x, y, z, error;
    int r, g, b;
    if (!(fields >> id >> x >> y >> z >> r >> g >> b >> error))
      throw InputError(points, "point " + std::to_string(line_number),
                       "expected POINT3D_ID X Y Z R G B ERROR TRACK[]");
    int first = -1, image, index;
    while (fields >> image >> index) first = first < 0 ? image : std::min(first, image);
    model.points.emplace_back(x, y, z);
    model.colors.emplace_back(static_cast<uint8_t>(std::clamp(r, 0, 255)),
                              static_cast<uint8_t>(std::clamp(g, 0, 255)),
                              static_cast<uint8_t>(std::clamp(b, 0, 255)));
    model.point_first_image.push_back(first);
  }
  return model;
}

// three.js cameras look along -z with y up; COLMAP's along +z with y down.
Rigid3d ThreeWorldFromCamera(const Rigid3d& colmap_cam_from_world) {
  const Rigid3d world_from_cam = colmap_cam_from_world.Inverse();
  const Eigen::Quaterniond flip(0.0, 1.0, 0.0, 0.0);  // 180 degrees about x
  return Rigid3d(world_from_cam.rotation * flip, world_from_cam.translation);
}

nlohmann::json PoseJson(const Rigid3d& pose) {
  const Eigen::Quaterniond& q = pose.rotation;
  const Eigen::Vector3d& t = pose.translation;
  return {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()};
}

// ---- Colours of snapshot meshes ------------------------------------------------------------

class PointGrid {
 public:
  PointGrid(const std::vector<Eigen::Vector3d>& points, double cell)
      : points_(points), cell_(cell) {
    for (size_t i = 0; i < points.size(); ++i) cells_[Key(Cell(points[i]))].push_back(i);
  }
  // The nearest point within `cell` of p, or -1.
  long Nearest(const Eigen::Vector3d& p) const {
    const Eigen::Vector3i c = Cell(p);
    long best = -1;
    double best_d2 = cell_ * cell_;
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          auto it = cells_.find(Key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (size_t i : it->second) {
            const double d2 = (points_[i] - p).squaredNorm();
            if (d2 <= best_d2) best_d2 = d2, best = static_cast<long>(i);
          }
        }
    return best;
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return (p / cell_).array().floor().cast<int>();
  }
  static uint64_t Key(const Eigen::Vector3i& c) {
    return (static_cast<uint64_t>(c.x() & 0x1FFFFF) << 42) |
           (static_cast<uint64_t>(c.y() & 0x1FFFFF) << 21) |
           static_cast<uint64_t>(c.z() & 0x1FFFFF);
  }
  const std::vector<Eigen::Vector3d>& points_;
  double cell_;
  std::unordered_map<uint64_t, std::vector<size_t>> cells_;
};

// A snapshot mesh with each vertex coloured as the nearest SfM point within the grid's radius
// (grey without one: a Steiner vertex, or a point that moved since), its own colours kept when
// it has them. With without_unmatched, the triangles with a vertex without a point are left out
// (the closed δO of an old reconstruction folder, without its observed part, then looks like
// the observed surface it grows into), and the vertices they alone used.
TriangleMesh ColoredByNearestPoint(const TriangleMesh& snapshot, const PointGrid& grid,
                                   const std::vector<Rgb8>& point_colors, bool without_unmatched) {
  std::vector<long> nearest(snapshot.vertices.size(), -1);
  for (size_t i = 0; i < snapshot.vertices.size(); ++i)
    nearest[i] = grid.Nearest(snapshot.vertices[i]);
  TriangleMesh mesh;
  std::vector<int> new_index(snapshot.vertices.size(), -1);
  for (const Eigen::Vector3i& t : snapshot.triangles) {
    if (without_unmatched && (nearest[t[0]] < 0 || nearest[t[1]] < 0 || nearest[t[2]] < 0))
      continue;
    Eigen::Vector3i kept;
    for (int k = 0; k < 3; ++k) {
      if (new_index[t[k]] < 0) {
        new_index[t[k]] = static_cast<int>(mesh.vertices.size());
        mesh.vertices.push_back(snapshot.vertices[t[k]]);
        mesh.colors.push_back(!snapshot.colors.empty() ? snapshot.colors[t[k]]
                              : nearest[t[k]] >= 0 && !point_colors.empty()
                                  ? point_colors[nearest[t[k]]]
                                  : Rgb8(128, 128, 128));
      }
      kept[k] = new_index[t[k]];
    }
    mesh.triangles.push_back(kept);
  }
  return mesh;
}

bool IsOurViewer(const fs::path& folder) { return fs::exists(folder / "data" / kSceneFile); }

}  // namespace

std::string ViewerOptions::Check() const {
  if (assets.empty()) return "assets: the folder of the page and of three.js must be given";
  if (!(snapshot_color_radius > 0.0)) return "snapshot_color_radius: must be > 0";
  return {};
}

ViewerSummary WriteViewer(const fs::path& reconstruction, const ViewerOptions& options) {
  ThrowIfInvalid(options.Check(), "ViewerOptions");
  for (const char* asset : {"index.html", "viewer.js", "viewer.css", "lib/three.min.js",
                            "lib/GLTFLoader.js", "lib/OrbitControls.js"})
    if (!fs::exists(options.assets / asset))
      throw InputError(options.assets / asset, "",
                       "viewer asset missing (the build copies the page and the npm package "
                       "three into viewer_assets/: run scripts/setup.sh)");
  if (!fs::is_directory(reconstruction))
    throw InputError(reconstruction, "", "is not a reconstruction folder");
  const fs::path out = reconstruction / "viewer";
  if (fs::exists(out) && !IsOurViewer(out))
    throw InputError(out, "", "exists and is not a viewer written by omnisculpt; move it away");

  // The inputs, read before anything is written.
  const TriangleMesh surface = ReadPlyMesh(reconstruction / "surface.ply");
  const std::vector<StampedPose> poses = ReadTum(reconstruction / "poses.tum");
  if (poses.empty()) throw InputError(reconstruction / "poses.tum", "", "holds no pose");
  nlohmann::json summary_json = nlohmann::json::object();
  if (fs::exists(reconstruction / "reconstruct.json")) {
    try {
      summary_json = nlohmann::json::parse(ReadText(reconstruction / "reconstruct.json"));
    } catch (const nlohmann::json::exception& e) {
      throw InputError(reconstruction / "reconstruct.json", "", e.what());
    }
  }
  ColmapModel model;
  const bool has_model = fs::exists(reconstruction / "sparse" / "images.txt");
  if (has_model) model = ReadColmapModel(reconstruction / "sparse");
  // The rig cameras' poses per keyframe, when images.txt has one frame per keyframe.
  const bool has_cameras = has_model && model.frame_names.size() == poses.size();

  ViewerSummary summary;
  summary.keyframes = poses.size();
  summary.triangles = surface.triangles.size();
  summary.index = out / "index.html";

  // The points, ordered by the first keyframe that observed them.
  PointCloud points;
  std::vector<size_t> points_until(poses.size(), 0);  // points of keyframes <= k
  if (has_model && !model.points.empty()) {
    std::unordered_map<int, size_t> keyframe_of_image;
    std::unordered_map<std::string, size_t> frame_index;
    for (size_t k = 0; k < model.frame_names.size(); ++k) frame_index[model.frame_names[k]] = k;
    for (const auto& [id, image] : model.images)
      keyframe_of_image[id] = frame_index[image.frame_name];
    std::vector<std::pair<size_t, size_t>> order;  // (keyframe, point)
    for (size_t i = 0; i < model.points.size(); ++i) {
      auto it = keyframe_of_image.find(model.point_first_image[i]);
      order.emplace_back(it == keyframe_of_image.end() ? 0 : it->second, i);
    }
    std::stable_sort(order.begin(), order.end());
    for (const auto& [keyframe, i] : order) {
      points.points.push_back(model.points[i]);
      points.colors.push_back(model.colors[i]);
      if (keyframe < points_until.size()) ++points_until[keyframe];
    }
  } else if (fs::exists(reconstruction / "points.ply")) {
    points = ReadPlyPoints(reconstruction / "points.ply");
    points_until.assign(poses.size(), 0);
    points_until[0] = points.points.size();
  }
  for (size_t k = 1; k < points_until.size(); ++k) points_until[k] += points_until[k - 1];
  summary.points = points.points.size();

  // Snapshots, in keyframe order: per keyframe, its observed surface (observed_<keyframe>.ply)
  // and the closed δO (surface_<keyframe>.ply), either of them possibly missing.
  struct SnapshotFiles {
    fs::path observed, closed;
  };
  std::map<long, SnapshotFiles> snapshot_files;
  if (fs::is_directory(reconstruction / "snapshots")) {
    for (const auto& entry : fs::directory_iterator(reconstruction / "snapshots")) {
      if (entry.path().extension() != ".ply") continue;
      const std::string stem = entry.path().stem().string();
      for (const std::string prefix : {"observed_", "surface_"}) {
        if (stem.rfind(prefix, 0) != 0) continue;
        const std::string number = stem.substr(prefix.size());
        if (number.empty() || number.find_first_not_of("0123456789") != std::string::npos) continue;
        SnapshotFiles& files = snapshot_files[std::stol(number)];
        (prefix == "observed_" ? files.observed : files.closed) = entry.path();
      }
    }
  }

  fs::path partial = reconstruction / "viewer.incomplete";
  fs::remove_all(partial);
  fs::create_directories(partial / "data");
  fs::create_directories(partial / "lib");
  for (const char* asset : {"index.html", "viewer.js", "viewer.css"})
    fs::copy_file(options.assets / asset, partial / asset);
  for (const auto& entry : fs::directory_iterator(options.assets / "lib"))
    fs::copy_file(entry.path(), partial / "lib" / entry.path().filename());

  nlohmann::json scene;
  scene["format"] = 1;
  scene["title"] = fs::absolute(reconstruction).lexically_normal().filename().string();
  if (scene["title"] == "")
    scene["title"] = fs::absolute(reconstruction).parent_path().filename().string();
  scene["up"] = {0, 0, 1};
  nlohmann::json keyframes = nlohmann::json::array();
  for (size_t k = 0; k < poses.size(); ++k) {
    long frame = std::lround(poses[k].timestamp * kDefaultFrameRate);
    if (has_cameras) {
      const std::string& name = model.frame_names[k];
      if (!name.empty() && name.find_first_not_of("0123456789") == std::string::npos)
        frame = std::stol(name);
    }
    keyframes.push_back({{"keyframe", k},
                         {"frame", frame},
                         {"time", poses[k].timestamp},
                         {"pose", PoseJson(poses[k].world_from_rig)},
                         {"points", points_until[k]}});
  }
  scene["keyframes"] = keyframes;
  nlohmann::json cameras = nlohmann::json::array();
  if (has_cameras) {
    std::map<std::string, int> camera_ids;  // by folder name, sorted: cam0, cam1, ...
    for (const auto& [id, image] : model.images) camera_ids[image.camera_name] = image.camera;
    std::unordered_map<std::string, size_t> frame_index;
    for (size_t k = 0; k < model.frame_names.size(); ++k) frame_index[model.frame_names[k]] = k;
    for (const auto& [name, camera_id] : camera_ids) {
      nlohmann::json views(poses.size(), nullptr);  // null: the camera has no image there
      for (const auto& [id, image] : model.images)
        if (image.camera_name == name)
          views[frame_index[image.frame_name]] =
              PoseJson(ThreeWorldFromCamera(image.cam_from_world));
      cameras.push_back(
          {{"name", name},
           {"fov_y_deg", model.fov_y_deg.count(camera_id) ? model.fov_y_deg[camera_id] : 60.0},
           {"aspect", model.aspect.count(camera_id) ? model.aspect[camera_id] : 1.0},
           {"poses", views}});
    }
  }
  scene["cameras"] = cameras;
  summary.cameras = cameras.size();
  scene["loop_closures"] = summary_json.value("loop_closures", nlohmann::json::array());
  summary.loops = scene["loop_closures"].size();
  nlohmann::json run = nlohmann::json::object();
  for (const char* key : {"status", "outcome", "frames", "keyframes", "points", "triangles",
                          "closed_triangles", "seconds", "frames_per_second", "mode"})
    if (summary_json.contains(key)) run[key] = summary_json[key];
  scene["run"] = run;
  const fs::path keyframes_csv = reconstruction / "stats" / "keyframes.csv";
  scene["keyframes_csv"] = fs::exists(keyframes_csv) ? ReadText(keyframes_csv) : "";

  WriteDataScript(partial / "data" / "surface.js", "surface",
                  nlohmann::json(Base64(EncodeGlb(surface, points))).dump(), &summary.bytes);
  scene["surface"] = {{"data", "surface"},
                      {"file", "data/surface.js"},
                      {"vertices", surface.vertices.size()},
                      {"triangles", surface.triangles.size()},
                      {"points", points.points.size()}};

  nlohmann::json snapshots = nlohmann::json::array();
  const PointGrid grid(points.points, options.snapshot_color_radius);
  for (const auto& [keyframe, files] : snapshot_files) {
    const bool observed = !files.observed.empty();
    const TriangleMesh read = ReadPlyMesh(observed ? files.observed : files.closed);
    const TriangleMesh mesh =
        observed && !read.colors.empty()
            ? read
            : ColoredByNearestPoint(read, grid, points.colors,
                                    !observed && options.snapshot_without_steiner);
    if (mesh.triangles.empty()) continue;
    const std::string key = "snapshot_" + std::to_string(keyframe);
    const std::string file_name = key + ".js";
    WriteDataScript(partial / "data" / file_name, key,
                    nlohmann::json(Base64(EncodeGlb(mesh, PointCloud()))).dump(), &summary.bytes);
    nlohmann::json snapshot = {{"keyframe", keyframe},
                               {"data", key},
                               {"file", "data/" + file_name},
                               {"observed", observed},
                               {"vertices", mesh.vertices.size()},
                               {"triangles", mesh.triangles.size()}};
    if (!observed) snapshot["closed_triangles"] = read.triangles.size();
    snapshots.push_back(snapshot);
  }
  scene["snapshots"] = snapshots;
  summary.snapshots = snapshots.size();
  const std::string scene_text = "window.OMNI_SCENE = " + scene.dump() + ";\n";
  WriteTextFileAtomically(partial / "data" / kSceneFile, scene_text);
  summary.bytes += scene_text.size();

  // Published whole: the previous viewer (ours, checked above) goes only now.
  if (fs::exists(out)) fs::remove_all(out);
  fs::rename(partial, out);
  return summary;
}

}  // namespace omni
