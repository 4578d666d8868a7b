#pragma once
// A drive folder (docs/design.md §5):
//   drive/rig.json
//   drive/images/<camera name>/<frame>.png|jpg     same frame names in every camera folder
//   drive/gt/poses.tum, drive/gt/mesh.ply           optional ground truth
//   drive/frames.csv                                optional per-frame timestamps
// frames.csv: a header naming at least the columns frame, camera and timestamp_s (seconds, a
// decimal number; other columns are ignored), then one row per image (frame name, camera name,
// its timestamp). A frame's timestamp is the mean of its cameras' rows (the cameras are
// synchronised); the frames' timestamps must increase in frame order. Without frames.csv a
// drive has no clock of its own and the commands stamp frame f with f / --frame-rate.
// Frames are the names present in every camera folder, in natural order ("2" before "10").
// Frames missing in some camera are reported (incomplete_frames()), never silently dropped.
// Images are loaded lazily, as 8-bit grey, and their size is checked against rig.json.

#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "calib/rig.h"

namespace omni {

struct DriveOptions {
  // File extensions recognised as images (lower case, with the dot).
  std::vector<std::string> image_extensions = {".png", ".jpg", ".jpeg"};
  // Fewest complete frames a drive must have to be opened.
  int min_frames = 1;

  std::string Check() const;
};

struct IncompleteFrame {
  std::string frame_name;
  std::vector<std::string> missing_cameras;
};

class Drive {
 public:
  // Reads rig.json and lists the images. Throws InputError (missing or malformed rig.json,
  // missing camera folder, empty folder, fewer than min_frames complete frames).
  static Drive Open(const std::filesystem::path& folder, const DriveOptions& options = {});

  const std::filesystem::path& folder() const { return folder_; }
  const Rig& rig() const { return rig_; }
  size_t NumFrames() const { return frame_names_.size(); }
  const std::string& FrameName(size_t frame) const { return frame_names_.at(frame); }
  const std::vector<std::string>& frame_names() const { return frame_names_; }
  // Frames present in some camera folders only; they are not among the frames.
  const std::vector<IncompleteFrame>& incomplete_frames() const { return incomplete_frames_; }

  std::filesystem::path ImagePath(size_t frame, size_t camera) const;
  // The image as 8-bit grey. Throws InputError naming the file if it is missing, damaged or not
  // an image (ImageFileProblem), not 8 bits per channel, or not the size rig.json gives for that
  // camera.
  cv::Mat LoadGray(size_t frame, size_t camera) const;
  // The image in colour, 8-bit RGB (CV_8UC3, red first as PLY colours want; a grey image gives
  // three equal channels). Throws InputError as LoadGray.
  cv::Mat LoadRgb(size_t frame, size_t camera) const;

  // The frame's timestamp (seconds) from frames.csv; false when the drive has none.
  bool HasTimestamps() const { return !timestamps_.empty(); }
  double FrameTimestamp(size_t frame) const { return timestamps_.at(frame); }

  std::filesystem::path GroundTruthPosesPath() const { return folder_ / "gt" / "poses.tum"; }
  std::filesystem::path GroundTruthMeshPath() const { return folder_ / "gt" / "mesh.ply"; }

 private:
  std::filesystem::path folder_;
  Rig rig_;
  std::vector<std::string> frame_names_;
  // image_files_[camera][frame]: file name inside images/<camera>/.
  std::vector<std::vector<std::string>> image_files_;
  std::vector<IncompleteFrame> incomplete_frames_;
  std::vector<double> timestamps_;  // per frame, from frames.csv; empty without it
};

// The per-frame timestamps of `frame_names` in a frames.csv file (format above). Throws
// InputError naming the file and line: a missing column, a bad number, a frame without a row,
// timestamps that do not increase.
std::vector<double> ReadFrameTimestamps(const std::filesystem::path& frames_csv,
                                        const std::vector<std::string>& frame_names);
// The same on the text of a frames.csv in memory; `frames_csv` names it in the errors.
std::vector<double> ParseFrameTimestamps(const std::string& text,
                                         const std::filesystem::path& frames_csv,
                                         const std::vector<std::string>& frame_names);

// Why the bytes of an image file cannot be decoded as a drive image, or "" when they can: a PNG
// whose chunks do not all fit the file or fail their CRC, or has more than 8 bits per channel
// (refused: dividing by 256 would hide a wrong export); a JPEG whose segments do not fit the file
// or whose data does not end in a marker; anything that is neither (a renamed file, 0 bytes).
// Drive::LoadGray checks it before decoding, so that the decoders never see a damaged file and
// print their own line on stderr ("libpng error: Read Error") naming no file.
std::string ImageFileProblem(const std::string& bytes);

// "2" < "10" < "a2" < "a10": digit runs compare by value.
bool NaturalLess(const std::string& a, const std::string& b);

}  // namespace omni
