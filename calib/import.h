#pragma once
// Importers of other calibration formats to a Rig (then written as rig.json).
//
// Kalibr camchain.yaml / camchain-imucam.yaml: pinhole camera model with radtan (-> opencv)
// or equidistant (-> fisheye) distortion. Extrinsics from the chained T_cn_cnm1
// (cam_n_from_cam_n-1); when a camera has none, from T_cam_imu. The first camera defines the
// rig frame.
//
// Ladybug SDK calibration text ("Ladybug 2.0" .conf export): `Resolution W H`, then per
// `BeginCamera ... EndCamera` block `focalLength fu fv` (rectified focal length / W, / H),
// `CamToLadybugEulerZYX rx ry rz tx ty tz` (head_from_cam: R = Rz(rz) Ry(ry) Rx(rx), radians;
// t = camera centre in the head frame, metres) and `Center X Y Z U V` (principal point
// normalised by W and H with pixel centres at +0.5: cx = U W - 0.5, cy = V H - 0.5).
// Rectified images are pinhole, so the cameras are imported as pinhole. The head frame is the
// rig frame. With upright, images stored rotated by 90 degrees are described (upright pixel
// = (H - 1 - v, u)).

#include <filesystem>
#include <string>

#include "calib/rig.h"

namespace omni {

Rig ImportKalibr(const std::filesystem::path& camchain_yaml);

struct KalibrImportOptions {
  // The imported rig is marked central (rig.json "central": true, the paper's approximation)
  // when no camera centre lies farther than this from the mean centre (Rig::MaxCenterOffset),
  // metres; farther, the SfM uses the true offsets.
  double central_max_center_offset_m = 0.05;
  // Largest |R^T R - I| entry accepted in a 4x4 transform before it is rejected as not rigid
  // (Kalibr prints many digits; hand-edited files have fewer). Accepted ones are projected to
  // the nearest rotation.
  double rotation_tolerance = 1e-3;
  std::string Check() const;
};
Rig ImportKalibr(const std::filesystem::path& camchain_yaml, const KalibrImportOptions& options);
// The same on the text of a camchain.yaml in memory; `camchain_yaml` names it in the errors.
Rig ParseKalibr(const std::string& text, const std::filesystem::path& camchain_yaml,
                const KalibrImportOptions& options = {});

struct LadybugImportOptions {
  bool upright = false;
};
Rig ImportLadybug(const std::filesystem::path& conf, const LadybugImportOptions& options = {});
// The same on the text of a .conf in memory; `conf` names it in the errors.
Rig ParseLadybug(const std::string& text, const std::filesystem::path& conf,
                 const LadybugImportOptions& options = {});

// Both importers check the rig they make as rig.json is checked (calib/rig_io.h, ranges
// included), so that what they write reads back; an image side is at most this many pixels.
constexpr int kMaxImportedImageSide = 1 << 16;

}  // namespace omni
