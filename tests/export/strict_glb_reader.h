#pragma once
// A strict reader of binary glTF 2.0 for the tests (written from the specification, sharing
// no code with export/gltf.cpp): the 12-byte header (magic "glTF", version 2, total length =
// file size), exactly a JSON chunk then a BIN chunk, chunk lengths multiples of 4 and within
// the file, asset.version "2.0", every accessor's bufferView inside its buffer and the buffer
// inside the BIN chunk, byte offsets aligned to the component size (vertex attributes to 4),
// componentType and type allowed for the attribute, POSITION with min/max equal to the data's,
// indices within the vertex count and within the accessor's min/max. It returns the first
// violation as text, or the meshes (positions, indices, RGB colours) by name.

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace omni::testing {

struct GlbPrimitive {
  int mode = 4;
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3i> colors;  // 0..255, empty when no COLOR_0
  std::vector<uint32_t> indices;        // empty when not indexed
};

struct GlbContent {
  std::string error;  // empty: valid
  nlohmann::json json;
  std::map<std::string, GlbPrimitive> meshes;  // by mesh name, the first primitive
};

namespace glb_detail {

inline uint32_t U32(const std::string& bytes, size_t offset) {
  uint32_t value;
  std::memcpy(&value, bytes.data() + offset, 4);
  return value;
}

inline size_t ComponentSize(int type) {
  switch (type) {
    case 5120:
    case 5121:
      return 1;
    case 5122:
    case 5123:
      return 2;
    case 5125:
    case 5126:
      return 4;
    default:
      return 0;
  }
}

inline size_t ComponentCount(const std::string& type) {
  if (type == "SCALAR") return 1;
  if (type == "VEC2") return 2;
  if (type == "VEC3") return 3;
  if (type == "VEC4") return 4;
  if (type == "MAT4") return 16;
  return 0;
}

// The accessor's components as doubles (normalised integers scaled to [0, 1] unless raw).
inline std::string ReadAccessor(const nlohmann::json& gltf, const std::string& bin, int index,
                                bool vertex_attribute, std::vector<double>* values,
                                size_t* components) {
  const std::string where = "accessors[" + std::to_string(index) + "]";
  if (!gltf.contains("accessors") || index < 0 ||
      index >= static_cast<int>(gltf["accessors"].size()))
    return where + ": no such accessor";
  const nlohmann::json& a = gltf["accessors"][index];
  for (const char* key : {"bufferView", "componentType", "count", "type"})
    if (!a.contains(key)) return where + ": no " + key;
  const int component_type = a["componentType"];
  const size_t size = ComponentSize(component_type);
  *components = ComponentCount(a["type"]);
  if (size == 0)
    return where + ": componentType " + std::to_string(component_type) + " not allowed";
  if (*components == 0) return where + ": type " + a["type"].get<std::string>() + " not allowed";
  const size_t count = a["count"];
  if (count == 0) return where + ": count 0";
  const int view_index = a["bufferView"];
  if (view_index < 0 || view_index >= static_cast<int>(gltf["bufferViews"].size()))
    return where + ": bufferView out of range";
  const nlohmann::json& view = gltf["bufferViews"][view_index];
  if (view.value("buffer", -1) != 0)
    return where + ": bufferView's buffer is not 0 (the BIN chunk)";
  const size_t view_offset = view.value("byteOffset", 0);
  const size_t view_length = view["byteLength"];
  const size_t buffer_length = gltf["buffers"][0]["byteLength"];
  if (view_offset + view_length > buffer_length) return where + ": bufferView beyond its buffer";
  if (buffer_length > bin.size()) return "buffers[0]: byteLength beyond the BIN chunk";
  const size_t accessor_offset = a.value("byteOffset", 0);
  const size_t element = size * *components;
  const size_t stride = view.value("byteStride", element);
  if ((view_offset + accessor_offset) % size != 0)
    return where + ": not aligned to its component size";
  if (vertex_attribute && ((view_offset + accessor_offset) % 4 != 0 || stride % 4 != 0))
    return where + ": vertex attribute not aligned to 4 bytes";
  if (accessor_offset + stride * (count - 1) + element > view_length)
    return where + ": data beyond its bufferView";
  const bool normalized = a.value("normalized", false);
  values->clear();
  for (size_t i = 0; i < count; ++i) {
    for (size_t k = 0; k < *components; ++k) {
      const char* p = bin.data() + view_offset + accessor_offset + i * stride + k * size;
      double v = 0;
      switch (component_type) {
        case 5121:
          v = static_cast<uint8_t>(*p);
          if (normalized) v /= 255.0;
          break;
        case 5123: {
          uint16_t u;
          std::memcpy(&u, p, 2);
          v = normalized ? u / 65535.0 : u;
          break;
        }
        case 5125: {
          uint32_t u;
          std::memcpy(&u, p, 4);
          v = u;
          break;
        }
        case 5126: {
          float f;
          std::memcpy(&f, p, 4);
          v = f;
          break;
        }
        default:
          return where + ": componentType not read by this reader";
      }
      values->push_back(v);
    }
  }
  // min/max, when given, must be those of the data.
  for (const char* bound : {"min", "max"}) {
    if (!a.contains(bound)) continue;
    if (a[bound].size() != *components) return where + ": " + bound + " of the wrong length";
    for (size_t k = 0; k < *components; ++k) {
      double extreme = (*values)[k];
      for (size_t i = 0; i < count; ++i)
        extreme = bound[1] == 'i' ? std::min(extreme, (*values)[i * *components + k])
                                  : std::max(extreme, (*values)[i * *components + k]);
      if (a[bound][k].get<double>() != extreme)
        return where + ": " + bound + "[" + std::to_string(k) + "] is not the data's";
    }
  }
  return {};
}

}  // namespace glb_detail

inline GlbContent ReadGlbStrictly(const std::string& bytes) {
  using namespace glb_detail;
  GlbContent content;
  auto fail = [&content](const std::string& error) {
    content.error = error;
    return content;
  };
  if (bytes.size() < 20) return fail("shorter than a header and a chunk header");
  if (U32(bytes, 0) != 0x46546C67) return fail("magic is not glTF");
  if (U32(bytes, 4) != 2) return fail("version is not 2");
  if (U32(bytes, 8) != bytes.size()) return fail("header length is not the file size");
  const uint32_t json_length = U32(bytes, 12);
  if (U32(bytes, 16) != 0x4E4F534A) return fail("the first chunk is not JSON");
  if (json_length % 4 != 0) return fail("JSON chunk length not a multiple of 4");
  if (20 + static_cast<size_t>(json_length) + 8 > bytes.size())
    return fail("JSON chunk beyond the file");
  const std::string json_text = bytes.substr(20, json_length);
  const size_t bin_header = 20 + json_length;
  const uint32_t bin_length = U32(bytes, bin_header);
  if (U32(bytes, bin_header + 4) != 0x004E4942) return fail("the second chunk is not BIN");
  if (bin_length % 4 != 0) return fail("BIN chunk length not a multiple of 4");
  if (bin_header + 8 + static_cast<size_t>(bin_length) != bytes.size())
    return fail("BIN chunk does not end the file");
  const std::string bin = bytes.substr(bin_header + 8, bin_length);
  try {
    content.json = nlohmann::json::parse(json_text);
  } catch (const nlohmann::json::exception& e) {
    return fail(std::string("JSON chunk: ") + e.what());
  }
  const nlohmann::json& gltf = content.json;
  if (!gltf.contains("asset") || gltf["asset"].value("version", "") != "2.0")
    return fail("asset.version is not 2.0");
  if (!gltf.contains("buffers") || gltf["buffers"].size() != 1 ||
      gltf["buffers"][0].contains("uri"))
    return fail("expected one buffer, the BIN chunk");
  if (!gltf.contains("meshes")) return fail("no meshes");
  // Every node's mesh exists; the scene's nodes exist.
  for (const nlohmann::json& node : gltf.value("nodes", nlohmann::json::array()))
    if (node.contains("mesh") && node["mesh"].get<size_t>() >= gltf["meshes"].size())
      return fail("a node's mesh out of range");
  for (const nlohmann::json& mesh : gltf["meshes"]) {
    const std::string name = mesh.value("name", "");
    if (!mesh.contains("primitives") || mesh["primitives"].empty())
      return fail(name + ": no primitive");
    const nlohmann::json& p = mesh["primitives"][0];
    GlbPrimitive primitive;
    primitive.mode = p.value("mode", 4);
    if (!p.contains("attributes") || !p["attributes"].contains("POSITION"))
      return fail(name + ": no POSITION");
    std::vector<double> values;
    size_t components = 0;
    const int position = p["attributes"]["POSITION"];
    if (std::string e = ReadAccessor(gltf, bin, position, true, &values, &components); !e.empty())
      return fail(name + ": POSITION " + e);
    const nlohmann::json& pa = gltf["accessors"][position];
    if (pa["componentType"] != 5126 || components != 3)
      return fail(name + ": POSITION not float VEC3");
    if (!pa.contains("min") || !pa.contains("max"))
      return fail(name + ": POSITION without min/max");
    for (size_t i = 0; i < values.size(); i += 3)
      primitive.positions.emplace_back(static_cast<float>(values[i]),
                                       static_cast<float>(values[i + 1]),
                                       static_cast<float>(values[i + 2]));
    if (p["attributes"].contains("COLOR_0")) {
      const int color = p["attributes"]["COLOR_0"];
      if (std::string e = ReadAccessor(gltf, bin, color, true, &values, &components); !e.empty())
        return fail(name + ": COLOR_0 " + e);
      const nlohmann::json& ca = gltf["accessors"][color];
      const int type = ca["componentType"];
      if ((components != 3 && components != 4) ||
          !(type == 5126 || ((type == 5121 || type == 5123) && ca.value("normalized", false))))
        return fail(name + ": COLOR_0 must be VEC3/VEC4 float or normalised unsigned byte/short");
      if (values.size() / components != primitive.positions.size())
        return fail(name + ": COLOR_0 count differs from POSITION's");
      for (size_t i = 0; i < values.size(); i += components)
        primitive.colors.emplace_back(static_cast<int>(std::lround(values[i] * 255)),
                                      static_cast<int>(std::lround(values[i + 1] * 255)),
                                      static_cast<int>(std::lround(values[i + 2] * 255)));
    }
    if (p.contains("indices")) {
      const int indices = p["indices"];
      if (std::string e = ReadAccessor(gltf, bin, indices, false, &values, &components); !e.empty())
        return fail(name + ": indices " + e);
      const nlohmann::json& ia = gltf["accessors"][indices];
      const int type = ia["componentType"];
      if (components != 1 || !(type == 5121 || type == 5123 || type == 5125) ||
          ia.value("normalized", false))
        return fail(name + ": indices must be unsigned integer SCALAR");
      const nlohmann::json& view = gltf["bufferViews"][ia["bufferView"].get<int>()];
      if (view.contains("byteStride")) return fail(name + ": indices' bufferView has a byteStride");
      for (double v : values) {
        if (v >= primitive.positions.size()) return fail(name + ": index beyond the vertices");
        primitive.indices.push_back(static_cast<uint32_t>(v));
      }
      if (primitive.mode == 4 && primitive.indices.size() % 3 != 0)
        return fail(name + ": TRIANGLES with a count of indices not a multiple of 3");
    }
    content.meshes[name] = primitive;
  }
  return content;
}

}  // namespace omni::testing
