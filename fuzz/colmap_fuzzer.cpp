// COLMAP text models (pipeline/colmap_keyframes.h): the input holds cameras.txt, images.txt,
// points3D.txt and frame_rays.txt separated by lines "%%" (the last ones may be missing).
#include "fuzz/fuzz_input.h"
#include "pipeline/colmap_keyframes.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string text = omni::fuzz::AsText(data, size);
  omni::ColmapTextModel model;
  std::string* parts[4] = {&model.cameras, &model.images, &model.points3d, &model.frame_rays};
  size_t start = 0;
  for (int i = 0; i < 4; ++i) {
    const size_t separator = i < 3 ? text.find("\n%%\n", start) : std::string::npos;
    *parts[i] =
        text.substr(start, separator == std::string::npos ? std::string::npos : separator - start);
    if (separator == std::string::npos) break;
    start = separator + 4;
  }
  std::unordered_map<omni::PointId, omni::Rgb8> colors;
  return omni::fuzz::ParseOrRefuse([&] { omni::ParseColmapKeyframes(model, "model", &colors); });
}
