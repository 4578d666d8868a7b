// The catalogue of bad inputs (docs/errors.md): each case runs the built `omnisculpt` as a user
// would and asserts the exit code, exactly one error line on stderr naming the file (or the
// warning naming it, for data that is skipped), that no decoder prints a line of its own, that
// the user's files are unchanged and that a failed run leaves nothing behind.

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <string>
#include <vector>

#include "tests/apps/run_omnisculpt.h"

namespace omni {
namespace {

namespace fs = std::filesystem;
using testing::CommandResult;
using testing::ReadTextFile;
using testing::RunOmnisculpt;
using testing::SplitText;

void WriteFile(const fs::path& path, const std::string& bytes) {
  std::ofstream stream(path, std::ios::binary | std::ios::trunc);
  stream.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// Every file under `folder` with its bytes, by relative path.
std::map<std::string, std::string> Snapshot(const fs::path& folder) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(folder)) {
    if (entry.is_regular_file())
      files[fs::relative(entry.path(), folder).string()] = ReadTextFile(entry.path());
  }
  return files;
}

// The lines of stderr that report an error (one per failed run, by the rule).
std::vector<std::string> ErrorLines(const std::string& err) {
  std::vector<std::string> lines;
  for (const std::string& line : SplitText(err)) {
    if (line.rfind("omnisculpt: error:", 0) == 0 ||
        line.rfind("omnisculpt: internal error:", 0) == 0)
      lines.push_back(line);
  }
  return lines;
}

// Warnings of the log ("[W] ...") on stderr.
std::vector<std::string> WarningLines(const std::string& err) {
  std::vector<std::string> lines;
  for (const std::string& line : SplitText(err)) {
    if (line.find("[W]") != std::string::npos) lines.push_back(line);
  }
  return lines;
}

// Exit 2 with exactly one error line, which names `file` and says `problem`, and nothing printed
// by a library on its own (libpng, libjpeg, a parser's exception).
void ExpectOneError(const CommandResult& result, const fs::path& file, const std::string& problem,
                    int exit_code = 2) {
  EXPECT_EQ(result.exit_code, exit_code) << result.err;
  const std::vector<std::string> errors = ErrorLines(result.err);
  ASSERT_EQ(errors.size(), 1u) << result.err;
  EXPECT_NE(errors[0].find(file.string()), std::string::npos) << errors[0];
  EXPECT_NE(errors[0].find(problem), std::string::npos) << errors[0];
  EXPECT_EQ(result.err.find("libpng"), std::string::npos) << result.err;
  EXPECT_EQ(result.err.find("internal error"), std::string::npos) << result.err;
  EXPECT_EQ(result.err.find("json.exception"), std::string::npos) << result.err;
}

// A folder nobody may create a file in, root included: chmod for a normal user, the immutable
// attribute for root (whom permissions do not stop). Undone on destruction.
class ReadOnlyFolder {
 public:
  explicit ReadOnlyFolder(const fs::path& folder) : folder_(folder) {
    fs::create_directories(folder_);
    if (geteuid() != 0) {
      fs::permissions(folder_, fs::perms::owner_read | fs::perms::owner_exec);
    } else {
      immutable_ = std::system(("chattr +i '" + folder_.string() + "'").c_str()) == 0;
    }
  }
  ~ReadOnlyFolder() {
    if (immutable_) {
      if (std::system(("chattr -i '" + folder_.string() + "'").c_str()) != 0) {
        ADD_FAILURE() << "chattr -i " << folder_;
      }
    }
    fs::permissions(folder_, fs::perms::owner_all);
  }
  // Whether the folder really refuses a new file (the test means nothing otherwise).
  bool RefusesWrites() const {
    const fs::path probe = folder_ / "probe";
    std::ofstream stream(probe);
    if (!stream) return true;
    stream.close();
    fs::remove(probe);
    return false;
  }

