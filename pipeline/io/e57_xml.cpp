// The E57 XML section through expat (ASTM E2807 sections 8.4 "XML section", 9.2 "Data3D", 9.3
// "Pose", 9.12 "ColorLimits" and Table 26 "CompressedVector"): an element stack of roles, so that
// only /e57Root/data3D/vectorChild and what the reader needs below it are kept.
#include "pipeline/io/e57_xml.h"

#include <expat.h>
#include <fmt/format.h>

#include <algorithm>
#include <bit>
#include <charconv>
#include <cmath>
#include <exception>
#include <limits>
#include <memory>
#include <string_view>

#include "iso/error.h"
#include "base/text.h"

namespace iso::io {
namespace {

// XML bytes handed to expat at a time.
constexpr size_t kChunkBytes = size_t{64} << 10;
// Names and GUIDs are kept for messages only.
constexpr size_t kMaxNameBytes = 100;
// The text of a number element; longer is refused as malformed.
constexpr size_t kMaxNumberText = 1024;

// What an element is to the reader, from its parent's role and its name.
enum class Role : uint8_t {
  kDocument,  // above the root element
  kOther,     // skipped with everything inside it
  kRoot,
  kData3D,
  kScan,  // data3D/vectorChild
  kScanName,
  kScanGuid,
  kPose,
  kRotation,
  kTranslation,
  kColorLimits,
  kNumber,  // a value the reader keeps (pose component, color limit)
  kPoints,
  kPrototype,
  kField,
  kCodecs
};

struct Frame {
  Role role = Role::kOther;
  std::string name;
  // kNumber: its type and scaling, and where the value goes.
  std::string type;
  double scale = 1.0;
  double offset = 0.0;
  std::optional<double>* target = nullptr;
};

// What a scan's elements gave, before the reader checks it.
struct ScanParts {
  std::array<std::optional<double>, 4> rotation;  // w x y z
  std::array<std::optional<double>, 3> translation;
  bool hasRotation = false;
  bool hasTranslation = false;
  bool hasPoints = false;
  bool hasPrototype = false;
};

constexpr std::array<std::string_view, 4> kQuaternionNames = {"w", "x", "y", "z"};
constexpr std::array<std::string_view, 3> kTranslationNames = {"x", "y", "z"};
constexpr std::array<std::string_view, 6> kColorLimitNames = {
    "colorRedMinimum",   "colorRedMaximum",  "colorGreenMinimum",
    "colorGreenMaximum", "colorBlueMinimum", "colorBlueMaximum"};

std::string_view trimmed(std::string_view text) {
  const auto isSpace = [](char c) { return c == ' ' || c == '\t' || c == '\r' || c == '\n'; };
  while (!text.empty() && isSpace(text.front())) text.remove_prefix(1);
  while (!text.empty() && isSpace(text.back())) text.remove_suffix(1);
  return text;
}

// At most kMaxNameBytes bytes of a name, cut at a UTF-8 character boundary.
std::string shortName(std::string_view text) {
  if (text.size() <= kMaxNameBytes) return std::string(text);
  size_t size = kMaxNameBytes;
  while (size > 0 && (static_cast<unsigned char>(text[size]) & 0xC0u) == 0x80u) --size;
  return std::string(text.substr(0, size));
}

const char* attribute(const XML_Char** attributes, std::string_view name) {
  for (; attributes[0] != nullptr; attributes += 2)
    if (name == attributes[0]) return attributes[1];
  return nullptr;
}

template <size_t N>
int indexOf(const std::array<std::string_view, N>& names, std::string_view name) {
  const auto* found = std::find(names.begin(), names.end(), name);
  return found == names.end() ? -1 : static_cast<int>(found - names.begin());
}

class XmlParser {
 public:
  XmlParser(E57Pages& pages, const E57Header& header) : pages_(pages), header_(header) {
    parser_ = XML_ParserCreate(nullptr);
    if (parser_ == nullptr) throw std::bad_alloc();
    XML_SetUserData(parser_, this);
    XML_SetElementHandler(parser_, &XmlParser::onStart, &XmlParser::onEnd);
    XML_SetCharacterDataHandler(parser_, &XmlParser::onText);
    XML_SetStartDoctypeDeclHandler(parser_, &XmlParser::onDoctype);
    XML_SetEntityDeclHandler(parser_, &XmlParser::onEntity);
    XML_SetParamEntityParsing(parser_, XML_PARAM_ENTITY_PARSING_NEVER);
  }
  ~XmlParser() { XML_ParserFree(parser_); }
  XmlParser(const XmlParser&) = delete;
  XmlParser& operator=(const XmlParser&) = delete;

