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
#include "synth/synth_options.h"

namespace omni {
namespace {

struct SynthCommandOptions {
  std::string preset = "demo";
  uint64_t seed = 1;
  int frames = 0;         // 0: the preset's
  int supersampling = 0;  // 0: the preset's
  std::string rig_path;
  std::string out;
  bool force = false;
  bool list_presets = false;
};

void RunSynth(const SynthCommandOptions& command, const GlobalOptions& global) {
  if (command.list_presets) {
    for (const SynthPreset& preset : SynthPresets()) {
      std::printf("%-6s %s\n", preset.name.c_str(), preset.description.c_str());
    }
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
  const Rig rig = command.rig_path.empty() ? DefaultRig() : ReadRigJson(command.rig_path);
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
  synth->add_option("--rig", command->rig_path, "rig.json (default: the built-in ladybug-like)");
  synth->add_option("--out", command->out, "Output drive folder");
  synth->add_flag("--force", command->force, "Replace a non-empty --out (at the end only)");
  synth->add_flag("--list-presets", command->list_presets, "Describe the presets and exit");
  synth->callback([command, &global] { RunSynth(*command, global); });
}

}  // namespace omni
