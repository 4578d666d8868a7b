#include "synth/drive_writer.h"

#include <spdlog/spdlog.h>
#include <tbb/parallel_for.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/ply.h"
#include "calib/rig_io.h"
#include "calib/tum.h"
#include "synth/hash.h"
#include "synth/renderer.h"

namespace omni::synth {
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

Rig ScaleRig(const Rig& rig, double scale) {
  Rig scaled = rig;
  if (scale == 1.0) return scaled;
  for (Camera& camera : scaled.cameras) {
    const int width = std::max(8, static_cast<int>(std::lround(camera.width * scale)));
    const int height = std::max(8, static_cast<int>(std::lround(camera.height * scale)));
    const double sx = static_cast<double>(width) / camera.width;
    const double sy = static_cast<double>(height) / camera.height;
    camera.params[0] *= sx;
    camera.params[1] *= sy;
    camera.params[2] = (camera.params[2] + 0.5) * sx - 0.5;
    camera.params[3] = (camera.params[3] + 0.5) * sy - 0.5;
    camera.width = width;
    camera.height = height;
  }
  return scaled;
}

double Seconds(Clock::time_point since) {
  return std::chrono::duration<double>(Clock::now() - since).count();
}

}  // namespace

Rigid3d SyntheticDrive::WorldFromCamera(size_t frame, size_t camera) const {
  return trajectory.world_from_rig.at(frame) * rig.cameras.at(camera).cam_from_rig.Inverse();
}

double SyntheticDrive::FrameTimestamp(size_t frame) const {
  return frame / options.trajectory.frame_rate;
}

uint64_t SyntheticDrive::ImageSeed(size_t frame, size_t camera) const {
  return Hash(options.seed, 0x1A6E, frame, camera);
}

SyntheticDrive MakeSyntheticDrive(const SynthOptions& options, const Rig& rig) {
  if (const std::string problem = options.Check(); !problem.empty()) {
    throw InputError("", "synth options", problem);
  }
  if (const std::string problem = rig.Check(); !problem.empty()) {
    throw InputError("", "rig", problem);
  }
  SyntheticDrive drive;
  drive.options = options;
  drive.rig = ScaleRig(rig, options.render.image_scale);
  drive.scene = BuildCity(options.city, options.seed);
  drive.trajectory = MakeTrajectory(drive.scene.streets, options.trajectory, options.seed);
  for (size_t c = 0; c < drive.rig.NumCameras(); ++c) {
    drive.camera_gains.push_back(1.0 + options.render.camera_gain_spread *
                                           Uniform(Hash(options.seed, 0x6A1, c), -1, 1));
    // Exactly 1 and 0 without exposure differences, so that such drives keep their bytes.
    const double spread = options.render.exposure_spread, offset = options.render.exposure_offset;
    drive.exposure_gains.push_back(
        spread > 0 ? 1.0 + spread * Uniform(Hash(options.seed, 0xE7905E, c), -1, 1) : 1.0);
    drive.exposure_offsets.push_back(
        offset > 0 ? offset * Uniform(Hash(options.seed, 0x0FF5E7, c), -1, 1) : 0.0);
  }
  const size_t step = static_cast<size_t>(options.trajectory.frame_step);
  for (size_t f = 0; f < drive.NumFrames(); f += step) drive.written_frames.push_back(f);
  return drive;
}

std::string SynthFrameName(size_t frame) {
  char name[32];
  std::snprintf(name, sizeof(name), "%06zu", frame);
  return name;
}