  std::vector<E57Scan> parse() {
    xmlStart_ = checkedXmlStart();
    const uint64_t length = header_.xmlLogicalLength;
    std::vector<std::byte> chunk(static_cast<size_t>(std::min<uint64_t>(length, kChunkBytes)));
    for (uint64_t done = 0; done < length;) {
      const size_t count = static_cast<size_t>(std::min<uint64_t>(chunk.size(), length - done));
      pages_.read(xmlStart_ + done, chunk.data(), count);
      done += count;
      const XML_Status status = XML_Parse(parser_, reinterpret_cast<const char*>(chunk.data()),
                                          static_cast<int>(count), done == length);
      if (error_) std::rethrow_exception(error_);
      if (status != XML_STATUS_OK) fail(XML_ErrorString(XML_GetErrorCode(parser_)));
    }
    return std::move(scans_);
  }

 private:
  // Where the XML section starts in the logical stream, after checking that it lies in the file.
  uint64_t checkedXmlStart() const {
    InputStream& in = pages_.stream();
    const std::optional<uint64_t> start = pages_.logicalOffset(header_.xmlPhysicalOffset);
    if (!start)
      in.failAt(header_.xmlPhysicalOffset,
                fmt::format("the XML section's offset {} is past the end of the file or inside a "
                            "page checksum",
                            header_.xmlPhysicalOffset));
    if (header_.xmlLogicalLength == 0)
      in.failAt(header_.xmlPhysicalOffset, "the XML section is empty");
    if (header_.xmlLogicalLength > kE57MaxXmlBytes)
      in.failAt(header_.xmlPhysicalOffset,
                fmt::format("the XML section has {} bytes, more than the {} supported",
                            withSeparators(header_.xmlLogicalLength), byteSize(kE57MaxXmlBytes)));
    if (header_.xmlLogicalLength > pages_.logicalLength() - *start)
      in.failAt(header_.xmlPhysicalOffset,
                fmt::format("the XML section ({} bytes) runs past the end of the file",
                            withSeparators(header_.xmlLogicalLength)));
    return *start;
  }

  // Throw a FileError at the parser's position: the file's byte and the XML line.
  [[noreturn]] void fail(const std::string& reason) const {
    const XML_Index index = XML_GetCurrentByteIndex(parser_);
    const uint64_t logical =
        xmlStart_ + std::min<uint64_t>(index < 0 ? 0 : uint64_t(index), header_.xmlLogicalLength);
    pages_.stream().failAt(
        pages_.physicalOffset(logical),
        fmt::format("XML line {}: {}", XML_GetCurrentLineNumber(parser_), reason));
  }

  [[noreturn]] void failInScan(const std::string& reason) const {
    fail(fmt::format("{}: {}", e57ScanLabel(scans_.back(), scans_.size() - 1), reason));
  }

  // Run a handler's work; an exception stops the parser and is rethrown after XML_Parse returns,
  // so that none crosses expat's C frames.
  template <typename Work>
  static void guarded(void* user, Work&& work) {
    auto& self = *static_cast<XmlParser*>(user);
    if (self.error_) return;
    try {
      work(self);
    } catch (...) {
      self.error_ = std::current_exception();
      XML_StopParser(self.parser_, XML_FALSE);
    }
  }

  static void XMLCALL onStart(void* user, const XML_Char* name, const XML_Char** attributes) {
    guarded(user, [&](XmlParser& self) { self.start(name, attributes); });
  }
  static void XMLCALL onEnd(void* user, const XML_Char*) {
    guarded(user, [&](XmlParser& self) { self.end(); });
  }
  static void XMLCALL onText(void* user, const XML_Char* text, int length) {
    guarded(user, [&](XmlParser& self) { self.addText({text, static_cast<size_t>(length)}); });
  }
  static void XMLCALL onDoctype(void* user, const XML_Char*, const XML_Char*, const XML_Char*,
                                int) {
    guarded(user, [&](XmlParser& self) {
      self.fail(
          "the XML section has a DOCTYPE declaration, which E57 never needs (refused, so "
          "that no entity is expanded)");
    });
  }
  static void XMLCALL onEntity(void* user, const XML_Char* name, int, const XML_Char*, int,
                               const XML_Char*, const XML_Char*, const XML_Char*, const XML_Char*) {
    guarded(user, [&](XmlParser& self) {
      self.fail(
          fmt::format("the XML section declares an entity ('{:.40}'), which E57 never "
                      "needs",
                      name));
    });
  }