 private:
  fs::path folder_;
  bool immutable_ = false;
};

class BadInputCatalogue : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(fs::temp_directory_path() /
                         ("omni_bad_input_catalogue_" + std::to_string(getpid())));
    fs::remove_all(*root_);
    fs::create_directories(*root_);
    // A small drive: the tiny city at a quarter of the image size, 8 frames.
    const CommandResult synth =
        RunOmnisculpt({"--quiet", "synth", "--preset", "tiny", "--frames", "8", "--image-scale",
                       "0.25", "--out", (*root_ / "drive").string()},
                      *root_);
    ASSERT_EQ(synth.exit_code, 0) << synth.err;
    // The same drive run whole: the damaged copies must end as it does, their bad image skipped.
    const CommandResult whole =
        RunOmnisculpt({"--quiet", "reconstruct", (*root_ / "drive").string(), "--out",
                       (*root_ / "whole").string()},
                      *root_);
    whole_exit_code_ = whole.exit_code;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
  }
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    scratch_ = *root_ / info->name();
    user_ = scratch_ / "user";
    logs_ = *root_ / "logs" / info->name();
    fs::create_directories(user_);
    fs::create_directories(logs_);
  }

  // A copy of the drive to damage.
  fs::path CopyDrive(const std::string& name = "drive") {
    const fs::path copy = scratch_ / name;
    fs::copy(*root_ / "drive", copy, fs::copy_options::recursive);
    return copy;
  }
  CommandResult Run(const std::vector<std::string>& arguments) {
    return RunOmnisculpt(arguments, logs_);
  }
  // `reconstruct DRIVE --out scratch/out`.
  CommandResult Reconstruct(const fs::path& drive) {
    return Run({"--quiet", "reconstruct", drive.string(), "--out", (scratch_ / "out").string()});
  }
  // A damaged image mid-drive is skipped: one warning naming it and saying `problem`, listed in
  // reconstruct.json, and the run ends as the undamaged drive does.
  void ExpectImageSkipped(const fs::path& drive, const fs::path& image,
                          const std::string& problem) {
    const CommandResult result = Reconstruct(drive);
    EXPECT_EQ(result.exit_code, whole_exit_code_) << result.err;
    EXPECT_LE(ErrorLines(result.err).size(), 1u) << result.err;
    EXPECT_EQ(result.err.find("libpng"), std::string::npos) << result.err;
    EXPECT_EQ(result.err.find("libjpeg"), std::string::npos) << result.err;
    int naming = 0;
    for (const std::string& line : WarningLines(result.err)) {
      if (line.find(image.string()) != std::string::npos) {
        ++naming;
        EXPECT_NE(line.find(problem), std::string::npos) << line;
      }
    }
    EXPECT_EQ(naming, 1) << result.err;
    EXPECT_EQ(result.out.find(image.string()), std::string::npos) << "a warning on stdout";
    const fs::path summary = scratch_ / "out" / "reconstruct.json";
    ASSERT_TRUE(fs::exists(summary)) << result.err;
    const nlohmann::json json = nlohmann::json::parse(ReadTextFile(summary));
    EXPECT_NE(json["skipped"].dump().find(image.filename().string()), std::string::npos) << json;
    EXPECT_NE(json["warnings"].dump().find(image.filename().string()), std::string::npos) << json;
  }
  fs::path Image(const fs::path& drive, const std::string& camera, int frame) {
    char name[32];
    std::snprintf(name, sizeof(name), "%06d.png", frame);
    return drive / "images" / camera / name;
  }

  static fs::path* root_;
  static int whole_exit_code_;
  fs::path scratch_;  // the test's folder
  fs::path user_;     // in it, the user's files
  fs::path logs_;     // the commands' stdout and stderr, elsewhere
};
fs::path* BadInputCatalogue::root_ = nullptr;
int BadInputCatalogue::whole_exit_code_ = -1;

// --- rig.json ---------------------------------------------------------------------------------

