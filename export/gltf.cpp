#include "export/gltf.h"

#include <algorithm>
#include <cstring>
#include <iomanip>
#include <limits>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <vector>

#include "calib/atomic_file.h"

namespace omni {
namespace {

constexpr uint32_t kGlbMagic = 0x46546C67;   // "glTF"
constexpr uint32_t kChunkJson = 0x4E4F534A;  // "JSON"
constexpr uint32_t kChunkBin = 0x004E4942;   // "BIN\0"
constexpr int kFloat = 5126, kUnsignedByte = 5121, kUnsignedInt = 5125;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;
constexpr int kModePoints = 0, kModeTriangles = 4;

void CheckInput(const TriangleMesh& mesh, const PointCloud& points) {
  if (!mesh.colors.empty() && mesh.colors.size() != mesh.vertices.size())
    throw std::invalid_argument("mesh: " + std::to_string(mesh.colors.size()) + " colours for " +
                                std::to_string(mesh.vertices.size()) + " vertices");
  if (!points.colors.empty() && points.colors.size() != points.points.size())
    throw std::invalid_argument("points: " + std::to_string(points.colors.size()) +
                                " colours for " + std::to_string(points.points.size()) + " points");
  const int n = static_cast<int>(mesh.vertices.size());
  for (const Eigen::Vector3i& t : mesh.triangles)
    for (int k = 0; k < 3; ++k)
      if (t[k] < 0 || t[k] >= n)
        throw std::invalid_argument("mesh: triangle index " + std::to_string(t[k]) +
                                    " out of range (" + std::to_string(n) + " vertices)");
}

// The BIN chunk and the JSON's buffer views and accessors, built together.
class GlbBuilder {
 public:
  // Appends a 4-byte aligned buffer view; returns its index.
  int AddView(const void* data, size_t bytes, int target) {
    while (bin_.size() % 4 != 0) bin_.push_back('\0');
    const size_t offset = bin_.size();
    bin_.append(static_cast<const char*>(data), bytes);
    views_.push_back(
        {{"buffer", 0}, {"byteOffset", offset}, {"byteLength", bytes}, {"target", target}});
    return static_cast<int>(views_.size()) - 1;
  }

  int AddPositions(const std::vector<Eigen::Vector3d>& vertices) {
    std::vector<float> xyz;
    xyz.reserve(3 * vertices.size());
    float lo[3], hi[3];
    std::fill(lo, lo + 3, std::numeric_limits<float>::max());
    std::fill(hi, hi + 3, std::numeric_limits<float>::lowest());
    for (const Eigen::Vector3d& v : vertices) {
      for (int k = 0; k < 3; ++k) {
        const float f = static_cast<float>(v[k]);
        xyz.push_back(f);
        lo[k] = std::min(lo[k], f);
        hi[k] = std::max(hi[k], f);
      }
    }
    const int view = AddView(xyz.data(), xyz.size() * sizeof(float), kArrayBuffer);
    // min/max as the exact float values (a strict reader compares them with the data).
    return AddAccessor(view, kFloat, vertices.size(), "VEC3",
                       {{"min", {lo[0], lo[1], lo[2]}}, {"max", {hi[0], hi[1], hi[2]}}});
  }

  int AddColors(const std::vector<Rgb8>& colors) {
    std::vector<uint8_t> rgba;
    rgba.reserve(4 * colors.size());
    for (const Rgb8& c : colors) rgba.insert(rgba.end(), {c[0], c[1], c[2], 255});
    const int view = AddView(rgba.data(), rgba.size(), kArrayBuffer);
    return AddAccessor(view, kUnsignedByte, colors.size(), "VEC4", {{"normalized", true}});
  }

  int AddIndices(const std::vector<Eigen::Vector3i>& triangles) {
    std::vector<uint32_t> indices;
    indices.reserve(3 * triangles.size());
    uint32_t hi = 0;
    for (const Eigen::Vector3i& t : triangles)
      for (int k = 0; k < 3; ++k) {
        indices.push_back(static_cast<uint32_t>(t[k]));
        hi = std::max(hi, indices.back());
      }
    const int view =
        AddView(indices.data(), indices.size() * sizeof(uint32_t), kElementArrayBuffer);
    return AddAccessor(view, kUnsignedInt, indices.size(), "SCALAR", {{"min", {0}}, {"max", {hi}}});
  }

  const std::string& bin() const { return bin_; }
  const nlohmann::json& views() const { return views_; }
  const nlohmann::json& accessors() const { return accessors_; }

 private:
  int AddAccessor(int view, int component_type, size_t count, const char* type,
                  nlohmann::json extra) {
    nlohmann::json accessor = {
        {"bufferView", view}, {"componentType", component_type}, {"count", count}, {"type", type}};
    accessor.update(extra);
    accessors_.push_back(accessor);
    return static_cast<int>(accessors_.size()) - 1;
  }

