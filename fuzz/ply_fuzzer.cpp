// PLY meshes and point clouds (calib/ply.h), ascii and binary.
#include "calib/ply.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string bytes = omni::fuzz::AsText(data, size);
  omni::fuzz::ParseOrRefuse([&] { omni::ParsePlyMesh(bytes, "mesh.ply"); });
  return omni::fuzz::ParseOrRefuse([&] { omni::ParsePlyPoints(bytes, "points.ply"); });
}
