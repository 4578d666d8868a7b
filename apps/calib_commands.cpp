// `omnisculpt calib import` and `omnisculpt calib show`: thin layers over calib/import.h,
// calib/rig_io.h and calib/rig_report.h.

#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include "apps/commands.h"
#include "apps/default_rig.h"
#include "apps/output_folder.h"
#include "calib/error.h"
#include "calib/import.h"
#include "calib/rig_io.h"
#include "calib/rig_report.h"
#include "synth/rig_presets.h"

namespace omni {
namespace {

struct CalibImportArgs {
  std::string format;
  std::filesystem::path input;
  std::filesystem::path output;
  bool upright = false;
  bool force = false;
};

struct CalibShowArgs {
  std::filesystem::path rig;
  bool use_default = false;
  std::string rig_preset;  // a built-in rig of synth/rig_presets.h
};

void RunCalibImport(const CalibImportArgs& args) {
  if (!std::filesystem::exists(args.input)) throw InputError(args.input, "", "no such file");
  if (!std::filesystem::is_regular_file(args.input)) {
    throw InputError(args.input, "", "not a regular file");
  }
  if (args.upright && args.format != "ladybug") {
    throw InputError("", "--upright", "only applies to --format ladybug");
  }
  CheckOutputFile(args.output, args.force, "--out");

  Rig rig;
  if (args.format == "kalibr") {
    rig = ImportKalibr(args.input);
  } else {
    LadybugImportOptions options;
    options.upright = args.upright;
    rig = ImportLadybug(args.input, options);
  }
  WriteRigJson(rig, args.output);

  std::printf("imported %zu camera%s from %s (%s) to %s: %s, max centre offset %.3f m\n",
              rig.NumCameras(), rig.NumCameras() == 1 ? "" : "s", args.input.string().c_str(),
              args.format.c_str(), args.output.string().c_str(),
              rig.central ? "central" : "non-central", rig.MaxCenterOffset());
  if (args.format == "ladybug") {
    std::printf(
        "note: the Ladybug cameras were imported as pinhole, since the .conf describes the "
        "rectified images%s\n",
        args.upright ? " (rotated upright by 90 degrees)" : "");
  }
}

void RunCalibShow(const CalibShowArgs& args) {
  Rig rig;
  if (args.use_default) {
    rig = DefaultRig();
  } else if (!args.rig_preset.empty()) {
    rig = synth::RigPresetRig(args.rig_preset);
  } else {
    if (args.rig.empty()) throw InputError("", "RIG", "give a rig.json file or --default");
    if (!std::filesystem::is_regular_file(args.rig)) throw InputError(args.rig, "", "no such file");
    rig = ReadRigJson(args.rig);
  }
  std::fputs(DescribeRig(rig).c_str(), stdout);
}

}  // namespace

void RegisterCalibCommands(CLI::App& app, const GlobalOptions& /*global*/) {
  CLI::App* calib = app.add_subcommand("calib", "Import and inspect rig calibrations");
  calib->require_subcommand(1);

  auto import_args = std::make_shared<CalibImportArgs>();
  CLI::App* import = calib->add_subcommand(
      "import", "Convert a Kalibr camchain.yaml or a Ladybug .conf calibration to rig.json");
  import
      ->add_option("--format", import_args->format,
                   "Format of IN: kalibr (camchain.yaml or camchain-imucam.yaml) or ladybug "
                   "(Ladybug SDK .conf text export)")
      ->required()
      ->check(CLI::IsMember({"kalibr", "ladybug"}));
  import->add_option("IN", import_args->input, "Calibration file to import")->required();
  import->add_option("--out", import_args->output, "rig.json file to write")->required();
  import->add_flag("--upright", import_args->upright,
                   "Ladybug only: the images are stored rotated by 90 degrees (portrait), upright "
                   "pixel = (H - 1 - v, u) of the native one");
  import->add_flag("--force", import_args->force, "Overwrite --out if it exists");
  import->callback([import_args] { RunCalibImport(*import_args);
});

auto show_args = std::make_shared<CalibShowArgs>();
CLI::App* show = calib->add_subcommand(
    "show", "Describe a rig: cameras, centres, viewing directions, fields of view, overlaps");
CLI::Option* rig_option = show->add_option("RIG", show_args->rig, "rig.json file to describe");
CLI::Option* default_option = show->add_flag("--default", show_args->use_default,
                                             "Describe the built-in ladybug-like rig instead");
CLI::Option* preset_option =
    show->add_option("--rig-preset", show_args->rig_preset,
                     "Describe a built-in rig preset instead: ladybug | pinhole | car | fisheye5");
rig_option->excludes(default_option);
rig_option->excludes(preset_option);
default_option->excludes(preset_option);
show->callback([show_args] { RunCalibShow(*show_args); });
}  // namespace omni

}  // namespace omni
