// Synthetic city drives: determinism, exact ground truth (hits reproject to their pixel and lie
// on gt/mesh.ply), Harris corners, loop closure.

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "calib/drive.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "raycast/raycast.h"
#include "synth/city.h"
#include "synth/drive_writer.h"
#include "synth/renderer.h"
#include "tests/calib/io_temp_dir.h"

namespace omni::synth {
namespace {

namespace fs = std::filesystem;

// The default rig of the command line (data/rigs/ladybug-like.json, compiled into the
// executable), read from the source tree.
Rig DefaultRig() { return ReadRigJson(fs::path(OMNI_SOURCE_DIR) / "data/rigs/ladybug-like.json"); }

fs::path TempFolder(const std::string& name) {
  const fs::path path =
      fs::temp_directory_path() / ("omni_synth_test_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(path);
  return path;
}

using omni::testing::ReadBytes;  // tests/calib/io_temp_dir.h

// Relative path -> bytes of every file under `folder`.
std::map<std::string, std::string> ReadTree(const fs::path& folder) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(folder)) {
    if (entry.is_regular_file()) {
      files[fs::relative(entry.path(), folder).string()] = ReadBytes(entry.path());
    }
  }
  return files;
}

// A small drive for the tests that write twice: the tiny city, few frames, half-size images.
SynthOptions SmallOptions(uint64_t seed) {
  SynthOptions options = SynthPresetOptions("tiny");
  options.seed = seed;
  options.trajectory.num_frames = 3;
  options.render.image_scale = 0.5;
  return options;
}

double DistanceToMesh(const TriangleMesh& mesh, const Eigen::Vector3d& p) {
  double best = std::numeric_limits<double>::infinity();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d& a = mesh.vertices[t[0]];
    const Eigen::Vector3d& b = mesh.vertices[t[1]];
    const Eigen::Vector3d& c = mesh.vertices[t[2]];
    // Cheap rejection by bounding box.
    const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c), hi = a.cwiseMax(b).cwiseMax(c);
    const double box = (lo - p).cwiseMax(p - hi).cwiseMax(0.0).norm();
    if (box >= best) continue;
    best = std::min(best, (ClosestPointOnTriangle(p, a, b, c) - p).norm());
  }
  return best;
}

// The tiny preset written once, full size, shared by the tests that only read it.
class TinyDriveTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    folder_ = new fs::path(TempFolder("tiny"));
    SynthWriteOptions write_options;
    write_options.progress = false;
    summary_ = new SynthSummary(
        WriteSyntheticDrive(SynthPresetOptions("tiny"), DefaultRig(), *folder_, write_options));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*folder_);
    delete folder_;
    delete summary_;
  }
  static fs::path* folder_;
  static SynthSummary* summary_;
};
fs::path* TinyDriveTest::folder_ = nullptr;
SynthSummary* TinyDriveTest::summary_ = nullptr;

TEST(SynthOptionsTest, PresetsAreValidAndUnknownOnesListThem) {
  for (const SynthPreset& preset : SynthPresets()) {
    const SynthOptions options = SynthPresetOptions(preset.name);
    EXPECT_EQ(options.Check(), "") << preset.name;
    EXPECT_EQ(options.preset, preset.name);
  }
  try {
    SynthPresetOptions("huge");
    FAIL() << "no error for an unknown preset";
  } catch (const InputError& error) {
    const std::string what = error.what();
    EXPECT_NE(what.find("huge"), std::string::npos) << what;
    EXPECT_NE(what.find("tiny, demo, paper"), std::string::npos) << what;
  }
  SynthOptions bad = SynthPresetOptions("tiny");
  bad.render.supersampling = 0;
  bad.trajectory.num_frames = 1;
  EXPECT_NE(bad.Check().find("render.supersampling"), std::string::npos);
  EXPECT_NE(bad.Check().find("trajectory.num_frames"), std::string::npos);
  EXPECT_THROW(MakeSyntheticDrive(bad, DefaultRig()), InputError);
}

