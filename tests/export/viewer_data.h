#pragma once
// Reading back the viewer's data (export/viewer_bundle.h) in the tests: the JSON value a data
// script assigns, the bytes of a base64 .glb, a .glb mesh against a PLY mesh.

#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>

#include "calib/ply.h"
#include "tests/calib/io_temp_dir.h"
#include "tests/export/strict_glb_reader.h"

namespace omni::testing {

inline std::string Base64Decoded(const std::string& text) {
  std::string out;
  int value = 0, bits = -8;
  for (char c : text) {
    const char* alphabet = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const char* at = std::strchr(alphabet, c);
    if (c == '=' || !at || !c) break;
    value = (value << 6) | static_cast<int>(at - alphabet);
    bits += 6;
    if (bits >= 0) {
      out.push_back(static_cast<char>((value >> bits) & 0xFF));
      bits -= 8;
    }
  }
  return out;
}

// The value a data script of the viewer assigns: "window.X = <json>;" or "...[key] = <json>;".
inline nlohmann::json ScriptValue(const std::filesystem::path& script) {
  const std::string text = ReadBytes(script);
  const size_t equals =
      text.rfind("] = ") != std::string::npos ? text.rfind("] = ") + 4 : text.find(" = ") + 3;
  return nlohmann::json::parse(text.substr(equals, text.rfind(';') - equals));
}

// The mesh of a .glb equals the PLY mesh: every vertex (as float), triangle and colour.
inline void ExpectSameMesh(const GlbPrimitive& glb, const TriangleMesh& ply) {
  ASSERT_EQ(glb.positions.size(), ply.vertices.size());
  ASSERT_EQ(glb.indices.size(), 3 * ply.triangles.size());
  ASSERT_EQ(glb.colors.size(), ply.colors.size());
  size_t differing = 0;
  for (size_t i = 0; i < ply.vertices.size(); ++i) {
    if (glb.positions[i] != ply.vertices[i].cast<float>()) ++differing;
    if (!ply.colors.empty() && glb.colors[i] != ply.colors[i].cast<int>()) ++differing;
  }
  for (size_t t = 0; t < ply.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      if (glb.indices[3 * t + k] != static_cast<uint32_t>(ply.triangles[t][k])) ++differing;
  EXPECT_EQ(differing, 0u);
}

}  // namespace omni::testing
