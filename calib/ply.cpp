#include "calib/ply.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "calib/atomic_file.h"
#include "calib/error.h"
#include "calib/input_file.h"
#include "calib/number_text.h"

namespace omni {
namespace {

enum class PlyFormat { kAscii, kBinaryLittleEndian, kBinaryBigEndian };
enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

std::optional<PlyType> PlyTypeFromName(const std::string& name) {
  if (name == "char" || name == "int8") return PlyType::kInt8;
  if (name == "uchar" || name == "uint8") return PlyType::kUint8;
  if (name == "short" || name == "int16") return PlyType::kInt16;
  if (name == "ushort" || name == "uint16") return PlyType::kUint16;
  if (name == "int" || name == "int32") return PlyType::kInt32;
  if (name == "uint" || name == "uint32") return PlyType::kUint32;
  if (name == "float" || name == "float32") return PlyType::kFloat32;
  if (name == "double" || name == "float64") return PlyType::kFloat64;
  return std::nullopt;
}

size_t PlyTypeSize(PlyType type) {
  switch (type) {
    case PlyType::kInt8:
    case PlyType::kUint8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUint16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 0;
}

bool IsIntegerType(PlyType type) { return type != PlyType::kFloat32 && type != PlyType::kFloat64; }

// The values an integer type holds (ascii values are checked against it).
std::pair<double, double> IntegerRange(PlyType type) {
  switch (type) {
    case PlyType::kInt8:
      return {-128.0, 127.0};
    case PlyType::kUint8:
      return {0.0, 255.0};
    case PlyType::kInt16:
      return {-32768.0, 32767.0};
    case PlyType::kUint16:
      return {0.0, 65535.0};
    case PlyType::kInt32:
      return {-2147483648.0, 2147483647.0};
    case PlyType::kUint32:
      return {0.0, 4294967295.0};
    default:
      return {0.0, 0.0};
  }
}

const char* PlyTypeName(PlyType type) {
  switch (type) {
    case PlyType::kInt8:
      return "char";
    case PlyType::kUint8:
      return "uchar";
    case PlyType::kInt16:
      return "short";
    case PlyType::kUint16:
      return "ushort";
    case PlyType::kInt32:
      return "int";
    case PlyType::kUint32:
      return "uint";
    case PlyType::kFloat32:
      return "float";
    case PlyType::kFloat64:
      return "double";
  }
  return "?";
}

bool HostIsLittleEndian() {
  const uint16_t probe = 1;
  uint8_t first_byte = 0;
  std::memcpy(&first_byte, &probe, 1);
  return first_byte == 1;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;  // the item type for a list
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
};

struct PlyElement {
  std::string name;
  size_t count = 0;
  std::vector<PlyProperty> properties;

  std::optional<size_t> Find(const std::string& property_name) const {
    for (size_t i = 0; i < properties.size(); ++i) {
      if (properties[i].name == property_name) return i;
    }
    return std::nullopt;
  }
};

struct PlyHeader {
  PlyFormat format = PlyFormat::kAscii;
  std::vector<PlyElement> elements;
  size_t data_offset = 0;  // first byte after "end_header\n"
};

std::vector<std::string> SplitWords(const std::string& line) {
  std::istringstream stream(line);
  std::vector<std::string> words;
  for (std::string word; stream >> word;) words.push_back(word);
  return words;
}

PlyHeader ParseHeader(const std::string& data, const std::filesystem::path& path) {
  PlyHeader header;
  size_t position = 0;
  int line_number = 0;
  bool have_format = false;
  auto next_line = [&](std::string* line) {
    if (position >= data.size()) return false;
    size_t end = data.find('\n', position);
    if (end == std::string::npos) end = data.size();
    *line = data.substr(position, end - position);
    if (!line->empty() && line->back() == '\r') line->pop_back();
    position = std::min(end + 1, data.size());
    ++line_number;
    return true;
  };

  std::string line;
  if (!next_line(&line) || line != "ply") {
    throw InputError(path, "", "not a PLY file (the first line is not \"ply\")");
  }
  while (true) {
    if (!next_line(&line)) throw InputError(path, "header", "no end_header line");
    const std::string where = "header line " + std::to_string(line_number);
    const std::vector<std::string> words = SplitWords(line);
    if (words.empty()) continue;
    const std::string& keyword = words[0];
    if (keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "end_header") break;
    if (keyword == "format") {
      if (words.size() != 3 || words[2] != "1.0") {
        throw InputError(path, where, "unsupported format line \"" + line + "\"");
      }
      if (words[1] == "ascii") {
        header.format = PlyFormat::kAscii;
      } else if (words[1] == "binary_little_endian") {
        header.format = PlyFormat::kBinaryLittleEndian;
      } else if (words[1] == "binary_big_endian") {
        header.format = PlyFormat::kBinaryBigEndian;
      } else {
        throw InputError(path, where,
                         "unsupported format \"" + words[1] +
                             "\" (expected ascii, binary_little_endian or binary_big_endian)");
      }
      have_format = true;
    } else if (keyword == "element") {
      char* end = nullptr;
      const long long count = words.size() == 3 ? std::strtoll(words[2].c_str(), &end, 10) : -1;
      if (words.size() != 3 || end != words[2].c_str() + words[2].size() || count < 0) {
        throw InputError(path, where, "expected \"element <name> <count>\", got \"" + line + "\"");
      }
      header.elements.push_back({words[1], static_cast<size_t>(count), {}});
    } else if (keyword == "property") {
      if (header.elements.empty()) {
        throw InputError(path, where, "property before any element");
      }
      PlyProperty property;
      bool ok = false;
      if (words.size() == 5 && words[1] == "list") {
        const auto count_type = PlyTypeFromName(words[2]);
        const auto item_type = PlyTypeFromName(words[3]);
        ok = count_type && item_type && IsIntegerType(*count_type);
        if (ok) {
          property.is_list = true;
          property.count_type = *count_type;
          property.type = *item_type;
          property.name = words[4];
        }
      } else if (words.size() == 3) {
        const auto type = PlyTypeFromName(words[1]);
        ok = type.has_value();
        if (ok) {
          property.type = *type;
          property.name = words[2];
        }
      }
      if (!ok) {
        throw InputError(path, where,
                         "expected \"property <type> <name>\" or \"property list <integer type> "
                         "<type> <name>\", got \"" +
                             line + "\"");
      }
      header.elements.back().properties.push_back(property);
    } else {
      throw InputError(path, where, "unknown header keyword \"" + keyword + "\"");
    }
  }
  if (!have_format) throw InputError(path, "header", "no format line");
  header.data_offset = position;
  return header;
}

// Reads the values of the data section, ascii or binary, as doubles (exact for every PLY
// integer type).
class DataReader {
 public:
  DataReader(const std::string& data, const PlyHeader& header, const std::filesystem::path& path)
      : data_(data),
        position_(header.data_offset),
        format_(header.format),
        swap_(header.format != PlyFormat::kAscii &&
              (header.format == PlyFormat::kBinaryLittleEndian) != HostIsLittleEndian()),
        path_(path) {}

  void SetElement(const std::string& name) { element_ = name; }

  double Read(PlyType type) {
    return format_ == PlyFormat::kAscii ? ReadAscii(type) : ReadBinary(type);
  }

  // Skips `count` rows of fixed size in a binary file; returns false when it cannot (ascii or
  // lists), so the caller reads them value by value.
  bool SkipRows(const PlyElement& element) {
    if (format_ == PlyFormat::kAscii) return false;
    size_t row_size = 0;
    for (const PlyProperty& property : element.properties) {
      if (property.is_list) return false;
      row_size += PlyTypeSize(property.type);
    }
    if (row_size != 0 && element.count > (data_.size() - position_) / row_size) Truncated();
    position_ += row_size * element.count;
    return true;
  }

  [[noreturn]] void Fail(const std::string& problem) const {
    throw InputError(path_, "element " + element_, problem);
  }

  // Whether `items` values of `type` can still follow (each takes at least one byte, or two
  // characters in ascii); a list length that cannot is truncated data.
  void CheckRoomFor(double items, PlyType type) const {
    const double per_item = format_ == PlyFormat::kAscii ? 2.0 : PlyTypeSize(type);
    if (items * per_item > static_cast<double>(data_.size() - position_) + 1.0) Truncated();
  }

  // After the last element: the file must end here (ascii: only white space may follow).
  void ExpectEnd() const {
    size_t end = position_;
    if (format_ == PlyFormat::kAscii) {
      while (end < data_.size() && std::isspace(static_cast<unsigned char>(data_[end]))) ++end;
    }
    if (end != data_.size()) {
      throw InputError(path_, "data",
                       std::to_string(data_.size() - position_) +
                           " byte(s) after the last element of the header (its counts are lower "
                           "than the data)");
    }
  }

 private:
  [[noreturn]] void Truncated() const { Fail("truncated data (the file ends too early)"); }

  double ReadBinary(PlyType type) {
    const size_t size = PlyTypeSize(type);
    if (data_.size() - position_ < size) Truncated();
    unsigned char bytes[8];
    std::memcpy(bytes, data_.data() + position_, size);
    position_ += size;
    if (swap_) std::reverse(bytes, bytes + size);
    switch (type) {
      case PlyType::kInt8: {
        int8_t v;
        std::memcpy(&v, bytes, 1);
        return v;
      }
      case PlyType::kUint8:
        return bytes[0];
      case PlyType::kInt16: {
        int16_t v;
        std::memcpy(&v, bytes, 2);
        return v;
      }
      case PlyType::kUint16: {
        uint16_t v;
        std::memcpy(&v, bytes, 2);
        return v;
      }
      case PlyType::kInt32: {
        int32_t v;
        std::memcpy(&v, bytes, 4);
        return v;
      }
      case PlyType::kUint32: {
        uint32_t v;
        std::memcpy(&v, bytes, 4);
        return v;
      }
      case PlyType::kFloat32: {
        float v;
        std::memcpy(&v, bytes, 4);
        return v;
      }
      case PlyType::kFloat64: {
        double v;
        std::memcpy(&v, bytes, 8);
        return v;
      }
    }
    return 0.0;
  }

  double ReadAscii(PlyType type) {
    while (position_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[position_]))) {
      ++position_;
    }
    if (position_ >= data_.size()) Truncated();
    size_t end = position_;
    while (end < data_.size() && !std::isspace(static_cast<unsigned char>(data_[end]))) ++end;
    const std::string token = data_.substr(position_, end - position_);
    position_ = end;
    double value = 0.0;
    if (IsIntegerType(type)) {
      const auto [low, high] = IntegerRange(type);
      if (!IsDecimalInteger(token) || !ParseDecimal(token, &value) || value < low || value > high) {
        Fail(std::string("expected an integer of type ") + PlyTypeName(type) + ", got \"" +
             token.substr(0, 40) + "\"");
      }
    } else if (!ParseDecimal(token, &value)) {
      Fail(DecimalProblem(token));
    }
    return value;
  }