std::string SceneJson(const SyntheticDrive& drive) {
  using nlohmann::json;
  const SynthOptions& o = drive.options;
  const SynthCityOptions& c = o.city;
  const SynthTrajectoryOptions& t = o.trajectory;
  const SynthRenderOptions& r = o.render;
  json j;
  j["generator"] = "omnisculpt synth";
  j["preset"] = o.preset;
  j["seed"] = o.seed;
  j["world_frame"] = "metres, z up, road surface at z = 0";
  j["rig"] = {
      {"name", drive.rig.name},
      {"cameras", drive.rig.NumCameras()},
      {"central_flag_in_rig_json", drive.rig.central},
      {"rendering",
       "non-central: every camera is rendered from its own centre, cam_from_rig of rig.json"},
      {"camera_gains", drive.camera_gains}};
  const bool exposure = r.exposure_spread > 0 || r.exposure_offset > 0;
  if (exposure) {
    j["rig"]["exposure_gains"] = drive.exposure_gains;
    j["rig"]["exposure_offsets"] = drive.exposure_offsets;
  }
  j["city"] = {{"block_size_x", c.block_size_x},
               {"block_size_y", c.block_size_y},
               {"block_jitter", c.block_jitter},
               {"loop_blocks_x", c.loop_blocks_x},
               {"loop_blocks_y", c.loop_blocks_y},
               {"ring_blocks", c.ring_blocks},
               {"road_half_width", c.road_half_width},
               {"sidewalk_width", c.sidewalk_width},
               {"kerb_height", c.kerb_height},
               {"building_depth", c.building_depth},
               {"building_min_width", c.building_min_width},
               {"building_max_width", c.building_max_width},
               {"building_min_height", c.building_min_height},
               {"building_max_height", c.building_max_height},
               {"floor_height_min", c.floor_height_min},
               {"floor_height_max", c.floor_height_max},
               {"window_depth", c.window_depth},
               {"balcony_probability", c.balcony_probability},
               {"cornice_depth", c.cornice_depth},
               {"pole_spacing", c.pole_spacing},
               {"tree_spacing", c.tree_spacing},
               {"parked_car_spacing", c.parked_car_spacing},
               {"tree_crown_subdivisions", c.tree_crown_subdivisions},
               {"street_x_lines", drive.scene.streets.x_lines},
               {"street_y_lines", drive.scene.streets.y_lines}};
  const LoopPath& path = drive.trajectory.path;
  j["trajectory"] = {{"num_frames", t.num_frames},
                     {"frame_rate", t.frame_rate},
                     {"rig_height", t.rig_height},
                     {"lane_offset", t.lane_offset},
                     {"corner_radius", t.corner_radius},
                     {"overlap", t.overlap},
                     {"speed_variation", t.speed_variation},
                     {"speed_cycles", t.speed_cycles},
                     {"pitch_amplitude_deg", t.pitch_amplitude_deg},
                     {"roll_amplitude_deg", t.roll_amplitude_deg},
                     {"bounce_amplitude", t.bounce_amplitude},
                     {"suspension_period", t.suspension_period},
                     {"loop_rectangle", {path.x0, path.y0, path.x1, path.y1}},
                     {"loop_corner_radius", path.radius},
                     {"loop_length", path.Length()},
                     {"driven_length", drive.trajectory.driven_length},
                     {"mean_frame_spacing",
                      drive.trajectory.driven_length / std::max<size_t>(1, drive.NumFrames() - 1)},
                     {"direction", "counter-clockwise seen from above, right lane"}};
  const bool stepped = t.frame_step > 1;
  if (stepped) {
    // Only with a frame step, so that the drives without one keep their bytes.
    j["trajectory"]["frame_step"] = t.frame_step;
    j["trajectory"]["frames_written"] = drive.written_frames.size();
  }
  j["render"] = {{"supersampling", r.supersampling},
                 {"adaptive", r.adaptive},
                 {"refine_contrast", r.refine_contrast},
                 {"ambient", r.ambient},
                 {"diffuse", r.diffuse},
                 {"sun_direction", r.sun_direction},
                 {"camera_gain_spread", r.camera_gain_spread},
                 {"noise_sigma", r.noise_sigma},
                 {"png_compression", r.png_compression},
                 {"image_scale", r.image_scale},
                 {"sky_horizon", r.sky_horizon},
                 {"sky_zenith", r.sky_zenith},
                 {"sky", "no hit: gradient from sky_horizon to sky_zenith by elevation"},
                 {"renderer", "Embree 3, rays from calib Camera::Unproject"}};
  if (exposure) {
    j["render"]["exposure_spread"] = r.exposure_spread;
    j["render"]["exposure_offset"] = r.exposure_offset;
  }
  j["scene"] = {{"triangles", drive.scene.mesh.triangles.size()},
                {"vertices", drive.scene.mesh.vertices.size()},
                {"buildings", drive.scene.num_buildings},
                {"poles", drive.scene.num_poles},
                {"trees", drive.scene.num_trees},
                {"parked_cars", drive.scene.num_cars}};
  // gt/mesh.ply's face property label, the index of the triangle's surface in this list.
  j["mesh_labels"] = synth::SurfaceNames();
  const std::string pixels = r.colour ? "8-bit colour" : "8-bit grey";
  j["files"] = {{"images", "images/<camera>/<frame>.png, " + pixels + ", frames 000000..."},
                {"poses", "gt/poses.tum: world_from_rig, timestamp = frame / frame_rate"},
                {"mesh",
                 "gt/mesh.ply: every rendered triangle, metres, facing free space; its "
                 "face property label indexes mesh_labels"}};
  if (stepped) {
    j["files"]["images"] = "images/<camera>/<frame>.png, " + pixels +
                           ", one trajectory frame in frame_step, named by its trajectory index";
    j["files"]["poses"] =
        "gt/poses.tum: world_from_rig of the frames written, timestamp = "
        "trajectory index / frame_rate";
    j["files"]["frames"] = "frames.csv: frame,camera,timestamp_s, one row per image";
  }
  return j.dump(2) + "\n";
}