TEST_F(BadInputCatalogue, RigJsonNumberTooLargeForADouble) {
  const std::string rig = ReadTextFile(*root_ / "drive" / "rig.json");
  const std::string width = "\"width\": ";
  const size_t at = rig.find(width);
  ASSERT_NE(at, std::string::npos);
  const size_t end = rig.find(',', at);
  for (const std::string& number : {std::string("1e309"), std::string(400, '7')}) {
    const fs::path path = user_ / "rig.json";
    WriteFile(path, rig.substr(0, at + width.size()) + number + rig.substr(end));
    ExpectOneError(Run({"calib", "show", path.string()}), path, "number overflow");
  }
}

TEST_F(BadInputCatalogue, RigJsonImplausibleValuesAndMissingKeys) {
  const nlohmann::json rig = nlohmann::json::parse(ReadTextFile(*root_ / "drive" / "rig.json"));
  struct Case {
    std::string pointer;  // JSON pointer of the value to change (removed when null)
    nlohmann::json value;
    std::string problem;
  };
  const Case cases[] = {
      {"/cameras/0/params/0", 1e20, "cameras[0].params[0]: expected a focal length fx"},
      {"/cameras/1/params/2", 1e39, "cameras[1].params[2]: expected a principal point cx"},
      {"/cameras/2/cam_from_rig/t/0", 1e308, "cameras[2].cam_from_rig.t: expected a camera within"},
      {"/central", nullptr, "central: missing field"},
      {"/cameras/0/model", nullptr, "cameras[0].model: missing field"},
  };
  for (const Case& c : cases) {
    nlohmann::json changed = rig;
    const nlohmann::json::json_pointer pointer(c.pointer);
    if (c.value.is_null()) {
      changed[pointer.parent_pointer()].erase(pointer.back());
    } else {
      changed[pointer] = c.value;
    }
    const fs::path path = user_ / "rig.json";
    WriteFile(path, changed.dump(1));
    ExpectOneError(Run({"calib", "show", path.string()}), path, c.problem);
    // The same rig.json in a drive refuses the drive, before any output exists.
    const fs::path drive = scratch_ / "drive";
    if (!fs::exists(drive)) CopyDrive();
    WriteFile(drive / "rig.json", changed.dump(1));
    ExpectOneError(Reconstruct(drive), drive / "rig.json", c.problem);
    EXPECT_FALSE(fs::exists(scratch_ / "out"));
    EXPECT_FALSE(fs::exists(scratch_ / "out.incomplete"));
  }
}

// --- PLY (mesh-check) -------------------------------------------------------------------------

TEST_F(BadInputCatalogue, MeshCheckRefusesNonFiniteTrailingAndMiscountedPly) {
  const std::string head =
      "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
      "property float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n";
  const std::string faces = "3 0 2 1\n3 0 1 3\n3 1 2 3\n3 0 3 2\n";
  const fs::path path = user_ / "mesh.ply";
  WriteFile(path, head + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + faces);
  EXPECT_EQ(Run({"mesh-check", path.string()}).exit_code, 0);
  struct Case {
    std::string bytes, problem;
  };
  const Case cases[] = {
      {head + "0 0 0\n1 0 0\nnan 1 0\n0 0 1\n" + faces, "expected a decimal number, got \"nan\""},
      {head + "0 0 0\n1 0 0\n0 inf 0\n0 0 1\n" + faces, "expected a decimal number, got \"inf\""},
      {head + "0 0 0\n1 0 0\n0 1e39999 0\n0 0 1\n" + faces, "number out of range"},
      {head + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + faces + "junk", "after the last element"},
      {head.substr(0, head.find("face 4")) + "face 3" + head.substr(head.find("face 4") + 6) +
           "0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + faces,
       "after the last element"},
      {head + "0 0 0\n1 0 0\n0 1 0\n0 0 1\n" + faces.substr(0, faces.size() - 8), "truncated data"},
  };
  for (const Case& c : cases) {
    WriteFile(path, c.bytes);
    ExpectOneError(Run({"mesh-check", path.string()}), path, c.problem);
  }
  // Binary: a NaN coordinate.
  std::string binary =
      "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n"
      "property float y\nproperty float z\nend_header\n";
  const float nan = std::numeric_limits<float>::quiet_NaN(), zero = 0.0f;
  binary.append(reinterpret_cast<const char*>(&zero), 4);
  binary.append(reinterpret_cast<const char*>(&nan), 4);
  binary.append(reinterpret_cast<const char*>(&zero), 4);
  WriteFile(path, binary);
  ExpectOneError(Run({"mesh-check", "--allow-boundary", path.string()}), path,
                 "vertex 0: expected finite coordinates");
}