  const std::string& data_;
  size_t position_;
  PlyFormat format_;
  bool swap_;
  const std::filesystem::path& path_;
  std::string element_;
};

struct PlyContent {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<Eigen::Matrix<uint8_t, 3, 1>> colors;
  std::vector<Eigen::Vector3i> triangles;
  std::vector<uint8_t> labels;  // one per triangle when the faces have a label
};

uint8_t ToColorByte(double value, PlyType type) {
  // Real-valued colours are in [0, 1] by PLY custom; integer ones in [0, 255].
  const double scaled = IsIntegerType(type) ? value : value * 255.0;
  return static_cast<uint8_t>(std::clamp(std::round(scaled), 0.0, 255.0));
}

std::optional<size_t> FindColor(const PlyElement& element, const std::string& channel) {
  if (auto index = element.Find(channel)) return index;
  return element.Find("diffuse_" + channel);
}

PlyContent ParsePly(const std::string& data, const std::filesystem::path& path, bool read_faces) {
  const PlyHeader header = ParseHeader(data, path);

  const PlyElement* vertex_element = nullptr;
  for (const PlyElement& element : header.elements) {
    if (element.name == "vertex") vertex_element = &element;
  }
  if (!vertex_element) throw InputError(path, "header", "no vertex element");
  size_t xyz[3];
  const char* axis_names[3] = {"x", "y", "z"};
  for (int axis = 0; axis < 3; ++axis) {
    const auto index = vertex_element->Find(axis_names[axis]);
    if (!index || vertex_element->properties[*index].is_list) {
      throw InputError(path, "element vertex",
                       std::string("no scalar property ") + axis_names[axis]);
    }
    xyz[axis] = *index;
  }
  std::optional<size_t> rgb[3] = {FindColor(*vertex_element, "red"),
                                  FindColor(*vertex_element, "green"),
                                  FindColor(*vertex_element, "blue")};
  const bool has_colors =
      rgb[0] && rgb[1] && rgb[2] && !vertex_element->properties[*rgb[0]].is_list &&
      !vertex_element->properties[*rgb[1]].is_list && !vertex_element->properties[*rgb[2]].is_list;

  PlyContent content;
  DataReader reader(data, header, path);
  std::vector<double> row;
  for (const PlyElement& element : header.elements) {
    reader.SetElement(element.name);
    const bool is_vertex = &element == vertex_element;
    std::optional<size_t> indices_property;
    bool has_label = false;  // the face's property label_index is a label of ours
    size_t label_index = 0;
    if (read_faces && element.name == "face") {
      indices_property = element.Find("vertex_indices");
      if (!indices_property) indices_property = element.Find("vertex_index");
      if (!indices_property || !element.properties[*indices_property].is_list ||
          !IsIntegerType(element.properties[*indices_property].type)) {
        throw InputError(path, "element face",
                         "no integer list property vertex_indices or vertex_index");
      }
      // Labels are optional: a property of another kind (a list, a real number) is not ours.
      if (const auto label = element.Find("label")) {
        has_label =
            !element.properties[*label].is_list && IsIntegerType(element.properties[*label].type);
        label_index = *label;
      }
    }
    if (!is_vertex && !indices_property) {
      if (reader.SkipRows(element)) continue;
    }
    // Every row takes at least one byte, so a count larger than the file is caught as truncated
    // data instead of reserving memory for it.
    const size_t plausible_count = std::min(element.count, data.size());
    if (is_vertex) {
      content.vertices.reserve(plausible_count);
      if (has_colors) content.colors.reserve(plausible_count);
    }
    if (indices_property) content.triangles.reserve(content.triangles.size() + plausible_count);
    if (element.properties.empty()) continue;  // rows without properties hold no data

    row.resize(element.properties.size());
    std::vector<int> polygon;
    for (size_t item = 0; item < element.count; ++item) {
      for (size_t p = 0; p < element.properties.size(); ++p) {
        const PlyProperty& property = element.properties[p];
        if (!property.is_list) {
          row[p] = reader.Read(property.type);
          continue;
        }
        const double count = reader.Read(property.count_type);
        if (count < 0) reader.Fail("negative list length");
        reader.CheckRoomFor(count, property.type);
        const bool is_indices = indices_property && *indices_property == p;
        if (is_indices) polygon.clear();
        for (size_t k = 0; k < static_cast<size_t>(count); ++k) {
          const double value = reader.Read(property.type);
          if (is_indices) {
            if (value < 0 || value >= static_cast<double>(vertex_element->count) ||
                value > std::numeric_limits<int>::max()) {
              std::ostringstream problem;
              problem << "face " << item << ": vertex index " << value << " out of range [0, "
                      << vertex_element->count << ")";
              reader.Fail(problem.str());
            }
            polygon.push_back(static_cast<int>(value));
          }
        }
        if (is_indices) {
          if (polygon.size() < 3) {
            reader.Fail("face " + std::to_string(item) + " has " + std::to_string(polygon.size()) +
                        " vertices, at least 3 needed");
          }
          // A polygon becomes a fan of triangles around its first vertex.
          for (size_t k = 1; k + 1 < polygon.size(); ++k) {
            content.triangles.emplace_back(polygon[0], polygon[k], polygon[k + 1]);
          }
        }
      }
      if (has_label) {
        // Read after the whole row: the property may come before or after the indices. Values
        // beyond a byte (another program's ids) are not labels of ours: the mesh has none.
        const double label = row[label_index];
        if (label >= 0.0 && label <= 255.0) {
          content.labels.resize(content.triangles.size(), static_cast<uint8_t>(label));
        } else {
          has_label = false;
          content.labels.clear();
        }
      }
      if (is_vertex) {
        const Eigen::Vector3d vertex(row[xyz[0]], row[xyz[1]], row[xyz[2]]);
        if (!vertex.allFinite()) {
          std::ostringstream problem;
          problem << "vertex " << item << ": expected finite coordinates, got " << vertex.x() << " "
                  << vertex.y() << " " << vertex.z();
          reader.Fail(problem.str());
        }
        content.vertices.push_back(vertex);
        if (has_colors) {
          Eigen::Matrix<uint8_t, 3, 1> color;
          for (int c = 0; c < 3; ++c) {
            if (!std::isfinite(row[*rgb[c]])) {
              std::ostringstream problem;
              problem << "vertex " << item << ": expected a finite colour, got " << row[*rgb[c]];
              reader.Fail(problem.str());
            }
            color[c] = ToColorByte(row[*rgb[c]], element.properties[*rgb[c]].type);
          }
          content.colors.push_back(color);
        }
      }
    }
  }
  reader.ExpectEnd();
  return content;
}

// Appends the little-endian bytes of a value.
template <typename T>
void PutLittleEndian(T value, std::string* out) {
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  if (!HostIsLittleEndian()) std::reverse(bytes, bytes + sizeof(T));
  out->append(bytes, sizeof(T));
}

void PutVertex(const Eigen::Vector3d& vertex, std::string* out) {
  for (int axis = 0; axis < 3; ++axis) PutLittleEndian(static_cast<float>(vertex[axis]), out);
}

}  // namespace

