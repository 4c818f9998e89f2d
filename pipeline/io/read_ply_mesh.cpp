// The PLY mesh reader: every vertex, and faces fanned into triangles.
#include <fmt/format.h>

#include <algorithm>

#include "iso/error.h"
#include "pipeline/io/ply.h"
#include "pipeline/io/ply_format.h"
#include "pipeline/io/ply_vertices.h"
#include "pipeline/io/text_fields.h"

namespace iso {
namespace {

using io::InputStream;
using io::PlyElement;
using io::PlyEncoding;
using io::PlyHeader;

// Reservations follow the header's counts only up to this many entries, so that a hostile count
// cannot allocate more than the file's content justifies.
constexpr uint64_t kMaxReserve = uint64_t{1} << 22;

// Turns a polygon's vertex indices into a fan of triangles (v0 v1 v2, v0 v2 v3, ...).
class FanBuilder {
 public:
  FanBuilder(const InputStream& in, uint64_t vertexCount, std::vector<std::array<uint32_t, 3>>& out)
      : in_(in), vertexCount_(vertexCount), out_(out) {}

  void startFace() { corners_ = 0; }
  // The next corner; `where` is the byte offset (binary) or nullopt (ASCII: the current line).
  void add(int64_t index, std::optional<uint64_t> where) {
    if (index < 0 || static_cast<uint64_t>(index) >= vertexCount_) {
      const std::string reason =
          fmt::format("a face refers to vertex {}, but there are {} vertices", index, vertexCount_);
      if (where) in_.failAt(*where, reason);
      in_.failLine(reason);
    }
    const auto vertex = static_cast<uint32_t>(index);
    if (corners_ == 0) first_ = vertex;
    if (corners_ >= 2) out_.push_back({first_, previous_, vertex});
    previous_ = vertex;
    ++corners_;
  }

 private:
  const InputStream& in_;
  uint64_t vertexCount_;
  std::vector<std::array<uint32_t, 3>>& out_;
  uint64_t corners_ = 0;
  uint32_t first_ = 0;
  uint32_t previous_ = 0;
};

size_t findIndexList(const InputStream& in, const PlyElement& face) {
  const std::optional<size_t> property = face.find({"vertex_indices", "vertex_index"});
  if (!property || !face.properties[*property].isList())
    throw FileError(in.name(), std::nullopt,
                    "the face element has no list property vertex_indices or vertex_index");
  if (!io::isPlyInteger(face.properties[*property].type))
    throw FileError(in.name(), std::nullopt, "face vertex indices must have an integer type");
  return *property;
}

[[noreturn]] void failFacesEnd(const InputStream& in, const PlyElement& face, uint64_t done) {
  in.fail(fmt::format("file ends after {} of {} faces", done, face.count));
}

void readBinaryFaces(InputStream& in, PlyEncoding encoding, const PlyElement& face,
                     size_t indexList, FanBuilder& fan) {
  const io::PlyType indexType = face.properties[indexList].type;
  const size_t indexBytes = io::plyTypeSize(indexType);
  for (uint64_t record = 0; record < face.count; ++record) {
    for (size_t i = 0; i < face.properties.size(); ++i) {
      const io::PlyProperty& property = face.properties[i];
      const uint64_t items =
          property.isList() ? io::readPlyListCount(in, encoding, *property.countType) : 1;
      if (i != indexList) {
        const uint64_t bytes = items * io::plyTypeSize(property.type);
        if (in.skip(bytes) != bytes) failFacesEnd(in, face, record);
        continue;
      }
      fan.startFace();
      for (uint64_t item = 0; item < items; ++item) {
        const std::span<const std::byte> bytes = in.peek(indexBytes);
        if (bytes.size() < indexBytes) failFacesEnd(in, face, record);
        fan.add(io::loadPlyInteger(encoding, indexType, bytes.data()), in.offset());
        in.consume(indexBytes);
      }
    }
  }
}

void readAsciiFaces(InputStream& in, const PlyElement& face, size_t indexList, FanBuilder& fan) {
  std::string_view line;
  std::string_view field;
  for (uint64_t record = 0; record < face.count;) {
    if (!in.readLine(line)) failFacesEnd(in, face, record);
    std::string_view rest = line;
    if (!io::nextField<io::isBlank>(rest, field)) continue;  // a blank line
    rest = line;
    for (size_t i = 0; i < face.properties.size(); ++i) {
      int64_t items = 1;
      const bool isList = face.properties[i].isList();
      if (isList && (!io::nextField<io::isBlank>(rest, field) || !io::parseInteger(field, items) ||
                     items < 0))
        in.failLine(
            fmt::format("invalid list length for face property '{}'", face.properties[i].name));
      if (i == indexList) fan.startFace();
      for (int64_t item = 0; item < items; ++item) {
        if (!io::nextField<io::isBlank>(rest, field))
          in.failLine(
              fmt::format("too few values for face property '{}'", face.properties[i].name));
        int64_t index = 0;
        if (i != indexList) continue;
        if (!io::parseInteger(field, index))
          in.failLine(fmt::format("face vertex index is not an integer: '{}'", field));
        fan.add(index, std::nullopt);
      }
    }
    if (io::nextField<io::isBlank>(rest, field))
      in.failLine(fmt::format("more values than the {} face properties", face.properties.size()));
    ++record;
  }
}

std::vector<glm::dvec3> readVertices(InputStream& in, PlyEncoding encoding,
                                     const PlyElement& vertex) {
  io::PlyVertexDecoder decoder(in, encoding, vertex, true);
  PointCloud cloud;
  cloud.positions.reserve(std::min(vertex.count, kMaxReserve));
  while (decoder.decode(in, cloud, size_t{1} << 20) > 0) {
  }
  return std::move(cloud.positions);
}

}  // namespace

TriangleMesh readPlyMesh(const std::filesystem::path& path) {
  InputStream in(path);
  const PlyHeader header = io::readPlyHeader(in);
  const std::optional<size_t> vertexElement = header.find("vertex");
  const std::optional<size_t> faceElement = header.find("face");
  if (!vertexElement)
    throw FileError(in.name(), std::nullopt, "the PLY file has no vertex element");
  if (!faceElement) throw FileError(in.name(), std::nullopt, "the PLY file has no faces");
  const PlyElement& face = header.elements[*faceElement];
  const size_t indexList = findIndexList(in, face);

  TriangleMesh mesh;
  mesh.triangles.reserve(std::min(face.count, kMaxReserve));
  FanBuilder fan(in, header.elements[*vertexElement].count, mesh.triangles);
  const size_t last = std::max(*vertexElement, *faceElement);
  for (size_t i = 0; i <= last; ++i) {
    const PlyElement& element = header.elements[i];
    if (i == *vertexElement) {
      mesh.vertices = readVertices(in, header.encoding, element);
    } else if (i != *faceElement) {
      io::skipPlyElement(in, header.encoding, element);
    } else if (header.encoding == PlyEncoding::Ascii) {
      readAsciiFaces(in, element, indexList, fan);
    } else {
      readBinaryFaces(in, header.encoding, element, indexList, fan);
    }
  }
  return mesh;
}

}  // namespace iso