namespace {

// The file that marks DRIVE.partial as synth's own (an interrupted run leaves it).
constexpr const char* kPartialMarker = "INCOMPLETE";

SynthSummary WriteStagedDrive(const SynthOptions& options, const SyntheticDrive& drive,
                              const fs::path& out, const fs::path& staging,
                              const SynthWriteOptions& write_options,
                              std::chrono::steady_clock::time_point start);

}  // namespace

SynthSummary WriteSyntheticDrive(const SynthOptions& options, const Rig& rig,
                                 const fs::path& out_argument,
                                 const SynthWriteOptions& write_options) {
  // "drive/" names the folder "drive": the staging folder must be its sibling.
  fs::path out = out_argument.lexically_normal();
  if (!out.empty() && !out.has_filename()) out = out.parent_path();
  const Clock::time_point start = Clock::now();
  std::error_code ec;
  if (out.empty() || out == "." || out == "..") {
    throw InputError(out_argument, "--out", "expected the path of a new folder");
  }
  const bool exists = fs::exists(out, ec);
  const bool empty_folder = fs::is_directory(out, ec) && fs::is_empty(out, ec);
  if (exists && !write_options.force && !empty_folder) {
    throw InputError(out, "--out", "exists and is not empty (--force replaces an earlier drive)");
  }
  if (exists && !empty_folder && !fs::exists(out / "gt" / "scene.json", ec)) {
    throw InputError(out, "--out",
                     "is not a drive written by synth (no gt/scene.json): not replaced, even with "
                     "--force");
  }
  fs::path staging = out;
  staging += ".partial";
  if (fs::exists(staging, ec)) {
    if (!fs::exists(staging / kPartialMarker, ec)) {
      throw InputError(staging, "--out",
                       "exists but is not left by an interrupted synth (no " +
                           std::string(kPartialMarker) + "); move it away");
    }
    fs::remove_all(staging, ec);
  }
  const SyntheticDrive drive = MakeSyntheticDrive(options, rig);

  fs::create_directories(staging, ec);
  if (ec) throw InputError(out, "--out", "cannot create " + staging.string() + ": " + ec.message());
  WriteTextFileAtomically(staging / kPartialMarker,
                          "omnisculpt synth is writing this folder; it is renamed to " +
                              out.filename().string() + " when complete.\n");
  try {
    return WriteStagedDrive(options, drive, out, staging, write_options, start);
  } catch (...) {
    // A failed run leaves nothing behind (a killed one leaves DRIVE.partial with its marker,
    // which the next run removes).
    fs::remove_all(staging, ec);
    throw;
  }
}

