#include "pipeline/io/ply_format.h"

#include <fmt/format.h>

#include <limits>

#include "pipeline/io/text_fields.h"

namespace iso::io {
namespace {

// Guards against headers that would make one record absurdly large.
constexpr size_t kMaxProperties = 4096;

std::optional<PlyType> parseType(std::string_view name) {
  struct Named {
    std::string_view name;
    PlyType type;
  };
  static constexpr Named kTypes[] = {
      {"char", PlyType::Int8},      {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
      {"uint8", PlyType::UInt8},    {"short", PlyType::Int16},     {"int16", PlyType::Int16},
      {"ushort", PlyType::UInt16},  {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
      {"int32", PlyType::Int32},    {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
      {"float", PlyType::Float32},  {"float32", PlyType::Float32}, {"double", PlyType::Float64},
      {"float64", PlyType::Float64}};
  for (const Named& named : kTypes)
    if (named.name == name) return named.type;
  return std::nullopt;
}

std::vector<std::string_view> splitFields(std::string_view line) {
  std::vector<std::string_view> fields;
  std::string_view field;
  while (nextField<isBlank>(line, field)) fields.push_back(field);
  return fields;
}

PlyType requireType(const InputStream& in, std::string_view name) {
  const std::optional<PlyType> type = parseType(name);
  if (!type) in.failLine(fmt::format("unknown property type '{}'", name));
  return *type;
}

void parseFormat(const InputStream& in, const std::vector<std::string_view>& fields,
                 PlyHeader& header) {
  if (fields.size() != 3) in.failLine("expected 'format ENCODING 1.0'");
  if (fields[1] == "ascii") {
    header.encoding = PlyEncoding::Ascii;
  } else if (fields[1] == "binary_little_endian") {
    header.encoding = PlyEncoding::BinaryLittleEndian;
  } else if (fields[1] == "binary_big_endian") {
    header.encoding = PlyEncoding::BinaryBigEndian;
  } else {
    in.failLine(fmt::format("unknown PLY format '{}'", fields[1]));
  }
  if (fields[2] != "1.0") in.failLine(fmt::format("unsupported PLY version '{}'", fields[2]));
}

void parseElement(const InputStream& in, const std::vector<std::string_view>& fields,
                  PlyHeader& header) {
  int64_t count = 0;
  if (fields.size() != 3 || !parseInteger(fields[2], count) || count < 0)
    in.failLine("expected 'element NAME COUNT' with a count of at least 0");
  header.elements.push_back({std::string(fields[1]), static_cast<uint64_t>(count), {}});
}

void parseProperty(const InputStream& in, const std::vector<std::string_view>& fields,
                   PlyHeader& header) {
  if (header.elements.empty()) in.failLine("a property before any element");
  PlyElement& element = header.elements.back();
  if (element.properties.size() >= kMaxProperties)
    in.failLine(
        fmt::format("more than {} properties in element '{}'", kMaxProperties, element.name));
  if (fields.size() == 3) {
    element.properties.push_back({std::string(fields[2]), requireType(in, fields[1]), {}});
    return;
  }
  if (fields.size() != 5 || fields[1] != "list")
    in.failLine("expected 'property TYPE NAME' or 'property list COUNT_TYPE TYPE NAME'");
  const PlyType countType = requireType(in, fields[2]);
  if (!isPlyInteger(countType)) in.failLine("a list count type must be an integer type");
  element.properties.push_back({std::string(fields[4]), requireType(in, fields[3]), countType});
}

[[noreturn]] void failEndsEarly(const InputStream& in, const PlyElement& element, uint64_t done) {
  in.fail(fmt::format("file ends after {} of {} '{}' records", done, element.count, element.name));
}

void skipBinaryRecordsWithLists(InputStream& in, PlyEncoding encoding, const PlyElement& element) {
  for (uint64_t record = 0; record < element.count; ++record) {
    uint64_t bytes = 0;  // scalars not yet skipped
    for (const PlyProperty& property : element.properties) {
      if (!property.isList()) {
        bytes += plyTypeSize(property.type);
        continue;
      }
      if (in.skip(bytes) != bytes) failEndsEarly(in, element, record);
      bytes = readPlyListCount(in, encoding, *property.countType) * plyTypeSize(property.type);
    }
    if (in.skip(bytes) != bytes) failEndsEarly(in, element, record);
  }
}

}  // namespace

size_t plyTypeSize(PlyType type) {
  switch (type) {
    case PlyType::Int8:
    case PlyType::UInt8:
      return 1;
    case PlyType::Int16:
    case PlyType::UInt16:
      return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32:
      return 4;
    case PlyType::Float64:
      return 8;
  }
  return 0;
}

bool isPlyInteger(PlyType type) { return type != PlyType::Float32 && type != PlyType::Float64; }

const char* plyFormatName(PlyEncoding encoding) {
  switch (encoding) {
    case PlyEncoding::Ascii:
      return "ply-ascii";
    case PlyEncoding::BinaryLittleEndian:
      return "ply-binary-le";
    case PlyEncoding::BinaryBigEndian:
      return "ply-binary-be";
  }
  return "ply";
}

bool PlyElement::hasLists() const {
  for (const PlyProperty& property : properties)
    if (property.isList()) return true;
  return false;
}

size_t PlyElement::scalarBytes() const {
  size_t bytes = 0;
  for (const PlyProperty& property : properties)
    if (!property.isList()) bytes += plyTypeSize(property.type);
  return bytes;
}

std::optional<size_t> PlyElement::find(std::initializer_list<std::string_view> names) const {
  for (size_t i = 0; i < properties.size(); ++i)
    for (std::string_view name : names)
      if (properties[i].name == name) return i;
  return std::nullopt;
}

std::optional<size_t> PlyHeader::find(std::string_view name) const {
  for (size_t i = 0; i < elements.size(); ++i)
    if (elements[i].name == name) return i;
  return std::nullopt;
}

PlyHeader readPlyHeader(InputStream& in) {
  std::string_view line;
  if (!in.readLine(line) || line != "ply")
    in.failLine("not a PLY file: it does not start with 'ply'");
  PlyHeader header;
  bool hasFormat = false;
  for (;;) {
    if (!in.readLine(line)) in.fail("the PLY header has no end_header line");
    const std::vector<std::string_view> fields = splitFields(line);
    if (fields.empty() || fields[0] == "comment" || fields[0] == "obj_info") continue;
    if (fields[0] == "end_header") break;
    if (fields[0] == "format") {
      parseFormat(in, fields, header);
      hasFormat = true;
    } else if (fields[0] == "element") {
      parseElement(in, fields, header);
    } else if (fields[0] == "property") {
      parseProperty(in, fields, header);
    } else {
      in.failLine(fmt::format("unknown PLY header line '{}'", line));
    }
  }
  if (!hasFormat) in.failLine("the PLY header has no format line");
  return header;
}

uint64_t readPlyListCount(InputStream& in, PlyEncoding encoding, PlyType countType) {
  const size_t size = plyTypeSize(countType);
  const std::span<const std::byte> bytes = in.peek(size);
  if (bytes.size() < size) in.fail("file ends inside a list");
  const int64_t count = loadPlyInteger(encoding, countType, bytes.data());
  if (count < 0) in.fail(fmt::format("negative list length {}", count));
  in.consume(size);
  return static_cast<uint64_t>(count);
}

void skipPlyElement(InputStream& in, PlyEncoding encoding, const PlyElement& element) {
  if (encoding == PlyEncoding::Ascii) {
    std::string_view line;
    for (uint64_t record = 0; record < element.count;) {
      if (!in.readLine(line)) failEndsEarly(in, element, record);
      if (line.find_first_not_of(" \t\r") != std::string_view::npos) ++record;
    }
    return;
  }
  if (element.hasLists()) return skipBinaryRecordsWithLists(in, encoding, element);
  const uint64_t recordBytes = element.scalarBytes();
  if (recordBytes == 0) return;
  if (element.count > std::numeric_limits<uint64_t>::max() / recordBytes)
    in.fail(fmt::format("element '{}' claims {} records, more than any file holds", element.name,
                        element.count));
  const uint64_t skipped = in.skip(element.count * recordBytes);
  if (skipped < element.count * recordBytes) failEndsEarly(in, element, skipped / recordBytes);
}

}  // namespace iso::io