// --- eval: trajectories and its --out --------------------------------------------------------

class EvalCatalogue : public BadInputCatalogue {
 protected:
  // A reconstruction folder made of the drive's own ground truth (eval reads it like any).
  fs::path MakeRec() {
    const fs::path rec = scratch_ / "rec";
    fs::create_directories(rec);
    fs::copy_file(*root_ / "drive" / "gt" / "poses.tum", rec / "poses.tum");
    fs::copy_file(*root_ / "drive" / "gt" / "mesh.ply", rec / "surface.ply");
    return rec;
  }
  std::vector<std::string> Eval(const fs::path& rec, const std::vector<std::string>& extra = {}) {
    std::vector<std::string> arguments = {
        "--quiet",   "eval",       "--gt",       (*root_ / "drive").string(),
        "--rec",     rec.string(), "--pixels",   "2000",
        "--samples", "2000",       "--no-plots", "--no-renders"};
    arguments.insert(arguments.end(), extra.begin(), extra.end());
    return arguments;
  }
};

TEST_F(EvalCatalogue, TrajectoryWithRepeatedDecreasingOrHexadecimalValues) {
  const fs::path rec = MakeRec();
  std::vector<std::string> lines;
  for (const std::string& line : SplitText(ReadTextFile(rec / "poses.tum"))) {
    if (!line.empty() && line[0] != '#') lines.push_back(line);
  }
  ASSERT_GE(lines.size(), 4u);
  auto with = [&](size_t index, const std::string& line) {
    std::string text;
    for (size_t i = 0; i < lines.size(); ++i) text += (i == index ? line : lines[i]) + "\n";
    return text;
  };
  const std::string second_stamp = lines[1].substr(0, lines[1].find(' '));
  struct Case {
    std::string text, problem;
  };
  const Case cases[] = {
      {with(2, second_stamp + lines[2].substr(lines[2].find(' '))),
       "line 3: timestamps must increase"},
      {with(2, "0" + lines[2].substr(lines[2].find(' '))), "line 3: timestamps must increase"},
      {with(1, "0x10" + lines[1].substr(lines[1].find(' '))),
       "line 2: value 1: expected a decimal number, got \"0x10\""},
      {with(1, lines[1] + " 1e309"), "line 2: expected 8 values"},
      {with(3, lines[3].substr(0, lines[3].rfind(' ')) + " nan"),
       "line 4: value 8: expected a decimal number, got \"nan\""},
  };
  for (const Case& c : cases) {
    WriteFile(rec / "poses.tum", c.text);
    ExpectOneError(Run(Eval(rec)), rec / "poses.tum", c.problem);
    EXPECT_FALSE(fs::exists(rec / "report")) << "a failed eval left its report folder";
  }
}

