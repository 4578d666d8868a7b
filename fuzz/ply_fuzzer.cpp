// PLY meshes and point clouds (calib/ply.h), ascii and binary.
#include "calib/ply.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes = omni::fuzz::AsText(data, size);
  omni::fuzz::ParseOrRefuse([&] {
    const omni::TriangleMesh mesh = omni::ParsePlyMesh(bytes, "mesh.ply");
    // Every triangle has its label (a face's, on each triangle of its fan), or none has.
    if (!mesh.labels.empty() && mesh.labels.size() != mesh.triangles.size()) __builtin_trap();
  });
  return omni::fuzz::ParseOrRefuse([&] { omni::ParsePlyPoints(bytes, "points.ply"); });
}
