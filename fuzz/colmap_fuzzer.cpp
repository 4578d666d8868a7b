// COLMAP text models (pipeline/colmap_keyframes.h): the input holds cameras.txt, images.txt and
// points3D.txt separated by lines "%%".
#include "fuzz/fuzz_input.h"
#include "pipeline/colmap_keyframes.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = omni::fuzz::AsText(data, size);
  omni::ColmapTextModel model;
  std::string* parts[3] = {&model.cameras, &model.images, &model.points3d};
  size_t start = 0;
  for (int i = 0; i < 3; ++i) {
    const size_t separator = i < 2 ? text.find("\n%%\n", start) : std::string::npos;
    *parts[i] =
        text.substr(start, separator == std::string::npos ? std::string::npos : separator - start);
    if (separator == std::string::npos) break;
    start = separator + 4;
  }
  std::unordered_map<omni::PointId, omni::Rgb8> colors;
  return omni::fuzz::ParseOrRefuse([&] { omni::ParseColmapKeyframes(model, "model", &colors); });
}