  void start(std::string_view name, const XML_Char** attributes) {
    if (stack_.size() >= kE57MaxXmlDepth)
      fail(fmt::format("elements nest deeper than {} levels", kE57MaxXmlDepth));
    const Role parent = stack_.empty() ? Role::kDocument : stack_.back().role;
    Frame frame;
    frame.role = roleOf(parent, name);
    frame.name = name;
    switch (frame.role) {
      case Role::kScan:
        if (scans_.size() == kE57MaxScans)
          fail(fmt::format("data3D holds more than {} point clouds, the most supported",
                           withSeparators(kE57MaxScans)));
        scans_.emplace_back();
        parts_ = {};
        break;
      case Role::kRotation:
        parts_.hasRotation = true;
        break;
      case Role::kTranslation:
        parts_.hasTranslation = true;
        break;
      case Role::kNumber:
        frame.type = valueOr(attribute(attributes, "type"), "");
        frame.scale = optionalNumber(attributes, "scale", frame.name).value_or(1.0);
        frame.offset = optionalNumber(attributes, "offset", frame.name).value_or(0.0);
        frame.target = numberTarget(parent, name);
        break;
      case Role::kPoints:
        startPoints(attributes);
        break;
      case Role::kPrototype:
        if (parts_.hasPrototype) failInScan("its points have two prototype elements");
        parts_.hasPrototype = true;
        break;
      case Role::kField:
        addField(name, attributes);
        break;
      default:
        break;
    }
    text_.clear();
    stack_.push_back(std::move(frame));
  }

  Role roleOf(Role parent, std::string_view name) {
    switch (parent) {
      case Role::kDocument:
        if (name != "e57Root") fail(fmt::format("the root element is '{:.40}', not e57Root", name));
        return Role::kRoot;
      case Role::kRoot:
        return name == "data3D" ? Role::kData3D : Role::kOther;
      case Role::kData3D:
        return name == "vectorChild" ? Role::kScan : Role::kOther;
      case Role::kScan:
        if (name == "name") return Role::kScanName;
        if (name == "guid") return Role::kScanGuid;
        if (name == "pose") return Role::kPose;
        if (name == "colorLimits") return Role::kColorLimits;
        if (name == "points") return Role::kPoints;
        return Role::kOther;
      case Role::kPose:
        if (name == "rotation") return Role::kRotation;
        if (name == "translation") return Role::kTranslation;
        return Role::kOther;
      case Role::kRotation:
        return indexOf(kQuaternionNames, name) >= 0 ? Role::kNumber : Role::kOther;
      case Role::kTranslation:
        return indexOf(kTranslationNames, name) >= 0 ? Role::kNumber : Role::kOther;
      case Role::kColorLimits:
        return indexOf(kColorLimitNames, name) >= 0 ? Role::kNumber : Role::kOther;
      case Role::kPoints:
        if (name == "prototype") return Role::kPrototype;
        if (name == "codecs") return Role::kCodecs;
        return Role::kOther;
      case Role::kPrototype:
        return Role::kField;
      case Role::kField:
        failInScan(
            fmt::format("its prototype field '{:.40}' holds an element ('{:.40}'): nested "
                        "fields are not supported",
                        stack_.back().name, name));
      case Role::kCodecs:
        failInScan(
            fmt::format("its points name a codec ('{:.40}'): only the default bitpack "
                        "codec is supported",
                        name));
      default:
        return Role::kOther;
    }
  }

  std::optional<double>* numberTarget(Role parent, std::string_view name) {
    E57Scan& scan = scans_.back();
    switch (parent) {
      case Role::kRotation:
        return &parts_.rotation[size_t(indexOf(kQuaternionNames, name))];
      case Role::kTranslation:
        return &parts_.translation[size_t(indexOf(kTranslationNames, name))];
      default: {
        const auto limit = size_t(indexOf(kColorLimitNames, name));
        return limit % 2 == 0 ? &scan.colorMinimum[limit / 2] : &scan.colorMaximum[limit / 2];
      }
    }
  }