  std::string bin_;
  nlohmann::json views_ = nlohmann::json::array();
  nlohmann::json accessors_ = nlohmann::json::array();
};

void AppendU32(std::string* out, uint32_t value) {
  char bytes[4];
  std::memcpy(bytes, &value, 4);  // glTF is little endian, as every platform omnisculpt builds on
  out->append(bytes, 4);
}

}  // namespace

std::string EncodeGlb(const TriangleMesh& mesh, const PointCloud& points) {
  CheckInput(mesh, points);
  const bool has_surface = !mesh.triangles.empty();
  const bool has_points = !points.points.empty();
  if (!has_surface && !has_points)
    throw std::invalid_argument("glb: neither triangles nor points to write");

  GlbBuilder builder;
  nlohmann::json meshes = nlohmann::json::array();
  nlohmann::json world_children = nlohmann::json::array();
  nlohmann::json nodes = nlohmann::json::array();
  // -90 degrees about x: the world's z up becomes glTF's y up.
  const double s = std::sqrt(0.5);
  nodes.push_back({{"name", "world"}, {"rotation", {-s, 0.0, 0.0, s}}});
  if (has_surface) {
    nlohmann::json attributes = {{"POSITION", builder.AddPositions(mesh.vertices)}};
    if (!mesh.colors.empty()) attributes["COLOR_0"] = builder.AddColors(mesh.colors);
    const int indices = builder.AddIndices(mesh.triangles);
    meshes.push_back({{"name", "surface"},
                      {"primitives",
                       {{{"attributes", attributes},
                         {"indices", indices},
                         {"material", 0},
                         {"mode", kModeTriangles}}}}});
    nodes.push_back({{"name", "surface"}, {"mesh", meshes.size() - 1}});
    world_children.push_back(nodes.size() - 1);
  }
  if (has_points) {
    nlohmann::json attributes = {{"POSITION", builder.AddPositions(points.points)}};
    if (!points.colors.empty()) attributes["COLOR_0"] = builder.AddColors(points.colors);
    meshes.push_back({{"name", "points"},
                      {"primitives", {{{"attributes", attributes}, {"mode", kModePoints}}}}});
    nodes.push_back({{"name", "points"}, {"mesh", meshes.size() - 1}});
    world_children.push_back(nodes.size() - 1);
  }
  nodes[0]["children"] = world_children;
  std::string bin = builder.bin();
  while (bin.size() % 4 != 0) bin.push_back('\0');

  const nlohmann::json gltf = {{"asset", {{"version", "2.0"}, {"generator", "omnisculpt"}}},
                               {"scene", 0},
                               {"scenes", {{{"name", "reconstruction"}, {"nodes", {0}}}}},
                               {"nodes", nodes},
                               {"meshes", meshes},
                               {"materials",
                                {{{"name", "surface"},
                                  {"pbrMetallicRoughness",
                                   {{"baseColorFactor", {1.0, 1.0, 1.0, 1.0}},
                                    {"metallicFactor", 0.0},
                                    {"roughnessFactor", 1.0}}},
                                  {"doubleSided", false}}}},
                               {"buffers", {{{"byteLength", bin.size()}}}},
                               {"bufferViews", builder.views()},
                               {"accessors", builder.accessors()}};
  std::string json = gltf.dump();
  while (json.size() % 4 != 0) json.push_back(' ');

  std::string glb;
  const size_t total = 12 + 8 + json.size() + 8 + bin.size();
  if (total > std::numeric_limits<uint32_t>::max())
    throw std::invalid_argument("glb: " + std::to_string(total) + " bytes, more than 4 GiB");
  glb.reserve(total);
  AppendU32(&glb, kGlbMagic);
  AppendU32(&glb, 2);
  AppendU32(&glb, static_cast<uint32_t>(total));
  AppendU32(&glb, static_cast<uint32_t>(json.size()));
  AppendU32(&glb, kChunkJson);
  glb += json;
  AppendU32(&glb, static_cast<uint32_t>(bin.size()));
  AppendU32(&glb, kChunkBin);
  glb += bin;
  return glb;
}

void WriteGlb(const TriangleMesh& mesh, const PointCloud& points,
              const std::filesystem::path& path) {
  const std::string glb = EncodeGlb(mesh, points);
  WriteFileAtomically(
      path, [&glb](std::ostream& out) { out.write(glb.data(), static_cast<long>(glb.size())); },
      /*binary=*/true);
}

void WriteObj(const TriangleMesh& mesh, const std::filesystem::path& path) {
  CheckInput(mesh, PointCloud());
  WriteFileAtomically(path, [&mesh](std::ostream& out) {
    out << "# omnisculpt surface: " << mesh.vertices.size() << " vertices, "
        << mesh.triangles.size() << " triangles (z up)\n";
    out << std::setprecision(9);
    for (size_t i = 0; i < mesh.vertices.size(); ++i) {
      const Eigen::Vector3d& v = mesh.vertices[i];
      out << "v " << v.x() << ' ' << v.y() << ' ' << v.z();
      if (!mesh.colors.empty()) {
        const Rgb8& c = mesh.colors[i];
        out << std::setprecision(4) << ' ' << c[0] / 255.0 << ' ' << c[1] / 255.0 << ' '
            << c[2] / 255.0 << std::setprecision(9);
      }
      out << '\n';
    }
    for (const Eigen::Vector3i& t : mesh.triangles)
      out << "f " << t[0] + 1 << ' ' << t[1] + 1 << ' ' << t[2] + 1 << '\n';
  });
}

}  // namespace omni