TEST_F(EvalCatalogue, OutIntoAUsersFolderIsRefusedAndItsFilesStay) {
  const fs::path rec = MakeRec();
  const fs::path mine = user_ / "mine";
  fs::create_directories(mine);
  WriteFile(mine / "report.md", "my notes\n");
  WriteFile(mine / "eval.json", "{\"mine\": true}\n");
  WriteFile(mine / "other.txt", "keep\n");
  const auto before = Snapshot(mine);
  ExpectOneError(Run(Eval(rec, {"--out", mine.string()})), mine, "exists and is not empty");
  EXPECT_EQ(Snapshot(mine), before);
  // Without eval.json it is not an earlier report: refused even with --force.
  fs::remove(mine / "eval.json");
  const auto without = Snapshot(mine);
  ExpectOneError(Run(Eval(rec, {"--out", mine.string(), "--force"})), mine,
                 "is not an earlier output of eval (no eval.json)");
  EXPECT_EQ(Snapshot(mine), without);
  // An earlier report is rewritten with --force, refused without.
  const fs::path report = scratch_ / "report";
  ASSERT_EQ(Run(Eval(rec, {"--out", report.string()})).exit_code, 0);
  ASSERT_TRUE(fs::exists(report / "eval.json"));
  ExpectOneError(Run(Eval(rec, {"--out", report.string()})), report, "exists and is not empty");
  EXPECT_EQ(Run(Eval(rec, {"--out", report.string(), "--force"})).exit_code, 0);
}

// --- output folders ---------------------------------------------------------------------------

TEST_F(BadInputCatalogue, ReadOnlyOutIsRefusedNamingTheFolder) {
  const fs::path locked = user_ / "locked";
  const ReadOnlyFolder read_only(locked);
  ASSERT_TRUE(read_only.RefusesWrites()) << "the folder accepts files: the cases would not test";
  const fs::path drive = *root_ / "drive";
  const fs::path out = locked / "out";
  struct Case {
    std::vector<std::string> arguments;
    fs::path named;
  };
  const Case cases[] = {
      {{"reconstruct", drive.string(), "--out", out.string()}, out},
      {{"sfm", drive.string(), "--out", out.string()}, out},
      {{"surface", "--from-gt", drive.string(), "--out", out.string()}, out},
      {{"eval", "--gt", drive.string(), "--rec", drive.string(), "--out", out.string()}, out},
      {{"synth", "--preset", "tiny", "--frames", "2", "--image-scale", "0.1", "--out",
        out.string()},
       out},
      // The folder itself as --out: it exists (empty) but cannot be written into.
      {{"sfm", drive.string(), "--out", locked.string()}, locked},
      {{"reconstruct", drive.string(), "--out", locked.string()}, locked},
      {{"calib", "import", "--format", "ladybug", (user_ / "x.conf").string(), "--out",
        (locked / "rig.json").string()},
       locked / "rig.json"},
  };
  WriteFile(user_ / "x.conf",
            "Resolution 1024 768\nBeginCamera\nfocalLength 0.4 0.5\n"
            "CamToLadybugEulerZYX 0 0 0 0 0 0\nCenter 0 0 0 0.5 0.5\nEndCamera\n");
  for (const Case& c : cases) {
    SCOPED_TRACE(c.arguments[0]);
    const CommandResult result = Run(c.arguments);
    ExpectOneError(result, c.named, "");
    const std::string error = ErrorLines(result.err).empty() ? "" : ErrorLines(result.err)[0];
    EXPECT_TRUE(error.find("cannot") != std::string::npos) << error;
    EXPECT_TRUE(fs::is_empty(locked));
  }
}

