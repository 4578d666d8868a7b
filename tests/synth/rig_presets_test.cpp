// The rig presets (synth/rig_presets.h) and the drive options that imitate what users bring:
// each preset's cameras, sizes and offsets, a short drive rendered with each, the frame step
// (low frame rates, frames.csv) and the per-camera exposure differences.

#include "synth/rig_presets.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "calib/drive.h"
#include "calib/error.h"
#include "calib/rig_io.h"
#include "calib/rig_report.h"
#include "calib/tum.h"
#include "synth/drive_writer.h"
#include "tests/calib/io_temp_dir.h"

namespace omni::synth {
namespace {

namespace fs = std::filesystem;
constexpr double kPi = 3.14159265358979323846;

fs::path TempFolder(const std::string& name) {
  const fs::path path = fs::temp_directory_path() /
                        ("omni_rig_presets_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(path);
  return path;
}

using omni::testing::ReadBytes;  // tests/calib/io_temp_dir.h

SynthWriteOptions Quiet() {
  SynthWriteOptions write_options;
  write_options.progress = false;
  return write_options;
}

double HorizontalFovDeg(const Camera& camera) { return ComputeFieldOfView(camera).horizontal_deg; }

// True when the rig-frame point projects into camera `camera`'s image.
bool Sees(const Camera& camera, const Eigen::Vector3d& point_in_rig) {
  Eigen::Vector2d pixel;
  return camera.Project(camera.cam_from_rig * point_in_rig, &pixel) && camera.IsInImage(pixel);
}

TEST(RigPresetTest, EveryPresetParsesAndIsTheFileOfDataRigs) {
  const std::vector<RigPreset> presets = RigPresets();
  ASSERT_EQ(presets.size(), 4u);
  EXPECT_EQ(presets.front().name, "ladybug");
  for (const RigPreset& preset : presets) {
    const Rig rig = RigPresetRig(preset.name);
    EXPECT_EQ(rig.Check(), "") << preset.name;
    // The compiled-in copy follows the file.
    EXPECT_EQ(std::string(RigPresetJson(preset.name)),
              ReadBytes(fs::path(OMNI_SOURCE_DIR) / "data" / "rigs" / preset.file))
        << preset.name;
    // The description calib show prints works on each.
    EXPECT_NE(DescribeRig(rig).find(rig.cameras.front().name), std::string::npos);
  }
  try {
    RigPresetJson("drone");
    FAIL() << "no error for an unknown rig preset";
  } catch (const InputError& error) {
    const std::string what = error.what();
    EXPECT_NE(what.find("drone"), std::string::npos) << what;
    EXPECT_NE(what.find("ladybug, pinhole, car, fisheye5"), std::string::npos) << what;
  }
}

TEST(RigPresetTest, LadybugIsTheUnchangedDefault) {
  const Rig rig = RigPresetRig("ladybug");
  EXPECT_EQ(rig.name, "ladybug-like");
  EXPECT_FALSE(rig.central);  // its 4-6 cm offsets: the SfM's non-central mode by default
  ASSERT_EQ(rig.NumCameras(), 6u);
  for (const Camera& camera : rig.cameras) {
    EXPECT_EQ(camera.width, 384);
    EXPECT_EQ(camera.height, 512);
  }
  EXPECT_LT(rig.MaxCenterOffset(), 0.06);
}

TEST(RigPresetTest, PinholeIsOneForwardCameraOfSixtyToSeventyDegrees) {
  const Rig rig = RigPresetRig("pinhole");
  ASSERT_EQ(rig.NumCameras(), 1u);
  const Camera& camera = rig.cameras[0];
  EXPECT_EQ(camera.model, CameraModel::kPinhole);
  EXPECT_EQ(camera.width, 1024);
  EXPECT_EQ(camera.height, 768);
  EXPECT_GE(HorizontalFovDeg(camera), 60.0);
  EXPECT_LE(HorizontalFovDeg(camera), 70.0);
  EXPECT_TRUE(Sees(camera, Eigen::Vector3d(10, 0, 0)));    // ahead
  EXPECT_FALSE(Sees(camera, Eigen::Vector3d(-10, 0, 0)));  // behind
  EXPECT_FALSE(Sees(camera, Eigen::Vector3d(0, 10, 0)));   // left
}

TEST(RigPresetTest, CarHasSixLargePinholesOneToOneAndAHalfMetresOutThatOverlapALittle) {
  const Rig rig = RigPresetRig("car");
  EXPECT_FALSE(rig.central);
  ASSERT_EQ(rig.NumCameras(), 6u);
  std::vector<double> headings;
  for (const Camera& camera : rig.cameras) {
    EXPECT_EQ(camera.model, CameraModel::kPinhole) << camera.name;
    EXPECT_EQ(camera.width, 1920) << camera.name;
    EXPECT_EQ(camera.height, 1200) << camera.name;
    const double offset = camera.CenterInRig().norm();
    EXPECT_GE(offset, 1.0) << camera.name;
    EXPECT_LE(offset, 1.5) << camera.name;
    const Eigen::Vector3d direction =
        camera.cam_from_rig.rotation.inverse() * Eigen::Vector3d::UnitZ();
    EXPECT_NEAR(direction.z(), 0.0, 1e-9) << camera.name;  // level
    headings.push_back(std::atan2(direction.y(), direction.x()) * 180.0 / kPi);
  }
  EXPECT_TRUE(Sees(rig.cameras[0], Eigen::Vector3d(20, 0, 0))) << "the first camera looks ahead";
  // Every camera overlaps exactly two others (its neighbours around the car), a little.
  for (size_t a = 0; a < rig.NumCameras(); ++a) {
    int neighbours = 0;
    for (size_t b = 0; b < rig.NumCameras(); ++b) {
      if (a == b) continue;
      const double overlap = ComputeViewOverlap(rig, a, b, 48);
      if (overlap > 0) {
        ++neighbours;
        EXPECT_GT(overlap, 0.03) << rig.cameras[a].name << " / " << rig.cameras[b].name;
        EXPECT_LT(overlap, 0.35) << rig.cameras[a].name << " / " << rig.cameras[b].name;
      }
    }
    EXPECT_EQ(neighbours, 2) << rig.cameras[a].name;
  }
}

TEST(RigPresetTest, Fisheye5HasAStereoPairThatSeesTheSamePointsAndThreeMoreFisheyes) {
  const Rig rig = RigPresetRig("fisheye5");
  EXPECT_FALSE(rig.central);
  ASSERT_EQ(rig.NumCameras(), 5u);
  for (const Camera& camera : rig.cameras) {
    EXPECT_EQ(camera.model, CameraModel::kFisheye) << camera.name;
    EXPECT_EQ(camera.width, 720) << camera.name;
    EXPECT_EQ(camera.height, 540) << camera.name;
    EXPECT_GT(HorizontalFovDeg(camera), 100.0) << camera.name;
  }
  const Camera& left = rig.cameras[0];
  const Camera& right = rig.cameras[1];
  EXPECT_NEAR((left.CenterInRig() - right.CenterInRig()).norm(), 0.10, 0.01);
  // Points 5 m ahead, straight or off to a side, project into both cameras of the pair.
  for (const Eigen::Vector3d& point :
       {Eigen::Vector3d(5, 0, 0), Eigen::Vector3d(5, 2, 1), Eigen::Vector3d(5, -3, -1.5)}) {
    EXPECT_TRUE(Sees(left, point)) << point.transpose();
    EXPECT_TRUE(Sees(right, point)) << point.transpose();
  }
  EXPECT_GT(ComputeViewOverlap(rig, 0, 1), 0.9);
  // The others look left, right and up.
  EXPECT_TRUE(Sees(rig.cameras[2], Eigen::Vector3d(0, 5, 0)));
  EXPECT_TRUE(Sees(rig.cameras[3], Eigen::Vector3d(0, -5, 0)));
  EXPECT_TRUE(Sees(rig.cameras[4], Eigen::Vector3d(0, 0, 5)));
  EXPECT_FALSE(Sees(rig.cameras[2], Eigen::Vector3d(0, -5, 0)));
}

// A few frames of the tiny city with each rig preset, small enough to render in seconds.
TEST(RigPresetTest, AShortDriveRendersWithEachPreset) {
  for (const RigPreset& preset : RigPresets()) {
    SynthOptions options = SynthPresetOptions("tiny");
    options.trajectory.num_frames = 2;
    options.render.image_scale = preset.name == "car" ? 0.1 : 0.25;
    const fs::path folder = TempFolder("render_" + preset.name);
    const Rig rig = RigPresetRig(preset.name);
    const SynthSummary summary = WriteSyntheticDrive(options, rig, folder, Quiet());
    EXPECT_EQ(summary.frames, 2u);
    EXPECT_EQ(summary.cameras, rig.NumCameras());
    const Drive drive = Drive::Open(folder);
    ASSERT_EQ(drive.NumFrames(), 2u) << preset.name;
    ASSERT_EQ(drive.rig().NumCameras(), rig.NumCameras()) << preset.name;
    EXPECT_EQ(drive.rig().central, rig.central) << preset.name;
    for (size_t c = 0; c < rig.NumCameras(); ++c) {
      const int width =
          static_cast<int>(std::lround(rig.cameras[c].width * options.render.image_scale));
      const int height =
          static_cast<int>(std::lround(rig.cameras[c].height * options.render.image_scale));
      for (size_t f = 0; f < drive.NumFrames(); ++f) {
        const cv::Mat image = drive.LoadGray(f, c);  // checks the size against rig.json
        EXPECT_EQ(image.cols, width) << preset.name << " " << rig.cameras[c].name;
        EXPECT_EQ(image.rows, height) << preset.name << " " << rig.cameras[c].name;
        cv::Scalar mean, stddev;
        cv::meanStdDev(image, mean, stddev);
        EXPECT_GT(mean[0], 20.0) << preset.name << " " << rig.cameras[c].name << " is dark";
        EXPECT_GT(stddev[0], 8.0) << preset.name << " " << rig.cameras[c].name << " is blank";
      }
    }
    fs::remove_all(folder);
  }
}

TEST(SynthFrameStepTest, KeepsEveryKthPoseWithItsTrajectoryIndexAndClock) {
  SynthOptions full = SynthPresetOptions("tiny");
  full.trajectory.num_frames = 25;
  full.render.image_scale = 0.25;
  SynthOptions stepped = full;
  stepped.trajectory.frame_step = 10;
  const fs::path full_folder = TempFolder("full"), stepped_folder = TempFolder("stepped");
  WriteSyntheticDrive(full, RigPresetRig("ladybug"), full_folder, Quiet());
  const SynthSummary summary =
      WriteSyntheticDrive(stepped, RigPresetRig("ladybug"), stepped_folder, Quiet());
  EXPECT_EQ(summary.frames, 3u);

  const std::vector<StampedPose> all = ReadTum(full_folder / "gt" / "poses.tum");
  const std::vector<StampedPose> kept = ReadTum(stepped_folder / "gt" / "poses.tum");
  ASSERT_EQ(all.size(), 25u);
  ASSERT_EQ(kept.size(), 3u);
  const Drive drive = Drive::Open(stepped_folder);
  ASSERT_EQ(drive.NumFrames(), 3u);
  ASSERT_TRUE(drive.HasTimestamps()) << "no frames.csv";
  EXPECT_FALSE(fs::exists(full_folder / "frames.csv"));
  for (size_t i = 0; i < kept.size(); ++i) {
    const size_t f = 10 * i;
    EXPECT_EQ(drive.FrameName(i), SynthFrameName(f));
    EXPECT_NEAR(kept[i].timestamp, f / 15.0, 1e-9);
    EXPECT_NEAR(kept[i].timestamp, all[f].timestamp, 1e-12);
    EXPECT_NEAR(drive.FrameTimestamp(i), kept[i].timestamp, 1e-9);
    EXPECT_EQ(kept[i].world_from_rig.translation, all[f].world_from_rig.translation);
    EXPECT_EQ(kept[i].world_from_rig.rotation.coeffs(), all[f].world_from_rig.rotation.coeffs());
    // The same frame as in the full drive, image for image.
    for (size_t c = 0; c < drive.rig().NumCameras(); ++c) {
      const std::string image =
          "images/" + drive.rig().cameras[c].name + "/" + SynthFrameName(f) + ".png";
      EXPECT_TRUE(ReadBytes(stepped_folder / image) == ReadBytes(full_folder / image)) << image;
    }
  }
  // One frames.csv row per image.
  std::ifstream csv(stepped_folder / "frames.csv");
  std::string line;
  std::getline(csv, line);
  EXPECT_EQ(line, "frame,camera,timestamp_s");
  int rows = 0;
  while (std::getline(csv, line)) ++rows;
  EXPECT_EQ(rows, 3 * 6);
  EXPECT_EQ(ReadBytes(stepped_folder / "gt" / "mesh.ply"),
            ReadBytes(full_folder / "gt" / "mesh.ply"));

  SynthOptions too_few = full;
  too_few.trajectory.frame_step = 25;
  EXPECT_NE(too_few.Check().find("trajectory.frame_step"), std::string::npos);
  fs::remove_all(full_folder);
  fs::remove_all(stepped_folder);
}

// Mean grey level of `exposed` and `reference` over the pixels that neither quantisation end
// clips: where the reference lies in [8, 170], so that a gain up to 1.3 and an offset up to 20
// levels stay below 255.
void UnclippedMeans(const cv::Mat& reference, const cv::Mat& exposed, double* mean_reference,
                    double* mean_exposed) {
  double sum_reference = 0, sum_exposed = 0;
  size_t count = 0;
  for (int y = 0; y < reference.rows; ++y) {
    for (int x = 0; x < reference.cols; ++x) {
      const int r = reference.at<uint8_t>(y, x), e = exposed.at<uint8_t>(y, x);
      if (r < 8 || r > 170 || e == 0 || e == 255) continue;
      sum_reference += r;
      sum_exposed += e;
      ++count;
    }
  }
  ASSERT_GT(count, static_cast<size_t>(reference.total() / 2));
  *mean_reference = sum_reference / count;
  *mean_exposed = sum_exposed / count;
}

TEST(SynthExposureTest, EachCameraIsScaledByItsDrawnGainAndTheGeometryStays) {
  SynthOptions reference = SynthPresetOptions("tiny");
  reference.trajectory.num_frames = 2;
  reference.render.image_scale = 0.5;
  SynthOptions exposed = reference;
  exposed.render.exposure_spread = 0.3;
  SynthOptions shifted = exposed;
  shifted.render.exposure_offset = 12;
  const Rig rig = RigPresetRig("ladybug");
  const fs::path a = TempFolder("exposure_0"), b = TempFolder("exposure_3"),
                 c = TempFolder("exposure_offset");
  WriteSyntheticDrive(reference, rig, a, Quiet());
  WriteSyntheticDrive(exposed, rig, b, Quiet());
  WriteSyntheticDrive(shifted, rig, c, Quiet());

  const SyntheticDrive drive = MakeSyntheticDrive(exposed, rig);
  const SyntheticDrive shifted_drive = MakeSyntheticDrive(shifted, rig);
  const SyntheticDrive reference_drive = MakeSyntheticDrive(reference, rig);
  double largest = 0;
  for (size_t camera = 0; camera < rig.NumCameras(); ++camera) {
    EXPECT_EQ(reference_drive.exposure_gains[camera], 1.0);
    EXPECT_EQ(reference_drive.exposure_offsets[camera], 0.0);
    EXPECT_EQ(drive.exposure_offsets[camera], 0.0);
    const double gain = drive.exposure_gains[camera];
    EXPECT_GE(gain, 0.7);
    EXPECT_LE(gain, 1.3);
    EXPECT_EQ(shifted_drive.exposure_gains[camera], gain);  // the offsets are drawn apart
    EXPECT_LE(std::abs(shifted_drive.exposure_offsets[camera]), 12.0);
    largest = std::max(largest, std::abs(gain - 1.0));
  }
  EXPECT_GT(largest, 0.1) << "the gains hardly differ from 1";

  for (size_t frame = 0; frame < 2; ++frame) {
    for (size_t camera = 0; camera < rig.NumCameras(); ++camera) {
      const std::string image =
          "images/" + rig.cameras[camera].name + "/" + SynthFrameName(frame) + ".png";
      const cv::Mat ref = cv::imread((a / image).string(), cv::IMREAD_UNCHANGED);
      const cv::Mat exp = cv::imread((b / image).string(), cv::IMREAD_UNCHANGED);
      const cv::Mat off = cv::imread((c / image).string(), cv::IMREAD_UNCHANGED);
      double mean_ref = 0, mean_exp = 0;
      UnclippedMeans(ref, exp, &mean_ref, &mean_exp);
      // The noise is the same in both (same image seed): only the rounding differs.
      EXPECT_NEAR(mean_exp, drive.exposure_gains[camera] * mean_ref, 1.0) << image;
      UnclippedMeans(ref, off, &mean_ref, &mean_exp);
      EXPECT_NEAR(
          mean_exp,
          shifted_drive.exposure_gains[camera] * mean_ref + shifted_drive.exposure_offsets[camera],
          1.0)
          << image;
    }
  }
  // The geometry is the same.
  for (const char* file : {"rig.json", "gt/poses.tum", "gt/mesh.ply"}) {
    EXPECT_TRUE(ReadBytes(a / file) == ReadBytes(b / file)) << file;
    EXPECT_TRUE(ReadBytes(a / file) == ReadBytes(c / file)) << file;
  }
  fs::remove_all(a);
  fs::remove_all(b);
  fs::remove_all(c);
}

}  // namespace
}  // namespace omni::synth