TEST(SynthPresetTest, LoopLengthsAndSpacingFollowThePresets) {
  // paper: ~600 m closed loop, ~1550 frames, ~0.4 m apart; demo: 150-200 m, ~400 frames.
  const SyntheticDrive paper = MakeSyntheticDrive(SynthPresetOptions("paper"), DefaultRig());
  EXPECT_NEAR(paper.trajectory.path.Length(), 600.0, 60.0);
  EXPECT_NEAR(paper.NumFrames(), 1550u, 50u);
  EXPECT_NEAR(paper.trajectory.driven_length / paper.NumFrames(), 0.4, 0.06);
  const SyntheticDrive demo = MakeSyntheticDrive(SynthPresetOptions("demo"), DefaultRig());
  EXPECT_GE(demo.trajectory.path.Length(), 150.0);
  EXPECT_LE(demo.trajectory.path.Length(), 200.0);
  EXPECT_NEAR(demo.NumFrames(), 400u, 20u);
  EXPECT_GT(demo.scene.mesh.triangles.size(), 10000u);
}

TEST(SynthDriveTest, SameSeedSameBytesOtherSeedOtherBytes) {
  SynthWriteOptions write_options;
  write_options.progress = false;
  const fs::path a = TempFolder("seed_a"), b = TempFolder("seed_b"), c = TempFolder("seed_c");
  WriteSyntheticDrive(SmallOptions(7), DefaultRig(), a, write_options);
  WriteSyntheticDrive(SmallOptions(7), DefaultRig(), b, write_options);
  WriteSyntheticDrive(SmallOptions(8), DefaultRig(), c, write_options);
  const auto files_a = ReadTree(a), files_b = ReadTree(b), files_c = ReadTree(c);
  // rig.json, 6 x 3 images, poses, mesh, scene.
  EXPECT_EQ(files_a.size(), 1u + 6u * 3u + 3u);
  ASSERT_EQ(files_a.size(), files_b.size());
  for (const auto& [name, bytes] : files_a) {
    ASSERT_TRUE(files_b.count(name)) << name;
    EXPECT_TRUE(bytes == files_b.at(name)) << name << " differs between two runs";
  }
  EXPECT_FALSE(files_a.at("gt/mesh.ply") == files_c.at("gt/mesh.ply"));
  EXPECT_FALSE(files_a.at("images/cam0/000001.png") == files_c.at("images/cam0/000001.png"));
  EXPECT_FALSE(fs::exists(a.string() + ".partial"));
  // The written rig is the one rendered (scaled), and reads back.
  const Rig rig = ReadRigJson(a / "rig.json");
  EXPECT_EQ(rig.cameras.at(0).width, 192);
  EXPECT_EQ(cv::imread((a / "images/cam3/000002.png").string(), cv::IMREAD_UNCHANGED).cols, 192);
  for (const fs::path& folder : {a, b, c}) fs::remove_all(folder);
}

TEST(SynthDriveTest, RefusesNonEmptyOutputAndForceReplacesOnlyAnEarlierDrive) {
  SynthWriteOptions write_options;
  write_options.progress = false;
  const fs::path out = TempFolder("force");
  fs::create_directories(out);
  std::ofstream(out / "keep.txt") << "old";
  EXPECT_THROW(WriteSyntheticDrive(SmallOptions(3), DefaultRig(), out, write_options), InputError);
  EXPECT_TRUE(fs::exists(out / "keep.txt"));
  // A folder of the user's is not replaced, even with force.
  write_options.force = true;
  EXPECT_THROW(WriteSyntheticDrive(SmallOptions(3), DefaultRig(), out, write_options), InputError);
  EXPECT_TRUE(fs::exists(out / "keep.txt"));
  EXPECT_FALSE(fs::exists(out.string() + ".partial"));
  fs::remove(out / "keep.txt");
  // An earlier drive is, at the end, and a user's DRIVE.replaced stays untouched.
  write_options.force = false;
  WriteSyntheticDrive(SmallOptions(3), DefaultRig(), out, write_options);
  const fs::path users = out.string() + ".replaced";
  fs::create_directories(users);
  std::ofstream(users / "keep.txt") << "mine";
  write_options.force = true;
  WriteSyntheticDrive(SmallOptions(4), DefaultRig(), out, write_options);
  EXPECT_TRUE(fs::exists(out / "gt" / "scene.json"));
  EXPECT_FALSE(fs::exists(out.string() + ".partial"));
  EXPECT_FALSE(fs::exists(out.string() + ".replaced1"));
  EXPECT_TRUE(fs::exists(users / "keep.txt"));
  fs::remove_all(out);
  fs::remove_all(users);
}