TEST_F(BadInputCatalogue, ExistingOutIsRefusedAndTheUsersFilesStay) {
  const fs::path drive = *root_ / "drive";
  const fs::path mine = user_ / "mine";
  fs::create_directories(mine / "sub");
  WriteFile(mine / "notes.txt", "mine\n");
  WriteFile(mine / "sub" / "surface.ply", "not a mesh\n");
  WriteFile(user_ / "view.png", "my picture\n");
  WriteFile(user_ / "rig.json", "my rig\n");
  WriteFile(user_ / "a_file", "a file\n");
  WriteFile(user_ / "x.conf",
            "Resolution 1024 768\nBeginCamera\nfocalLength 0.4 0.5\n"
            "CamToLadybugEulerZYX 0 0 0 0 0 0\nCenter 0 0 0 0.5 0.5\nEndCamera\n");
  const auto before = Snapshot(user_);
  struct Case {
    std::vector<std::string> arguments;
    fs::path named;
    std::string problem;
  };
  const Case cases[] = {
      {{"reconstruct", drive.string(), "--out", mine.string()}, mine, "exists and is not empty"},
      {{"reconstruct", drive.string(), "--out", mine.string(), "--force"},
       mine,
       "is not a previous reconstruction"},
      {{"sfm", drive.string(), "--out", mine.string()}, mine, "exists and is not empty"},
      {{"sfm", drive.string(), "--out", mine.string(), "--force"},
       mine,
       "is not an earlier output of sfm"},
      {{"surface", "--from-gt", drive.string(), "--out", mine.string()},
       mine,
       "exists and is not empty"},
      {{"synth", "--preset", "tiny", "--frames", "2", "--out", mine.string(), "--force"},
       mine,
       "is not a drive written by synth"},
      {{"render", (drive / "gt" / "mesh.ply").string(), "--bird", "--out",
        (user_ / "view.png").string()},
       user_ / "view.png",
       "exists already"},
      {{"calib", "import", "--format", "ladybug", (user_ / "x.conf").string(), "--out",
        (user_ / "rig.json").string()},
       user_ / "rig.json",
       "exists already"},
      {{"sfm", drive.string(), "--out", (user_ / "a_file").string()},
       user_ / "a_file",
       "exists and is not a folder"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.arguments[0]);
    ExpectOneError(Run(c.arguments), c.named, c.problem);
    EXPECT_EQ(Snapshot(user_), before);
  }
  // Nothing was made beside the user's folders either.
  for (const auto& entry : fs::directory_iterator(user_)) {
    const std::string name = entry.path().filename().string();
    EXPECT_EQ(name.find(".incomplete"), std::string::npos) << name;
    EXPECT_EQ(name.find(".partial"), std::string::npos) << name;
  }
}

// --- drives -----------------------------------------------------------------------------------

TEST_F(BadInputCatalogue, MissingCameraFolderRefusesTheDriveAndLeavesNothing) {
  const fs::path drive = CopyDrive();
  fs::remove_all(drive / "images" / "cam3");
  ExpectOneError(Reconstruct(drive), drive / "images" / "cam3", "missing camera folder");
  EXPECT_FALSE(fs::exists(scratch_ / "out"));
  EXPECT_FALSE(fs::exists(scratch_ / "out.incomplete"));
}

TEST_F(BadInputCatalogue, FrameMissingInOneCameraIsAWarningNamingIt) {
  const fs::path drive = CopyDrive();
  fs::remove(Image(drive, "cam2", 7));
  const CommandResult result = Reconstruct(drive);
  EXPECT_NE(result.exit_code, 2) << result.err;
  const std::vector<std::string> warnings = WarningLines(result.err);
  int naming = 0;
  for (const std::string& line : warnings) {
    if (line.find((drive / "images").string()) != std::string::npos &&
        line.find("000007 (missing in cam2)") != std::string::npos)
      ++naming;
  }
  EXPECT_EQ(naming, 1) << result.err;
  const nlohmann::json json =
      nlohmann::json::parse(ReadTextFile(scratch_ / "out" / "reconstruct.json"));
  EXPECT_EQ(json["frames"], 7) << json;
  EXPECT_NE(json["warnings"].dump().find("000007 (missing in cam2)"), std::string::npos) << json;
}