  void startPoints(const XML_Char** attributes) {
    if (parts_.hasPoints) failInScan("it has two points elements");
    parts_.hasPoints = true;
    const std::string_view type = valueOr(attribute(attributes, "type"), "");
    if (type != "CompressedVector")
      failInScan(fmt::format("its points element has type '{:.40}', not CompressedVector", type));
    E57Scan& scan = scans_.back();
    scan.fileOffset = requiredCount(attributes, "fileOffset");
    scan.recordCount = requiredCount(attributes, "recordCount");
  }

  uint64_t requiredCount(const XML_Char** attributes, std::string_view name) const {
    const char* text = attribute(attributes, name);
    if (text == nullptr) failInScan(fmt::format("its points element has no {} attribute", name));
    const std::string_view value = trimmed(text);
    uint64_t count = 0;
    const auto [end, error] = std::from_chars(value.data(), value.data() + value.size(), count);
    if (error != std::errc() || end != value.data() + value.size() || value.empty())
      failInScan(fmt::format("its points' {} '{:.40}' is not a non-negative integer", name, text));
    return count;
  }

  static std::string_view valueOr(const char* text, std::string_view fallback) {
    return text != nullptr ? std::string_view(text) : fallback;
  }

  // A finite number attribute, or nullopt when absent.
  std::optional<double> optionalNumber(const XML_Char** attributes, std::string_view name,
                                       std::string_view element) const {
    const char* text = attribute(attributes, name);
    if (text == nullptr) return std::nullopt;
    double value = 0.0;
    if (!parseNumber(trimmed(text), value) || !std::isfinite(value))
      failInScan(
          fmt::format("the {} of '{:.40}' is '{:.40}', not a finite number", name, element, text));
    return value;
  }

  std::optional<int64_t> optionalInteger(const XML_Char** attributes, std::string_view name,
                                         std::string_view element) const {
    const char* text = attribute(attributes, name);
    if (text == nullptr) return std::nullopt;
    int64_t value = 0;
    if (!parseInteger(trimmed(text), value))
      failInScan(
          fmt::format("the {} of '{:.40}' is '{:.40}', not a 64-bit integer", name, element, text));
    return value;
  }

  void addField(std::string_view name, const XML_Char** attributes) {
    E57Scan& scan = scans_.back();
    if (scan.prototype.size() == kE57MaxFields)
      failInScan(
          fmt::format("its prototype has more than {} fields, the most supported", kE57MaxFields));
    if (++fieldsInAll_ > kE57MaxFieldsInAll)
      fail(fmt::format("the prototypes have more than {} fields in all, the most supported",
                       withSeparators(kE57MaxFieldsInAll)));
    E57Field field;
    field.name = shortName(name);
    const std::string_view type = valueOr(attribute(attributes, "type"), "");
    if (type == "Float") {
      const std::string_view precision = valueOr(attribute(attributes, "precision"), "double");
      if (precision != "single" && precision != "double")
        failInScan(
            fmt::format("its prototype field '{}' has precision '{:.40}' (known: single, "
                        "double)",
                        field.name, precision));
      field.encoding = precision == "single" ? E57Encoding::kSingle : E57Encoding::kDouble;
      field.lowest = optionalNumber(attributes, "minimum", name);
      field.highest = optionalNumber(attributes, "maximum", name);
    } else if (type == "Integer" || type == "ScaledInteger") {
      field.encoding = type == "Integer" ? E57Encoding::kInteger : E57Encoding::kScaledInteger;
      // E2807 Tables 17 and 19: absent bounds are those of a 64-bit integer.
      field.minimum = optionalInteger(attributes, "minimum", name)
                          .value_or(std::numeric_limits<int64_t>::min());
      field.maximum = optionalInteger(attributes, "maximum", name)
                          .value_or(std::numeric_limits<int64_t>::max());
      if (field.maximum < field.minimum)
        failInScan(fmt::format("its prototype field '{}' has maximum {} below its minimum {}",
                               field.name, field.maximum, field.minimum));
      if (field.encoding == E57Encoding::kScaledInteger) {
        field.scale = optionalNumber(attributes, "scale", name).value_or(1.0);
        field.offset = optionalNumber(attributes, "offset", name).value_or(0.0);
      }
      const double low = double(field.minimum) * field.scale + field.offset;
      const double high = double(field.maximum) * field.scale + field.offset;
      field.lowest = std::min(low, high);
      field.highest = std::max(low, high);
    } else {
      failInScan(
          fmt::format("its prototype field '{}' has type '{:.40}', which this reader "
                      "cannot decode (supported: Float, Integer, ScaledInteger)",
                      field.name, type));
    }
    scan.prototype.push_back(std::move(field));
  }

