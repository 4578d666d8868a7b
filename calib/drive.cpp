#include "calib/drive.h"

#include <spdlog/spdlog.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <limits>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>
#include <system_error>

#include "calib/error.h"
#include "calib/input_file.h"
#include "calib/number_text.h"
#include "calib/png_grey.h"
#include "calib/rig_io.h"

namespace omni {
namespace {

// How many incomplete frames the warning names before giving only their count.
constexpr size_t kIncompleteFramesNamedInWarning = 5;

bool IsDigit(char c) { return std::isdigit(static_cast<unsigned char>(c)) != 0; }

std::string ToLower(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return text;
}

std::string JoinWords(const std::vector<std::string>& words, const std::string& separator) {
  std::string joined;
  for (size_t i = 0; i < words.size(); ++i) {
    if (i > 0) joined += separator;
    joined += words[i];
  }
  return joined;
}

// Image files of one camera folder: frame name (file stem) -> file name.
std::map<std::string, std::string> ListImages(const std::filesystem::path& camera_folder,
                                              const DriveOptions& options) {
  std::map<std::string, std::string> files;
  std::error_code error;
  std::filesystem::directory_iterator it(camera_folder, error);
  if (error) throw InputError(camera_folder, "", "cannot list folder: " + error.message());
  for (const std::filesystem::directory_entry& entry : it) {
    std::error_code status_error;
    if (!entry.is_regular_file(status_error)) continue;
    const std::filesystem::path& file = entry.path();
    const std::string extension = ToLower(file.extension().string());
    if (std::find(options.image_extensions.begin(), options.image_extensions.end(), extension) ==
        options.image_extensions.end()) {
      continue;
    }
    const std::string frame = file.stem().string();
    const std::string name = file.filename().string();
    auto [existing, inserted] = files.emplace(frame, name);
    if (!inserted) {
      const std::string first = std::min(existing->second, name);
      const std::string second = std::max(existing->second, name);
      throw InputError(camera_folder, "",
                       "two images for frame \"" + frame + "\": " + first + " and " + second);
    }
  }
  return files;
}

uint32_t BigEndian32(const unsigned char* bytes) {
  return (uint32_t{bytes[0]} << 24) | (uint32_t{bytes[1]} << 16) | (uint32_t{bytes[2]} << 8) |
         uint32_t{bytes[3]};
}

// The CRC-32 of PNG chunks (ISO 3309, polynomial 0xEDB88320): zlib's, several times faster than
// a table lookup per byte (it is computed for every image the SfM reads).
uint32_t Crc32(const unsigned char* bytes, size_t size) {
  uLong crc = crc32(0L, Z_NULL, 0);
  while (size > 0) {  // zlib takes the length as uInt
    const uInt chunk = static_cast<uInt>(std::min<size_t>(size, 1u << 30));
    crc = crc32(crc, bytes, chunk);
    bytes += chunk;
    size -= chunk;
  }
  return static_cast<uint32_t>(crc);
}

// The problem with the chunks of a PNG file (signature checked by the caller), or "".
std::string PngProblem(const std::string& data) {
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
  size_t position = 8;
  bool first = true;
  while (true) {
    if (data.size() - position < 12) return "truncated PNG (the file ends before its IEND chunk)";
    const uint32_t length = BigEndian32(bytes + position);
    const std::string type(data, position + 4, 4);
    if (length > data.size() - position - 12) {
      return "truncated PNG (chunk " + type + " runs past the end of the file)";
    }
    const uint32_t crc = BigEndian32(bytes + position + 8 + length);
    if (Crc32(bytes + position + 4, length + 4) != crc) {
      return "corrupt PNG (chunk " + type + " fails its CRC check)";
    }
    if (first) {
      if (type != "IHDR" || length != 13) return "corrupt PNG (no IHDR chunk first)";
      // 1, 2 and 4-bit grey or palette images decode to 8 bits exactly; 16 bits do not.
      const int bit_depth = bytes[position + 8 + 8];
      if (bit_depth > 8) {
        return std::to_string(bit_depth) +
               "-bit PNG: expected 8 bits per channel (convert it, e.g. `convert IN -depth 8 "
               "OUT.png`; dividing by 256 here would hide a wrong export)";
      }
      first = false;
    }
    position += 12 + length;
    if (type == "IEND") return "";
  }
}

// The problem with the markers of a JPEG file (SOI checked by the caller), or "": every segment
// fits the file and the entropy-coded data ends in a marker (EOI).
std::string JpegProblem(const std::string& data) {
  const auto* bytes = reinterpret_cast<const unsigned char*>(data.data());
  const std::string truncated = "truncated JPEG (the file ends before its end-of-image marker)";
  size_t position = 2;
  while (true) {
    if (position + 2 > data.size()) return truncated;
    if (bytes[position] != 0xFF) return "corrupt JPEG (no marker where one is expected)";
    while (position + 1 < data.size() && bytes[position + 1] == 0xFF) ++position;  // fill bytes
    if (position + 2 > data.size()) return truncated;
    const unsigned char marker = bytes[position + 1];
    if (marker == 0xD9) return "";  // EOI
    if (marker == 0x01 || (marker >= 0xD0 && marker <= 0xD7)) {
      position += 2;
      continue;
    }
    if (position + 4 > data.size()) return truncated;
    const size_t length = (size_t{bytes[position + 2]} << 8) | bytes[position + 3];
    if (length < 2) return "corrupt JPEG (a segment shorter than its length field)";
    if (length > data.size() - position - 2) return truncated;
    position += 2 + length;
    if (marker == 0xDA) {  // start of scan: entropy-coded data up to the next marker
      while (position + 1 < data.size() &&
             !(bytes[position] == 0xFF && bytes[position + 1] != 0x00 &&
               !(bytes[position + 1] >= 0xD0 && bytes[position + 1] <= 0xD7))) {
        ++position;
      }
      if (position + 1 >= data.size()) return truncated;
    }
  }
}

// The image `file` decoded with `flags`, at 8 bits per channel, checked against the camera's
// size in rig.json; InputError naming the file otherwise.
cv::Mat ReadImage8Bit(const std::filesystem::path& file, int flags, const Camera& rig_camera) {
  const std::string data = ReadInputFile(file);
  if (const std::string problem = ImageFileProblem(data); !problem.empty()) {
    throw InputError(file, "", problem);
  }
  if (data.size() > static_cast<size_t>(std::numeric_limits<int>::max())) {
    throw InputError(file, "", "image file too large (over 2 GB)");
  }
  cv::Mat image;
  // A drive's plain 8-bit grey PNGs (the common case) decode here about twice as fast, to the
  // same pixels, whether grey is asked for or the file's own channels are (LoadRgb, which expands
  // them); every other file goes through OpenCV.
  const bool grey_is_the_answer =
      flags == cv::IMREAD_GRAYSCALE || flags == (cv::IMREAD_ANYCOLOR | cv::IMREAD_ANYDEPTH);
  if (!(grey_is_the_answer && DecodePlainGreyPng(data, &image))) {
    image.release();
    try {
      const cv::Mat bytes(1, static_cast<int>(data.size()), CV_8U, const_cast<char*>(data.data()));
      image = cv::imdecode(bytes, flags);
    } catch (const cv::Exception&) {
      image.release();  // a codec that throws on a corrupt file is treated as one that fails
    }
  }
  if (image.empty()) throw InputError(file, "", "cannot decode the image (corrupt)");
  if (image.depth() != CV_8U) throw InputError(file, "", "expected 8 bits per channel");
  if (image.cols != rig_camera.width || image.rows != rig_camera.height) {
    throw InputError(file, "",
                     "image is " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                         ", rig.json gives camera " + rig_camera.name + " " +
                         std::to_string(rig_camera.width) + "x" +
                         std::to_string(rig_camera.height));
  }
  return image;
}

}  // namespace

std::string ImageFileProblem(const std::string& data) {
  if (data.empty()) return "empty file (0 bytes)";
  static const char kPngSignature[] = "\x89PNG\r\n\x1a\n";
  if (data.size() >= 8 && data.compare(0, 8, kPngSignature, 8) == 0) return PngProblem(data);
  if (data.size() >= 3 && static_cast<unsigned char>(data[0]) == 0xFF &&
      static_cast<unsigned char>(data[1]) == 0xD8 && static_cast<unsigned char>(data[2]) == 0xFF) {
    return JpegProblem(data);
  }
  return "not a PNG or JPEG image (its first bytes are neither signature)";
}

std::string DriveOptions::Check() const {
  if (image_extensions.empty()) return "image_extensions: expected at least one extension";
  for (const std::string& extension : image_extensions) {
    if (extension.size() < 2 || extension[0] != '.' || extension != ToLower(extension)) {
      return "image_extensions: expected lower-case extensions with the dot (\".png\"), got \"" +
             extension + "\"";
    }
  }
  if (min_frames < 1) return "min_frames: expected at least 1, got " + std::to_string(min_frames);
  return "";
}

bool NaturalLess(const std::string& a, const std::string& b) {
  size_t i = 0;
  size_t j = 0;
  while (i < a.size() && j < b.size()) {
    if (IsDigit(a[i]) && IsDigit(b[j])) {
      size_t a_end = i;
      while (a_end < a.size() && IsDigit(a[a_end])) ++a_end;
      size_t b_end = j;
      while (b_end < b.size() && IsDigit(b[b_end])) ++b_end;
      // Skip leading zeros (keeping one digit), then the longer run is the larger number.
      size_t a_start = i;
      while (a_start + 1 < a_end && a[a_start] == '0') ++a_start;
      size_t b_start = j;
      while (b_start + 1 < b_end && b[b_start] == '0') ++b_start;
      const size_t a_length = a_end - a_start;
      const size_t b_length = b_end - b_start;
      if (a_length != b_length) return a_length < b_length;
      const int order = a.compare(a_start, a_length, b, b_start, b_length);
      if (order != 0) return order < 0;
      i = a_end;
      j = b_end;
    } else {
      if (a[i] != b[j]) {
        return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      }
      ++i;
      ++j;
    }
  }
  const bool a_done = i == a.size();
  const bool b_done = j == b.size();
  if (a_done != b_done) return a_done;
  // Equal as numbers ("01" and "1"): order by the plain text so the order stays strict.
  return a < b;
}

Drive Drive::Open(const std::filesystem::path& folder, const DriveOptions& options) {
  const std::string option_problem = options.Check();
  if (!option_problem.empty()) throw InputError("", "drive options", option_problem);

  std::error_code error;
  if (!std::filesystem::is_directory(folder, error)) {
    throw InputError(folder, "",
                     std::filesystem::exists(folder, error) ? "not a folder" : "no such folder");
  }
  Drive drive;
  drive.folder_ = folder;
  drive.rig_ = ReadRigJson(folder / "rig.json");

  const std::filesystem::path images = folder / "images";
  if (!std::filesystem::is_directory(images, error)) {
    throw InputError(images, "",
                     "missing folder (expected images/<camera>/ for each camera of rig.json)");
  }

  // Per camera: frame name -> file name.
  const size_t num_cameras = drive.rig_.NumCameras();
  std::vector<std::map<std::string, std::string>> camera_files(num_cameras);
  for (size_t camera = 0; camera < num_cameras; ++camera) {
    const std::string& name = drive.rig_.cameras[camera].name;
    const std::filesystem::path camera_folder = images / name;
    if (!std::filesystem::is_directory(camera_folder, error)) {
      throw InputError(camera_folder, "",
                       "missing camera folder (rig.json has a camera \"" + name + "\")");
    }
    camera_files[camera] = ListImages(camera_folder, options);
    if (camera_files[camera].empty()) {
      throw InputError(
          camera_folder, "",
          "no images (expected files ending in " + JoinWords(options.image_extensions, ", ") + ")");
    }
  }

  std::vector<std::string> all_frames;
  for (const auto& files : camera_files) {
    for (const auto& [frame, file] : files) all_frames.push_back(frame);
  }
  std::sort(all_frames.begin(), all_frames.end(), NaturalLess);
  all_frames.erase(std::unique(all_frames.begin(), all_frames.end()), all_frames.end());

  drive.image_files_.assign(num_cameras, {});
  for (const std::string& frame : all_frames) {
    IncompleteFrame incomplete{frame, {}};
    for (size_t camera = 0; camera < num_cameras; ++camera) {
      if (camera_files[camera].count(frame) == 0) {
        incomplete.missing_cameras.push_back(drive.rig_.cameras[camera].name);
      }
    }
    if (!incomplete.missing_cameras.empty()) {
      drive.incomplete_frames_.push_back(std::move(incomplete));
      continue;
    }
    drive.frame_names_.push_back(frame);
    for (size_t camera = 0; camera < num_cameras; ++camera) {
      drive.image_files_[camera].push_back(camera_files[camera].at(frame));
    }
  }

  if (!drive.incomplete_frames_.empty()) {
    std::vector<std::string> examples;
    for (size_t i = 0; i < drive.incomplete_frames_.size() && i < kIncompleteFramesNamedInWarning;
         ++i) {
      const IncompleteFrame& incomplete = drive.incomplete_frames_[i];
      examples.push_back(incomplete.frame_name + " (missing in " +
                         JoinWords(incomplete.missing_cameras, ", ") + ")");
    }
    if (drive.incomplete_frames_.size() > kIncompleteFramesNamedInWarning)
      examples.push_back("...");
    spdlog::warn("{}: {} frame(s) missing in some camera folders are not used: {}", images.string(),
                 drive.incomplete_frames_.size(), JoinWords(examples, "; "));
  }

  if (std::filesystem::exists(folder / "frames.csv", error))
    drive.timestamps_ = ReadFrameTimestamps(folder / "frames.csv", drive.frame_names_);

  if (static_cast<int>(drive.frame_names_.size()) < options.min_frames) {
    throw InputError(folder, "",
                     "drive too short: " + std::to_string(drive.frame_names_.size()) +
                         " complete frames, at least " + std::to_string(options.min_frames) +
                         " needed");
  }
  return drive;
}

std::vector<double> ReadFrameTimestamps(const std::filesystem::path& frames_csv,
                                        const std::vector<std::string>& frame_names) {
  return ParseFrameTimestamps(ReadInputFile(frames_csv), frames_csv, frame_names);
}

std::vector<double> ParseFrameTimestamps(const std::string& text,
                                         const std::filesystem::path& frames_csv,
                                         const std::vector<std::string>& frame_names) {
  std::istringstream in(text);
  auto split = [](const std::string& line) {
    std::vector<std::string> fields;
    std::string field;
    std::istringstream stream(line);
    while (std::getline(stream, field, ',')) {
      while (!field.empty() && (field.back() == '\r' || field.back() == ' ')) field.pop_back();
      while (!field.empty() && field.front() == ' ') field.erase(field.begin());
      fields.push_back(field);
    }
    return fields;
  };
  std::string line;
  if (!std::getline(in, line)) throw InputError(frames_csv, "line 1", "empty (expected a header)");
  const std::vector<std::string> header = split(line);
  auto column = [&](const std::string& name) {
    const auto it = std::find(header.begin(), header.end(), name);
    if (it == header.end())
      throw InputError(frames_csv, "line 1",
                       "no column \"" + name + "\" (expected frame,camera,timestamp_s)");
    return static_cast<size_t>(it - header.begin());
  };
  const size_t frame_column = column("frame"), time_column = column("timestamp_s");
  const size_t camera_column = column("camera");
  const size_t last_column = std::max({frame_column, time_column, camera_column});
  std::map<std::string, std::pair<double, int>> sums;       // frame -> (sum, rows)
  std::set<std::pair<std::string, std::string>> rows_seen;  // (frame, camera)
  for (int number = 2; std::getline(in, line); ++number) {
    if (line.empty() || line == "\r") continue;
    const std::vector<std::string> fields = split(line);
    const std::string where = "line " + std::to_string(number);
    if (fields.size() <= last_column)
      throw InputError(frames_csv, where,
                       "expected " + std::to_string(header.size()) + " fields, got " +
                           std::to_string(fields.size()));
    if (!rows_seen.emplace(fields[frame_column], fields[camera_column]).second)
      throw InputError(frames_csv, where,
                       "a second row for frame \"" + fields[frame_column] + "\" camera \"" +
                           fields[camera_column] + "\"");
    const std::string& value_text = fields[time_column];
    double value = 0.0;
    if (!ParseDecimal(value_text, &value))
      throw InputError(frames_csv, where,
                       "timestamp_s: " + DecimalProblem(value_text) + " (seconds)");
    auto& [sum, rows] = sums[fields[frame_column]];
    sum += value;
    ++rows;
  }
  std::vector<double> timestamps;
  for (const std::string& frame : frame_names) {
    const auto it = sums.find(frame);
    if (it == sums.end()) throw InputError(frames_csv, "", "no row for frame \"" + frame + "\"");
    timestamps.push_back(it->second.first / it->second.second);
    if (!std::isfinite(timestamps.back()))
      throw InputError(frames_csv, "",
                       "frame \"" + frame + "\": timestamp_s out of range (its mean overflows)");
    if (timestamps.size() > 1 && !(timestamps.back() > timestamps[timestamps.size() - 2]))
      throw InputError(frames_csv, "",
                       "timestamps must increase: frame \"" + frame +
                           "\" is not after the one "
                           "before it");
  }
  return timestamps;
}

std::filesystem::path Drive::ImagePath(size_t frame, size_t camera) const {
  return folder_ / "images" / rig_.cameras.at(camera).name / image_files_.at(camera).at(frame);
}

cv::Mat Drive::LoadGray(size_t frame, size_t camera) const {
  return ReadImage8Bit(ImagePath(frame, camera), cv::IMREAD_GRAYSCALE, rig_.cameras.at(camera));
}

cv::Mat Drive::LoadRgb(size_t frame, size_t camera) const {
  // The file's own channels (IMREAD_COLOR would expand a grey PNG in the decoder, 2.5 times
  // slower), EXIF orientation applied as LoadGray's IMREAD_GRAYSCALE does.
  cv::Mat image = ReadImage8Bit(ImagePath(frame, camera), cv::IMREAD_ANYCOLOR | cv::IMREAD_ANYDEPTH,
                                rig_.cameras.at(camera));
  if (image.channels() == 2) {  // grey and alpha
    cv::Mat grey;
    cv::extractChannel(image, grey, 0);
    image = grey;
  }
  cv::Mat rgb;
  cv::cvtColor(image, rgb,
               image.channels() == 1   ? cv::COLOR_GRAY2RGB
               : image.channels() == 4 ? cv::COLOR_BGRA2RGB
                                       : cv::COLOR_BGR2RGB);
  return rgb;
}

}  // namespace omni
