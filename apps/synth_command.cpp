// `omnisculpt synth`: a synthetic city drive with exact ground truth.

#include <spdlog/spdlog.h>

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "apps/commands.h"
#include "apps/default_rig.h"
#include "calib/error.h"
#include "calib/rig_io.h"
#include "synth/drive_writer.h"
#include "synth/rig_presets.h"
#include "synth/synth_options.h"

namespace omni {
namespace {

struct SynthCommandOptions {
  std::string preset = "demo";
  uint64_t seed = 1;
  int frames = 0;         // 0: the preset's
  int supersampling = 0;  // 0: the preset's
  std::string rig_path;
  std::string rig_preset;  // empty: ladybug (or --rig)
  double image_scale = 0;  // 0: the preset's
  double rig_height = 0;   // 0: the preset's
  int frame_step = 1;
  double exposure_spread = 0;
  double exposure_offset = 0;
  bool colour = false;
  std::string out;
  bool force = false;
  bool list_presets = false;
  bool list_rig_presets = false;
};

void PrintRigPresets() {
  for (const synth::RigPreset& preset : synth::RigPresets()) {
    std::printf("%-8s %s (data/rigs/%s)\n", preset.name.c_str(), preset.description.c_str(),
                preset.file.c_str());
  }
}

void RunSynth(const SynthCommandOptions& command, const GlobalOptions& global) {
  if (command.list_presets) {
    for (const SynthPreset& preset : SynthPresets()) {
      std::printf("%-6s %s\n", preset.name.c_str(), preset.description.c_str());
    }
    std::printf("\nrig presets (--rig-preset):\n");
    PrintRigPresets();
    return;
  }
  if (command.list_rig_presets) {
    PrintRigPresets();
    return;
  }
  SynthOptions options = SynthPresetOptions(command.preset);
  if (command.out.empty()) throw InputError("", "--out", "an output folder is required");
  options.seed = command.seed;
  if (command.frames != 0) {
    if (command.frames < 2) throw InputError("", "--frames", "must be at least 2");
    options.trajectory.num_frames = command.frames;
  }
  if (command.supersampling != 0) options.render.supersampling = command.supersampling;
  if (command.image_scale != 0) options.render.image_scale = command.image_scale;
  if (command.rig_height != 0) {
    if (!(command.rig_height > 0.5) || !(command.rig_height < 50.0))
      throw InputError("", "--rig-height", "must be above 0.5 m and below 50 m");
    options.trajectory.rig_height = command.rig_height;
  }
  if (command.frame_step < 1) throw InputError("", "--frame-step", "must be at least 1");
  options.trajectory.frame_step = command.frame_step;
  if (command.exposure_spread < 0 || command.exposure_spread >= 0.9)
    throw InputError("", "--exposure-spread", "must be in [0, 0.9)");
  options.render.exposure_spread = command.exposure_spread;
  if (command.exposure_offset < 0 || command.exposure_offset > 64)
    throw InputError("", "--exposure-offset", "must be in [0, 64] grey levels");
  options.render.exposure_offset = command.exposure_offset;
  options.render.colour = command.colour;
  const Rig rig = !command.rig_path.empty()     ? ReadRigJson(command.rig_path)
                  : !command.rig_preset.empty() ? synth::RigPresetRig(command.rig_preset)
                                                : DefaultRig();
  synth::SynthWriteOptions write_options;
  write_options.force = command.force;
  write_options.progress = !global.quiet;
  const synth::SynthSummary summary =
      synth::WriteSyntheticDrive(options, rig, command.out, write_options);
  spdlog::info(
      "synth: wrote {} ({} frames x {} cameras, {} triangles, loop {:.1f} m, driven {:.1f} m) in "
      "{:.1f} s; rendering {:.1f} s, {:.2f} Mrays/s, {:.1f} frames/s",
      command.out, summary.frames, summary.cameras, summary.triangles, summary.loop_length,
      summary.driven_length, summary.total_seconds, summary.render_seconds,
      summary.rays / std::max(1e-9, summary.render_seconds) / 1e6,
      summary.frames / std::max(1e-9, summary.render_seconds));
}

}  // namespace

void RegisterSynthCommand(CLI::App& app, const GlobalOptions& global) {
  auto command = std::make_shared<SynthCommandOptions>();
  CLI::App* synth = app.add_subcommand(
      "synth",
      "Ray-trace a synthetic textured city seen by the rig along a closed loop, with "
      "exact ground truth (poses, mesh)");
  synth->add_option("--preset", command->preset, "tiny | demo | paper | short (see --list-presets)")
      ->capture_default_str();
  synth->add_option("--seed", command->seed, "Seed of the city, textures and noise")
      ->capture_default_str();
  synth->add_option("--frames", command->frames, "Number of frames (default: the preset's)");
  synth->add_option("--supersampling", command->supersampling,
                    "Rays per pixel side at edges (default: the preset's, 3)");
  CLI::Option* rig_option = synth->add_option("--rig", command->rig_path,
                                              "rig.json (default: the built-in ladybug-like)");
  synth
      ->add_option("--rig-preset", command->rig_preset,
                   "Built-in rig: ladybug (the default) | pinhole | car | fisheye5 (see "
                   "--list-rig-presets)")
      ->excludes(rig_option);
  synth->add_option("--image-scale", command->image_scale,
                    "Scale every camera's size and intrinsics, e.g. 0.25 for quick car drives "
                    "(default: the preset's, 1)");
  synth->add_option("--rig-height", command->rig_height,
                    "Height of the rig's origin above the road, metres (default: the preset's, "
                    "4: a mast as the paper's; a car's roof is about 2)");
  synth
      ->add_option("--frame-step", command->frame_step,
                   "Write one frame in K of the trajectory, named by its trajectory index, with "
                   "a frames.csv of the capture times (low frame rates)")
      ->capture_default_str();
  synth
      ->add_option("--exposure-spread", command->exposure_spread,
                   "Per-camera exposure gain drawn in [1-E, 1+E] from the seed")
      ->capture_default_str();
  synth
      ->add_option("--exposure-offset", command->exposure_offset,
                   "Per-camera exposure offset drawn in [-O, O] grey levels from the seed")
      ->capture_default_str();
  synth->add_flag("--colour", command->colour,
                  "Colour images: each building's walls, doors and trim tinted by a colour from "
                  "the seed (roads, glass, roofs and the sky stay grey)");
  synth->add_option("--out", command->out, "Output drive folder");
  synth->add_flag("--force", command->force,
                  "Replace an earlier drive in --out (one with gt/scene.json), at the end only");
  synth->add_flag("--list-presets", command->list_presets,
                  "Describe the drive presets and the rig presets and exit");
  synth->add_flag("--list-rig-presets", command->list_rig_presets,
                  "Describe the rig presets and exit");
  synth->callback([command, &global] { RunSynth(*command, global); });
}

}  // namespace omni