// `sfm` and `surface` keep their warnings in their JSON summaries too (sfm.json, surface.json).
TEST_F(BadInputCatalogue, SkippedImageIsInSfmJsonAndWarningsOfSurfaceInSurfaceJson) {
  const fs::path drive = CopyDrive();
  const fs::path image = Image(drive, "cam1", 4);
  WriteFile(image, "");
  const fs::path sfm_out = scratch_ / "sfm_out";
  const CommandResult sfm = Run({"--quiet", "sfm", drive.string(), "--out", sfm_out.string()});
  EXPECT_NE(sfm.exit_code, 2) << sfm.err;
  ASSERT_TRUE(fs::exists(sfm_out / "sfm.json")) << sfm.err;
  const nlohmann::json sfm_json = nlohmann::json::parse(ReadTextFile(sfm_out / "sfm.json"));
  EXPECT_EQ(sfm_json["frames_skipped"], 1) << sfm_json;
  EXPECT_NE(sfm_json["skipped"].dump().find(image.filename().string()), std::string::npos);
  EXPECT_NE(sfm_json["warnings"].dump().find(image.string()), std::string::npos) << sfm_json;
  EXPECT_EQ(sfm_json["status"], sfm.exit_code == 0 ? "usable" : "not_usable") << sfm_json;

  // A ground truth whose frames do not match the images: surface warns and says so in its JSON.
  fs::remove(Image(drive, "cam0", 0));
  for (const std::string camera : {"cam1", "cam2", "cam3", "cam4", "cam5"})
    fs::remove(Image(drive, camera, 0));
  const fs::path surface_out = scratch_ / "surface_out";
  const CommandResult surface =
      Run({"--quiet", "surface", "--from-gt", drive.string(), "--out", surface_out.string()});
  ASSERT_TRUE(fs::exists(surface_out / "surface.json")) << surface.err;
  const nlohmann::json surface_json =
      nlohmann::json::parse(ReadTextFile(surface_out / "surface.json"));
  EXPECT_EQ(surface_json["status"], surface.exit_code == 0 ? "usable" : "not_usable");
  const std::vector<std::string> warnings = WarningLines(surface.err);
  ASSERT_FALSE(warnings.empty()) << surface.err;
  EXPECT_EQ(surface_json["warnings"].size(), warnings.size()) << surface_json;
  EXPECT_NE(surface_json["warnings"].dump().find("ground-truth poses"), std::string::npos)
      << surface_json;
}

TEST_F(BadInputCatalogue, ZeroByteImageMidDriveIsSkippedWithAWarning) {
  const fs::path drive = CopyDrive();
  WriteFile(Image(drive, "cam1", 4), "");
  ExpectImageSkipped(drive, Image(drive, "cam1", 4), "empty file (0 bytes)");
}

TEST_F(BadInputCatalogue, TruncatedImageMidDriveIsSkippedWithoutADecoderLine) {
  const fs::path drive = CopyDrive();
  const fs::path image = Image(drive, "cam0", 3);
  const std::string bytes = ReadTextFile(image);
  WriteFile(image, bytes.substr(0, bytes.size() / 2));
  ExpectImageSkipped(drive, image, "truncated PNG");
}

