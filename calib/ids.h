#pragma once
// Typed ids with an explicit invalid value (docs/design.md §3), so that a keyframe id cannot be
// passed where a point id is expected.

#include <cstdint>
#include <functional>
#include <limits>

namespace omni {

template <typename Tag>
struct TypedId {
  static constexpr uint32_t kInvalidValue = std::numeric_limits<uint32_t>::max();
  uint32_t value = kInvalidValue;

  constexpr TypedId() = default;
  constexpr explicit TypedId(uint32_t v) : value(v) {}
  static constexpr TypedId Invalid() { return TypedId(); }
  constexpr bool IsValid() const { return value != kInvalidValue; }
  constexpr bool operator==(TypedId other) const { return value == other.value; }
  constexpr bool operator!=(TypedId other) const { return value != other.value; }
  constexpr bool operator<(TypedId other) const { return value < other.value; }
};

using KeyframeId = TypedId<struct KeyframeIdTag>;
using PointId = TypedId<struct PointIdTag>;
using CameraIndex = TypedId<struct CameraIndexTag>;
using FrameIndex = TypedId<struct FrameIndexTag>;

}  // namespace omni

namespace std {
template <typename Tag>
struct hash<omni::TypedId<Tag>> {
  size_t operator()(omni::TypedId<Tag> id) const noexcept { return std::hash<uint32_t>()(id.value); }
};
}  // namespace std