TEST_F(TinyDriveTest, HitsReprojectToTheirPixelAndLieOnTheWrittenMesh) {
  const SyntheticDrive drive = MakeSyntheticDrive(SynthPresetOptions("tiny"), DefaultRig());
  const SceneRenderer renderer(drive.scene, drive.options.seed, drive.options.render);
  const TriangleMesh mesh = ReadPlyMesh(*folder_ / "gt" / "mesh.ply");
  ASSERT_EQ(mesh.triangles.size(), drive.scene.mesh.triangles.size());
  ASSERT_EQ(summary_->triangles, mesh.triangles.size());
  std::mt19937 rng(12345);
  int hits = 0, facing = 0, samples = 0;
  double worst_reprojection = 0, worst_distance = 0;
  for (int i = 0; i < 300; ++i) {
    const size_t frame = rng() % drive.NumFrames();
    const size_t camera_index = rng() % 5;  // side cameras: mostly hits
    const Camera& camera = drive.rig.cameras[camera_index];
    const Eigen::Vector2d pixel(
        std::uniform_real_distribution<double>(-0.5, camera.width - 0.5)(rng),
        std::uniform_real_distribution<double>(-0.5, camera.height - 0.5)(rng));
    const Rigid3d world_from_cam = drive.WorldFromCamera(frame, camera_index);
    ++samples;
    const auto hit = renderer.CastPixel(camera, world_from_cam, pixel);
    if (!hit) continue;
    ++hits;
    Eigen::Vector2d reprojected;
    ASSERT_TRUE(camera.Project(world_from_cam.Inverse() * hit->point, &reprojected));
    worst_reprojection = std::max(worst_reprojection, (reprojected - pixel).norm());
    if (i < 120) worst_distance = std::max(worst_distance, DistanceToMesh(mesh, hit->point));
    // Triangles face the free space the camera sees from.
    if (drive.scene.normals[hit->triangle].dot(hit->point - world_from_cam.translation) < 0) {
      ++facing;
    }
  }
  EXPECT_GT(hits, samples / 2);
  EXPECT_LT(worst_reprojection, 0.01);
  EXPECT_LT(worst_distance, 1e-4);
  EXPECT_GE(facing, hits * 99 / 100);
}

// gt/mesh.ply labels every triangle with its surface (the index in gt/scene.json's
// mesh_labels): the labels read back are the scene's surfaces, and they say what the geometry
// is: the road lies flat on the ground, a pole's triangles are narrow and upright, a car's are
// below 2 m.
TEST_F(TinyDriveTest, TheMeshLabelsEveryTriangleWithItsSurface) {
  const SyntheticDrive drive = MakeSyntheticDrive(SynthPresetOptions("tiny"), DefaultRig());
  const TriangleMesh mesh = ReadPlyMesh(*folder_ / "gt" / "mesh.ply");
  ASSERT_EQ(mesh.labels.size(), mesh.triangles.size());
  ASSERT_EQ(drive.scene.surfaces.size(), mesh.triangles.size());
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    ASSERT_EQ(mesh.labels[t], static_cast<uint8_t>(drive.scene.surfaces[t])) << t;
  }
  std::ifstream scene_file(*folder_ / "gt" / "scene.json");
  const nlohmann::json scene = nlohmann::json::parse(scene_file);
  EXPECT_EQ(scene.at("mesh_labels").get<std::vector<std::string>>(), synth::SurfaceNames());
  const std::vector<std::string>& names = synth::SurfaceNames();
  auto label_of = [&](const std::string& name) {
    return static_cast<uint8_t>(std::find(names.begin(), names.end(), name) - names.begin());
  };
  std::map<std::string, int> counted;
  double road_height = 0.0, pole_width = 0.0, pole_height = 0.0, car_top = 0.0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    Eigen::Vector3d lo = mesh.vertices[mesh.triangles[t][0]], hi = lo;
    for (int k = 1; k < 3; ++k) {
      lo = lo.cwiseMin(mesh.vertices[mesh.triangles[t][k]]);
      hi = hi.cwiseMax(mesh.vertices[mesh.triangles[t][k]]);
    }
    const std::string& name = names.at(mesh.labels[t]);
    ++counted[name];
    if (mesh.labels[t] == label_of("road")) {
      road_height = std::max({road_height, std::abs(lo.z()), std::abs(hi.z())});
    } else if (mesh.labels[t] == label_of("pole")) {
      pole_width = std::max({pole_width, hi.x() - lo.x(), hi.y() - lo.y()});
      pole_height = std::max(pole_height, hi.z() - lo.z());
    } else if (mesh.labels[t] == label_of("car")) {
      car_top = std::max(car_top, hi.z());
    }
  }
  for (const char* name : {"road", "wall", "pole", "car", "trim"}) {
    EXPECT_GT(counted[name], 0) << name;
  }
  EXPECT_LT(road_height, 0.01);
  EXPECT_LT(pole_width, 0.5);
  EXPECT_GT(pole_height, 2.0);
  EXPECT_GT(car_top, 1.0);
  EXPECT_LT(car_top, 2.0);
}