TEST_F(BadInputCatalogue, WrongSizeImageMidDriveIsSkippedWithAWarning) {
  const fs::path drive = CopyDrive();
  const fs::path image = Image(drive, "cam4", 5);
  const cv::Mat original = cv::imread(image.string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(original.empty());
  cv::imwrite(image.string(), cv::Mat(original.rows + 2, original.cols, CV_8UC1, cv::Scalar(90)));
  ExpectImageSkipped(
      drive, image,
      "image is " + std::to_string(original.cols) + "x" + std::to_string(original.rows + 2));
}

TEST_F(BadInputCatalogue, SixteenBitImageMidDriveIsRefusedWithAWarning) {
  const fs::path drive = CopyDrive();
  const fs::path image = Image(drive, "cam2", 4);
  cv::Mat deep;
  cv::imread(image.string(), cv::IMREAD_GRAYSCALE).convertTo(deep, CV_16U, 256.0);
  cv::imwrite(image.string(), deep);
  ExpectImageSkipped(drive, image, "16-bit PNG: expected 8 bits per channel");
}

TEST_F(BadInputCatalogue, RenamedFilesAreJudgedByTheirContent) {
  // A text file renamed to .png is not an image: skipped with a warning.
  const fs::path drive = CopyDrive();
  const fs::path image = Image(drive, "cam5", 3);
  WriteFile(image, "these are my notes, not an image\n");
  ExpectImageSkipped(drive, image, "not a PNG or JPEG image");
  // A JPEG renamed to .png is an image: read as such, no warning about it.
  const fs::path jpeg_drive = CopyDrive("jpeg_drive");
  const fs::path renamed = Image(jpeg_drive, "cam0", 2);
  std::vector<uint8_t> jpeg;
  cv::imencode(".jpg", cv::imread(renamed.string(), cv::IMREAD_GRAYSCALE), jpeg,
               {cv::IMWRITE_JPEG_QUALITY, 98});
  WriteFile(renamed, std::string(jpeg.begin(), jpeg.end()));
  fs::remove_all(scratch_ / "out");
  const CommandResult result = Reconstruct(jpeg_drive);
  EXPECT_EQ(result.exit_code, whole_exit_code_) << result.err;
  EXPECT_EQ(result.err.find(renamed.string()), std::string::npos) << result.err;
}

TEST_F(BadInputCatalogue, BlackFramesEndWithoutAUsableResultSayingWhy) {
  const fs::path drive = CopyDrive();
  for (const auto& entry : fs::recursive_directory_iterator(drive / "images")) {
    if (entry.path().extension() != ".png") continue;
    const cv::Mat image = cv::imread(entry.path().string(), cv::IMREAD_GRAYSCALE);
    cv::imwrite(entry.path().string(), cv::Mat::zeros(image.size(), CV_8UC1));
  }
  const CommandResult result = Reconstruct(drive);
  ExpectOneError(result, drive, "", 3);
  const nlohmann::json json =
      nlohmann::json::parse(ReadTextFile(scratch_ / "out" / "reconstruct.json"));
  EXPECT_EQ(json["status"], "not_usable") << json;
  EXPECT_FALSE(fs::exists(scratch_ / "out" / "surface.ply"));
  EXPECT_FALSE(fs::exists(scratch_ / "out.incomplete"));
}

TEST_F(BadInputCatalogue, OneAndTwoFrameDrivesAreRefusedOrNotUsableAndLeaveNoIncompleteFolder) {
  for (const int frames : {1, 2}) {
    SCOPED_TRACE(frames);
    const fs::path drive = scratch_ / ("drive" + std::to_string(frames));
    fs::copy(*root_ / "drive", drive, fs::copy_options::recursive);
    for (const auto& entry : fs::recursive_directory_iterator(drive / "images")) {
      if (entry.path().extension() == ".png" && std::stoi(entry.path().stem().string()) >= frames)
        fs::remove(entry.path());
    }
    const fs::path out = scratch_ / ("out" + std::to_string(frames));
    const CommandResult result =
        Run({"--quiet", "reconstruct", drive.string(), "--out", out.string()});
    EXPECT_TRUE(result.exit_code == 2 || result.exit_code == 3) << result.err;
    ASSERT_EQ(ErrorLines(result.err).size(), 1u) << result.err;
    EXPECT_NE(ErrorLines(result.err)[0].find(drive.string()), std::string::npos) << result.err;
    fs::path incomplete = out;
    incomplete += ".incomplete";
    EXPECT_FALSE(fs::exists(incomplete)) << "a failed run left " << incomplete;
    // Exit 2 leaves nothing; exit 3 publishes OUT saying why.
    EXPECT_EQ(fs::exists(out / "reconstruct.json"), result.exit_code == 3) << result.err;
    if (result.exit_code == 2) {
      EXPECT_FALSE(fs::exists(out));
    }
  }
}

}  // namespace
}  // namespace omni
