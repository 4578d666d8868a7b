#include "calib/tum.h"

#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/input_file.h"
#include "calib/number_text.h"

namespace omni {
namespace {

// A quaternion whose norm is within this of 1 is normalised; others are rejected.
constexpr double kQuaternionNormTolerance = 1e-3;
// Within this of 1 it is kept as written, so that a write/read round trip is exact.
constexpr double kQuaternionExactTolerance = 1e-12;

constexpr int kNumTumFields = 8;

}  // namespace

std::vector<StampedPose> ParseTum(const std::string& text, const std::filesystem::path& source) {
  std::vector<StampedPose> poses;
  std::istringstream stream(text);
  std::string line;
  int line_number = 0;
  while (std::getline(stream, line)) {
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const size_t first = line.find_first_not_of(" \t");
    if (first == std::string::npos || line[first] == '#') continue;
    const std::string where = "line " + std::to_string(line_number);

    std::istringstream fields(line);
    std::vector<std::string> tokens;
    for (std::string token; fields >> token;) tokens.push_back(token);
    if (tokens.size() != kNumTumFields) {
      throw InputError(source, where,
                       "expected 8 values (timestamp tx ty tz qx qy qz qw), got " +
                           std::to_string(tokens.size()));
    }
    double values[kNumTumFields];
    for (int i = 0; i < kNumTumFields; ++i) {
      if (!ParseDecimal(tokens[i], &values[i])) {
        throw InputError(source, where,
                         "value " + std::to_string(i + 1) + ": " + DecimalProblem(tokens[i]));
      }
    }
    if (!poses.empty() && !(values[0] > poses.back().timestamp)) {
      throw InputError(source, where,
                       "timestamps must increase: " + tokens[0] + " is not after the line before");
    }
    // TUM order: qx qy qz qw; Eigen's constructor takes w first.
    Eigen::Quaterniond rotation(values[7], values[4], values[5], values[6]);
    const double norm = rotation.norm();
    if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) {
      std::ostringstream problem;
      problem << "expected a unit quaternion qx qy qz qw, norm is " << norm;
      throw InputError(source, where, problem.str());
    }
    if (std::abs(norm - 1.0) > kQuaternionExactTolerance) rotation.normalize();
    StampedPose pose;
    pose.timestamp = values[0];
    pose.world_from_rig = Rigid3d(rotation, Eigen::Vector3d(values[1], values[2], values[3]));
    poses.push_back(pose);
  }
  return poses;
}

std::vector<StampedPose> ReadTum(const std::filesystem::path& path) {
  return ParseTum(ReadInputFile(path), path);
}

void WriteTum(const std::vector<StampedPose>& poses, const std::filesystem::path& path) {
  WriteFileAtomically(path, [&](std::ostream& stream) {
    stream << "# timestamp tx ty tz qx qy qz qw (world_from_rig)\n";
    char buffer[512];
    for (const StampedPose& pose : poses) {
      const Eigen::Vector3d& t = pose.world_from_rig.translation;
      const Eigen::Quaterniond& q = pose.world_from_rig.rotation;
      // Timestamps to the nanosecond; the rest with enough digits to read back the same bits.
      std::snprintf(buffer, sizeof(buffer), "%.9f %.17g %.17g %.17g %.17g %.17g %.17g %.17g\n",
                    pose.timestamp, t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w());
      stream << buffer;
    }
  });
}

}  // namespace omni