TEST_F(TinyDriveTest, SideImagesHaveManyHarrisCorners) {
  // "Default settings" of OpenCV's Harris: cv::goodFeaturesToTrack with useHarrisDetector=true,
  // k = 0.04, blockSize 3, qualityLevel 0.01, minDistance 1, no mask, maxCorners 100000.
  const Drive drive_folder = Drive::Open(*folder_);
  ASSERT_EQ(drive_folder.NumFrames(), 30u);
  int images = 0, rich = 0;
  for (size_t frame = 0; frame < drive_folder.NumFrames(); ++frame) {
    for (size_t camera = 0; camera < 5; ++camera) {
      const cv::Mat image = drive_folder.LoadGray(frame, camera);
      std::vector<cv::Point2f> corners;
      cv::goodFeaturesToTrack(image, corners, 100000, 0.01, 1.0, cv::noArray(), 3, true, 0.04);
      ++images;
      if (corners.size() > 300) ++rich;
    }
  }
  EXPECT_GE(rich * 100, images * 95) << rich << " of " << images << " images";
}

TEST_F(TinyDriveTest, PosesAreWrittenAndTheLoopCloses) {
  const std::vector<StampedPose> poses = ReadTum(*folder_ / "gt" / "poses.tum");
  const SyntheticDrive drive = MakeSyntheticDrive(SynthPresetOptions("tiny"), DefaultRig());
  ASSERT_EQ(poses.size(), drive.NumFrames());
  double spacing = 0;
  for (size_t f = 0; f < poses.size(); ++f) {
    EXPECT_NEAR(poses[f].timestamp, f / 15.0, 1e-9);
    EXPECT_LT((poses[f].world_from_rig.translation - drive.trajectory.world_from_rig[f].translation)
                  .norm(),
              1e-6);
    EXPECT_NEAR(poses[f].world_from_rig.translation.z(), 4.0, 0.05);  // rig ~4 m above the road
    if (f > 0) {
      const double step =
          (poses[f].world_from_rig.translation - poses[f - 1].world_from_rig.translation).norm();
      EXPECT_GT(step, 0.5);
      spacing = std::max(spacing, step);
    }
  }
  // The drive ends past its start: the last poses pass within a frame spacing of the first one
  // and the last one is a few metres from it.
  const Eigen::Vector3d start = poses.front().world_from_rig.translation;
  double closest = std::numeric_limits<double>::infinity();
  for (size_t f = poses.size() - 4; f < poses.size(); ++f) {
    closest = std::min(closest, (poses[f].world_from_rig.translation - start).norm());
  }
  EXPECT_LT(closest, spacing);
  EXPECT_LT((poses.back().world_from_rig.translation - start).norm(), 10.0);
  EXPECT_GT(drive.trajectory.driven_length, drive.trajectory.path.Length());
  // The path itself is closed and continuous.
  Eigen::Vector2d p0, p1, t0, t1;
  double k0, k1;
  drive.trajectory.path.Evaluate(0.0, &p0, &t0, &k0);
  drive.trajectory.path.Evaluate(drive.trajectory.path.Length() - 1e-9, &p1, &t1, &k1);
  EXPECT_LT((p0 - p1).norm(), 1e-6);
  EXPECT_LT((t0 - t1).norm(), 1e-6);
  for (double s = 0; s < drive.trajectory.path.Length(); s += 0.05) {
    drive.trajectory.path.Evaluate(s, &p0, &t0, &k0);
    drive.trajectory.path.Evaluate(s + 0.05, &p1, &t1, &k1);
    EXPECT_NEAR((p1 - p0).norm(), 0.05, 1e-3) << s;
  }
}

}  // namespace
}  // namespace omni::synth

