// rig.json (calib/rig_io.h).
#include "calib/rig_io.h"
#include "fuzz/fuzz_input.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = omni::fuzz::AsText(data, size);
  return omni::fuzz::ParseOrRefuse([&] {
    const omni::Rig rig = omni::ParseRigJson(text, "rig.json");
    // What was accepted writes and reads back.
    omni::ParseRigJson(omni::RigToJson(rig), "written rig.json");
  });
}