  void addText(std::string_view text) {
    if (stack_.empty()) return;
    switch (stack_.back().role) {
      case Role::kNumber:
        if (text_.size() + text.size() > kMaxNumberText)
          failInScan(
              fmt::format("the value of '{}' is too long to be a number", stack_.back().name));
        text_.append(text);
        break;
      case Role::kScanName:
      case Role::kScanGuid:
        text_.append(text.substr(0, std::min(text.size(), kMaxNameBytes + 4 - text_.size())));
        break;
      default:
        break;
    }
  }

  void end() {
    const Frame frame = std::move(stack_.back());
    stack_.pop_back();
    switch (frame.role) {
      case Role::kNumber:
        *frame.target = numberValue(frame);
        break;
      case Role::kScanName:
        scans_.back().name = shortName(text_);
        break;
      case Role::kScanGuid:
        scans_.back().guid = shortName(text_);
        break;
      case Role::kPoints:
        if (!parts_.hasPrototype) failInScan("its points element has no prototype");
        break;
      case Role::kScan:
        endScan();
        break;
      default:
        break;
    }
    text_.clear();
  }

  // The value of a number element (E2807 8.4.3–8.4.5): empty text is 0; a scaled integer's text is
  // the raw integer.
  double numberValue(const Frame& frame) const {
    const std::string_view text = trimmed(text_);
    const auto malformed = [&](const char* what) {
      failInScan(fmt::format("'{}' holds '{:.40}', not {}", frame.name, text, what));
    };
    if (frame.type == "Float") {
      double value = 0.0;
      if (!text.empty() && (!parseNumber(text, value) || !std::isfinite(value)))
        malformed("a finite number");
      return value;
    }
    if (frame.type != "Integer" && frame.type != "ScaledInteger")
      failInScan(fmt::format("'{}' has type '{:.40}', not Float, Integer or ScaledInteger",
                             frame.name, frame.type));
    int64_t value = 0;
    if (!text.empty() && !parseInteger(text, value)) malformed("a 64-bit integer");
    if (frame.type == "Integer") return double(value);
    return double(value) * frame.scale + frame.offset;
  }

  void endScan() {
    E57Scan& scan = scans_.back();
    if (!parts_.hasPoints) failInScan("it has no points element (CompressedVector)");
    if (parts_.hasRotation) {
      for (size_t i = 0; i < 4; ++i) {
        if (!parts_.rotation[i])
          failInScan(fmt::format("its pose's rotation has no {}", kQuaternionNames[i]));
        scan.rotation[i] = *parts_.rotation[i];
      }
    }
    if (parts_.hasTranslation) {
      for (size_t i = 0; i < 3; ++i) {
        if (!parts_.translation[i])
          failInScan(fmt::format("its pose's translation has no {}", kTranslationNames[i]));
        scan.translation[i] = *parts_.translation[i];
      }
    }
  }

  E57Pages& pages_;
  const E57Header& header_;
  XML_Parser parser_ = nullptr;
  uint64_t xmlStart_ = 0;
  std::exception_ptr error_;
  std::vector<Frame> stack_;
  std::string text_;  // the text of the innermost element, when its role keeps it
  size_t fieldsInAll_ = 0;
  ScanParts parts_;  // of the scan being parsed
  std::vector<E57Scan> scans_;
};

}  // namespace

uint32_t E57Field::bitWidth() const {
  switch (encoding) {
    case E57Encoding::kSingle:
      return 32;
    case E57Encoding::kDouble:
      return 64;
    case E57Encoding::kInteger:
    case E57Encoding::kScaledInteger:
      break;
  }
  return static_cast<uint32_t>(std::bit_width(uint64_t(maximum) - uint64_t(minimum)));
}

std::string e57ScanLabel(const E57Scan& scan, size_t index) {
  if (scan.name.empty()) return fmt::format("scan {}", index + 1);
  return fmt::format("scan {} '{}'", index + 1, scan.name);
}

std::vector<E57Scan> readE57Scans(E57Pages& pages, const E57Header& header) {
  return XmlParser(pages, header).parse();
}

}  // namespace iso::io