namespace omni::synth {
namespace {

// --colour: each pixel is the grey render times its tint, channel by channel, with the same
// noise: the channel whose tint is 1 equals the grey pixel exactly, the others are the grey
// level scaled by their tint within rounding; walls come out coloured, roads and the sky grey.
TEST(SynthColourTest, ColourImagesAreTheGreyImageTimesTheTintOfEachBuilding) {
  const SyntheticDrive drive = MakeSyntheticDrive(SynthPresetOptions("tiny"), DefaultRig());
  SynthRenderOptions colour_options = drive.options.render;
  colour_options.colour = true;
  colour_options.supersampling = 1;  // one ray per pixel: one tint per pixel
  SynthRenderOptions grey_options = colour_options;
  grey_options.colour = false;
  grey_options.noise_sigma = 0.0;  // without noise the tint scales the level itself
  colour_options.noise_sigma = 0.0;
  const SceneRenderer colour(drive.scene, drive.options.seed, colour_options);
  const SceneRenderer grey(drive.scene, drive.options.seed, grey_options);
  const size_t frame = 3, camera_index = 1;  // a side camera: facades
  const Camera& camera = drive.rig.cameras[camera_index];
  const Rigid3d world_from_cam = drive.WorldFromCamera(frame, camera_index);
  const cv::Mat c = colour.Render(camera, world_from_cam, 7, 1.0);
  const cv::Mat g = grey.Render(camera, world_from_cam, 7, 1.0);
  ASSERT_EQ(c.type(), CV_8UC3);
  ASSERT_EQ(g.type(), CV_8UC1);
  ASSERT_EQ(c.size(), g.size());
  size_t tinted = 0, pixels = 0, wall_pixels = 0, wall_tinted = 0, mismatches = 0, grey_tinted = 0;
  for (int y = 0; y < c.rows; y += 3) {
    for (int x = 0; x < c.cols; x += 3) {
      ++pixels;
      const cv::Vec3b bgr = c.at<cv::Vec3b>(y, x);
      const int level = g.at<uint8_t>(y, x);
      // The pixel's own tint, from what its centre ray hits.
      const auto hit = colour.CastPixel(camera, world_from_cam, Eigen::Vector2d(x, y));
      Eigen::Vector3d tint = Eigen::Vector3d::Ones();
      if (hit) {
        tint = colour.Tint(drive.scene.objects[hit->triangle] * 16u +
                           static_cast<uint32_t>(drive.scene.surfaces[hit->triangle]));
      }
      // level = round(255 v), channel = round(255 v tint): within one level of tint · level
      // (unless the grey level is clamped at 255). The single ray of CastPixel and the packet
      // rays of Render may part at a silhouette: a few pixels get another object's tint.
      bool matches = true;
      for (int k = 0; k < 3 && level < 255; ++k) {
        matches = matches && std::abs(bgr[2 - k] - tint[k] * level) <= 1.0 + 1e-9;
      }
      mismatches += matches ? 0 : 1;
      const bool is_tinted = bgr[0] != bgr[1] || bgr[1] != bgr[2];
      tinted += is_tinted ? 1 : 0;
      if (hit && drive.scene.surfaces[hit->triangle] == Surface::kWall) {
        ++wall_pixels;
        wall_tinted += is_tinted ? 1 : 0;
      } else if (!hit || drive.scene.surfaces[hit->triangle] == Surface::kRoad) {
        grey_tinted += matches && is_tinted ? 1 : 0;
      }
    }
  }
  EXPECT_LT(mismatches, pixels / 1000 + 1) << mismatches << " of " << pixels;
  EXPECT_GT(wall_pixels, pixels / 10);
  EXPECT_GT(wall_tinted, wall_pixels * 9 / 10);
  EXPECT_GT(tinted, pixels / 10);
  EXPECT_EQ(grey_tinted, 0u) << "road or sky pixels tinted";
}

}  // namespace
}  // namespace omni::synth