TriangleMesh ReadPlyMesh(const std::filesystem::path& path) {
  return ParsePlyMesh(ReadInputFile(path), path);
}

PointCloud ReadPlyPoints(const std::filesystem::path& path) {
  return ParsePlyPoints(ReadInputFile(path), path);
}

TriangleMesh ParsePlyMesh(const std::string& data, const std::filesystem::path& source) {
  PlyContent content = ParsePly(data, source, /*read_faces=*/true);
  TriangleMesh mesh;
  mesh.vertices = std::move(content.vertices);
  mesh.triangles = std::move(content.triangles);
  mesh.colors = std::move(content.colors);
  mesh.labels = std::move(content.labels);
  return mesh;
}

PointCloud ParsePlyPoints(const std::string& data, const std::filesystem::path& source) {
  PlyContent content = ParsePly(data, source, /*read_faces=*/false);
  PointCloud cloud;
  cloud.points = std::move(content.vertices);
  cloud.colors = std::move(content.colors);
  return cloud;
}

void WritePlyMesh(const TriangleMesh& mesh, const std::filesystem::path& path) {
  const bool has_colors = !mesh.colors.empty();
  if (has_colors && mesh.colors.size() != mesh.vertices.size()) {
    throw std::invalid_argument("WritePlyMesh: " + std::to_string(mesh.colors.size()) +
                                " colours for " + std::to_string(mesh.vertices.size()) +
                                " vertices");
  }
  const bool has_labels = !mesh.labels.empty();
  if (has_labels && mesh.labels.size() != mesh.triangles.size()) {
    throw std::invalid_argument("WritePlyMesh: " + std::to_string(mesh.labels.size()) +
                                " labels for " + std::to_string(mesh.triangles.size()) +
                                " triangles");
  }
  std::string out;
  out += "ply\nformat binary_little_endian 1.0\ncomment written by omnisculpt\n";
  out += "element vertex " + std::to_string(mesh.vertices.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  if (has_colors) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out += "element face " + std::to_string(mesh.triangles.size()) + "\n";
  out += "property list uchar int vertex_indices\n";
  if (has_labels) out += "property uchar label\n";
  out += "end_header\n";
  out.reserve(out.size() + mesh.vertices.size() * (has_colors ? 15 : 12) +
              mesh.triangles.size() * (has_labels ? 14 : 13));
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    PutVertex(mesh.vertices[i], &out);
    if (has_colors) {
      for (int c = 0; c < 3; ++c) PutLittleEndian(mesh.colors[i][c], &out);
    }
  }
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    PutLittleEndian(static_cast<uint8_t>(3), &out);
    for (int k = 0; k < 3; ++k) PutLittleEndian(static_cast<int32_t>(mesh.triangles[t][k]), &out);
    if (has_labels) PutLittleEndian(mesh.labels[t], &out);
  }
  WriteFileAtomically(
      path, [&](std::ostream& stream) { stream.write(out.data(), out.size()); }, true);
}

void WritePlyPoints(const PointCloud& cloud, const std::filesystem::path& path) {
  const bool has_colors = !cloud.colors.empty();
  if (has_colors && cloud.colors.size() != cloud.points.size()) {
    throw std::invalid_argument("WritePlyPoints: " + std::to_string(cloud.colors.size()) +
                                " colours for " + std::to_string(cloud.points.size()) + " points");
  }
  std::string out;
  out += "ply\nformat binary_little_endian 1.0\ncomment written by omnisculpt\n";
  out += "element vertex " + std::to_string(cloud.points.size()) + "\n";
  out += "property float x\nproperty float y\nproperty float z\n";
  if (has_colors) out += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  out += "end_header\n";
  out.reserve(out.size() + cloud.points.size() * (has_colors ? 15 : 12));
  for (size_t i = 0; i < cloud.points.size(); ++i) {
    PutVertex(cloud.points[i], &out);
    if (has_colors) {
      for (int c = 0; c < 3; ++c) PutLittleEndian(cloud.colors[i][c], &out);
    }
  }
  WriteFileAtomically(
      path, [&](std::ostream& stream) { stream.write(out.data(), out.size()); }, true);
}

}  // namespace omni