namespace {

SynthSummary WriteStagedDrive(const SynthOptions& options, const SyntheticDrive& drive,
                              const fs::path& out, const fs::path& staging,
                              const SynthWriteOptions& write_options,
                              std::chrono::steady_clock::time_point start) {
  std::error_code ec;
  for (const Camera& camera : drive.rig.cameras) {
    fs::create_directories(staging / "images" / camera.name, ec);
    if (ec)
      throw InputError(out, "--out", "cannot create " + staging.string() + ": " + ec.message());
  }
  fs::create_directories(staging / "gt", ec);
  if (ec) throw InputError(out, "--out", "cannot create " + staging.string() + ": " + ec.message());

  WriteRigJson(drive.rig, staging / "rig.json");
  std::vector<StampedPose> poses;
  for (const size_t f : drive.written_frames) {
    poses.push_back({drive.FrameTimestamp(f), drive.trajectory.world_from_rig[f]});
  }
  WriteTum(poses, staging / "gt" / "poses.tum");
  if (options.trajectory.frame_step > 1) {
    // The drive's own clock (calib/drive.h): the same timestamps as gt/poses.tum.
    std::string csv = "frame,camera,timestamp_s\n";
    for (const size_t f : drive.written_frames) {
      char timestamp[64];
      std::snprintf(timestamp, sizeof(timestamp), "%.9f", drive.FrameTimestamp(f));
      for (const Camera& camera : drive.rig.cameras) {
        csv += SynthFrameName(f) + "," + camera.name + "," + timestamp + "\n";
      }
    }
    WriteTextFileAtomically(staging / "frames.csv", csv);
  }
  WritePlyMesh(drive.scene.mesh, staging / "gt" / "mesh.ply");
  WriteTextFileAtomically(staging / "gt" / "scene.json", SceneJson(drive));

  const SceneRenderer renderer(drive.scene, options.seed, options.render);
  const size_t num_cameras = drive.rig.NumCameras();
  const size_t num_frames = drive.written_frames.size();
  const size_t num_images = num_frames * num_cameras;
  if (write_options.progress)
    spdlog::info("synth: {} frames x {} cameras, {} triangles, loop {:.1f} m -> {}", num_frames,
                 num_cameras, drive.scene.mesh.triangles.size(), drive.trajectory.path.Length(),
                 out.string());
  const Clock::time_point render_start = Clock::now();
  std::atomic<size_t> done{0};
  std::mutex error_mutex;
  std::string error;
  const std::vector<int> png_params = {cv::IMWRITE_PNG_COMPRESSION, options.render.png_compression};
  tbb::parallel_for(size_t{0}, num_images, [&](size_t index) {
    const size_t frame = drive.written_frames[index / num_cameras], camera = index % num_cameras;
    const cv::Mat image = renderer.Render(
        drive.rig.cameras[camera], drive.WorldFromCamera(frame, camera),
        drive.ImageSeed(frame, camera), drive.RenderGain(camera), drive.exposure_offsets[camera]);
    const fs::path path =
        staging / "images" / drive.rig.cameras[camera].name / (SynthFrameName(frame) + ".png");
    bool written = false;
    try {
      written = cv::imwrite(path.string(), image, png_params);
    } catch (const cv::Exception&) {
    }
    if (!written) {
      std::lock_guard<std::mutex> lock(error_mutex);
      error = path.string();
      return;
    }
    const size_t count = ++done;
    const size_t step = std::max<size_t>(1, num_images / 10);
    if (write_options.progress && count % step == 0) {
      const double seconds = Seconds(render_start);
      spdlog::info("synth: {}/{} images, {:.1f} images/s, ETA {:.0f} s", count, num_images,
                   count / seconds, (num_images - count) * seconds / count);
    }
  });
  if (!error.empty()) throw InputError(error, "", "cannot write the image");

  SynthSummary summary;
  summary.render_seconds = Seconds(render_start);
  // Publish: replace the old output only now.
  fs::remove(staging / kPartialMarker, ec);
  if (fs::exists(out, ec)) {
    // A name nobody uses: only the checked earlier drive is ever removed.
    fs::path old = out;
    old += ".replaced";
    for (int k = 1; fs::exists(old, ec); ++k) {
      old = out;
      old += ".replaced" + std::to_string(k);
    }
    fs::rename(out, old, ec);
    if (ec) throw InputError(out, "--out", "cannot replace: " + ec.message());
    fs::rename(staging, out, ec);
    if (ec)
      throw InputError(out, "--out", "cannot rename " + staging.string() + ": " + ec.message());
    fs::remove_all(old, ec);
  } else {
    fs::rename(staging, out, ec);
    if (ec)
      throw InputError(out, "--out", "cannot rename " + staging.string() + ": " + ec.message());
  }
  summary.frames = num_frames;
  summary.cameras = num_cameras;
  summary.triangles = drive.scene.mesh.triangles.size();
  summary.loop_length = drive.trajectory.path.Length();
  summary.driven_length = drive.trajectory.driven_length;
  summary.rays = renderer.RaysCast();
  summary.total_seconds = Seconds(start);
  return summary;
}

}  // namespace

}  // namespace omni::synth
