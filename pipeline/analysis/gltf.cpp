// glTF 2.0 binary files of triangle meshes (pipeline/analysis/gltf.h). The JSON is written here:
// Debian 12's tinygltf (2.7) cannot express EXT_meshopt_compression's fallback buffer (a
// byteLength without data), and cgltf is not packaged. meshoptimizer encodes the streams.
#include "pipeline/analysis/gltf.h"

#include <meshoptimizer.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstring>
#include <glm/common.hpp>
#include <limits>
#include <nlohmann/json.hpp>
#include <string>

#include "iso/error.h"

namespace iso {
namespace {

// glTF's numbers for component types and buffer targets.
constexpr int kByte = 5120, kUnsignedByte = 5121, kUnsignedShort = 5123, kUnsignedInt = 5125,
              kFloat = 5126;
constexpr int kArrayBuffer = 34962, kElementArrayBuffer = 34963;

size_t padded(size_t n) { return (n + 3) & ~size_t{3}; }

// One stream of the file: its uncompressed bytes and how glTF describes them; with a filter,
// the bytes the filter decodes to `data` (EXT_meshopt_compression's filters).
struct Stream {
  Stream(size_t stride_, size_t count_, bool indices_ = false)
      : data(stride_ * count_), stride(stride_), count(count_), indices(indices_) {}
  std::vector<uint8_t> data, filtered;
  std::string filter;
  size_t stride, count;
  bool indices;
  size_t firstTriangle = 0;  // of an index stream
};

template <class T>
void put(std::vector<uint8_t>& out, size_t at, T value) {
  std::memcpy(out.data() + at, &value, sizeof(T));
}

// The mesh's positions as `T`s (value(x, axis) each coordinate), 4-byte aligned vertices, and
// their smallest and largest on each axis (glTF's accessor min and max; 0 for no vertices).
template <class T, class Value>
void storePositions(const TriangleMesh& mesh, Stream& out, nlohmann::json& min, nlohmann::json& max,
                    const Value& value) {
  std::array<T, 3> low, high;
  low.fill(std::numeric_limits<T>::max());
  high.fill(std::numeric_limits<T>::lowest());
  for (size_t v = 0; v < mesh.vertices.size(); ++v)
    for (int a = 0; a < 3; ++a) {
      const T x = value(mesh.vertices[v][a], a);
      put(out.data, v * out.stride + size_t(a) * sizeof(T), x);
      low[size_t(a)] = std::min(low[size_t(a)], x);
      high[size_t(a)] = std::max(high[size_t(a)], x);
    }
  for (size_t a = 0; a < 3; ++a) {
    min.push_back(mesh.vertices.empty() ? T(0) : low[a]);
    max.push_back(mesh.vertices.empty() ? T(0) : high[a]);
  }
}

uint8_t unorm8(float v) { return uint8_t(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f)); }

}  // namespace

std::vector<uint8_t> encodeGlb(const TriangleMesh& source, const MeshAttributes& sourceAttributes,
                               const GlbOptions& options, GlbStats* stats) {
  if (options.yUp) {  // the same mesh in glTF's axes, about the origin; then as any other
    const auto turn = [](const glm::dvec3& v) { return glm::dvec3(v.x, v.z, -v.y); };
    TriangleMesh turned{std::vector<glm::dvec3>(source.vertices.size()), source.triangles};
    for (size_t v = 0; v < turned.vertices.size(); ++v)
      turned.vertices[v] = turn(source.vertices[v] - options.origin);
    MeshAttributes attributes = sourceAttributes;
    for (glm::vec3& n : attributes.normals) n = glm::vec3(n.x, n.z, -n.y);
    GlbOptions rest = options;
    rest.yUp = false;
    rest.origin = glm::dvec3(0.0);
    return encodeGlb(turned, attributes, rest, stats);
  }
  const TriangleMesh& mesh = source;
  const MeshAttributes& attributes = sourceAttributes;
  const size_t n = mesh.vertices.size();
  GlbStats s;
  s.vertices = n;
  s.triangles = mesh.triangles.size();
  // Positions relative to the origin, their box, and the 16-bit step over its largest extent.
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-lo);
  for (const glm::dvec3& v : mesh.vertices) {
    lo = glm::min(lo, v - options.origin);
    hi = glm::max(hi, v - options.origin);
  }
  if (n == 0) lo = hi = glm::dvec3(0.0);
  const double extent = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z});
  const double finest = extent > 0.0 ? extent / 65535.0 : 1.0;
  double step = finest;
  if (options.positionStep > finest) {
    // A grid of multiples of the step from the origin: meshes quantized with one step (tiles of
    // one cut) put a vertex they share at one point.
    const glm::dvec3 low = glm::floor(lo / options.positionStep) * options.positionStep;
    if (std::max({hi.x - low.x, hi.y - low.y, hi.z - low.z}) / options.positionStep <= 65535.0) {
      step = options.positionStep;
      lo = low;
    }
  }
  s.quantized = options.maxPositionStep <= 0.0 || finest <= options.maxPositionStep;
  s.positionStep = s.quantized ? step : 0.0;

  nlohmann::json accessors = nlohmann::json::array(), attributesJson = nlohmann::json::object();
  std::vector<Stream> streams;
  Stream position(s.quantized ? 8 : 12, n);
  nlohmann::json qmin = nlohmann::json::array(), qmax = nlohmann::json::array();
  if (s.quantized)
    storePositions<uint16_t>(mesh, position, qmin, qmax, [&](double x, int a) {
      return uint16_t(std::clamp(std::round((x - options.origin[a] - lo[a]) / step), 0.0, 65535.0));
    });
  else
    storePositions<float>(mesh, position, qmin, qmax,
                          [&](double x, int a) { return float(x - options.origin[a] - lo[a]); });
  accessors.push_back({{"bufferView", streams.size()},
                       {"componentType", s.quantized ? kUnsignedShort : kFloat},
                       {"count", n},
                       {"type", "VEC3"},
                       {"min", qmin},
                       {"max", qmax}});
  attributesJson["POSITION"] = accessors.size() - 1;
  streams.push_back(std::move(position));
  if (!attributes.normals.empty()) {
    // Octahedral: two 8-bit numbers a normal, which the file's bytes are the decoding of (with
    // compression, the decoder's filter makes them from the two).
    Stream normal(4, n);
    std::vector<float> unit(4 * n, 0.0f);
    for (size_t v = 0; v < n; ++v) {
      glm::vec3 d = attributes.normals[v];
      const float length = std::sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
      d = length > 0.0f ? d / length : glm::vec3(0.0f, 0.0f, 1.0f);
      for (int a = 0; a < 3; ++a) unit[4 * v + size_t(a)] = d[a];
    }
    normal.filtered.resize(4 * n);
    meshopt_encodeFilterOct(normal.filtered.data(), n, 4, 8, unit.data());
    normal.data = normal.filtered;
    meshopt_decodeFilterOct(normal.data.data(), n, 4);
    normal.filter = "OCTAHEDRAL";
    accessors.push_back({{"bufferView", streams.size()},
                         {"componentType", kByte},
                         {"normalized", true},
                         {"count", n},
                         {"type", "VEC3"}});
    attributesJson["NORMAL"] = accessors.size() - 1;
    streams.push_back(std::move(normal));
  }
  if (!attributes.colors.empty()) {
    Stream color(4, n);
    for (size_t v = 0; v < n; ++v)
      for (int a = 0; a < 3; ++a)
        put(color.data, v * 4 + size_t(a), unorm8(attributes.colors[v][a]));
    accessors.push_back({{"bufferView", streams.size()},
                         {"componentType", kUnsignedByte},
                         {"normalized", true},
                         {"count", n},
                         {"type", "VEC3"}});
    attributesJson["COLOR_0"] = accessors.size() - 1;
    streams.push_back(std::move(color));
  }
  // The triangles, and the skirts' after them, each their own index stream and primitive.
  const bool wide = n > 65535;
  const size_t skirts = std::min(options.skirtsFrom, mesh.triangles.size());
  nlohmann::json primitives = nlohmann::json::array();
  std::vector<std::pair<size_t, size_t>> parts = {{0, skirts}};
  if (skirts < mesh.triangles.size()) parts.push_back({skirts, mesh.triangles.size()});
  for (const auto& [first, last] : parts) {
    Stream index(wide ? 4 : 2, 3 * (last - first), true);
    index.firstTriangle = first;
    for (size_t t = first; t < last; ++t)
      for (size_t c = 0; c < 3; ++c) {
        const uint32_t i = mesh.triangles[t][c];
        if (wide)
          put(index.data, (3 * (t - first) + c) * 4, i);
        else
          put(index.data, (3 * (t - first) + c) * 2, uint16_t(i));
      }
    accessors.push_back({{"bufferView", streams.size()},
                         {"componentType", wide ? kUnsignedInt : kUnsignedShort},
                         {"count", index.count},
                         {"type", "SCALAR"}});
    primitives.push_back(
        {{"attributes", attributesJson}, {"indices", accessors.size() - 1}, {"mode", 4}});
    streams.push_back(std::move(index));
  }

  // The binary chunk: each stream compressed (or as it is), 4-byte aligned; with compression,
  // the views' uncompressed layout lies in a second, fallback buffer that holds no bytes.
  std::vector<uint8_t> bin;
  nlohmann::json views = nlohmann::json::array();
  size_t fallback = 0;
  for (const Stream& stream : streams) {
    nlohmann::json view = {{"buffer", options.compress ? 1 : 0},
                           {"byteLength", stream.data.size()},
                           {"target", stream.indices ? kElementArrayBuffer : kArrayBuffer}};
    if (!stream.indices) view["byteStride"] = stream.stride;
    if (options.compress) {
      view["byteOffset"] = fallback;
      fallback += padded(stream.data.size());
      std::vector<uint8_t> encoded;
      if (stream.indices) {
        std::vector<uint32_t> flat(stream.count);
        for (size_t i = 0; i < stream.count; ++i)
          flat[i] = mesh.triangles[stream.firstTriangle + i / 3][i % 3];
        encoded.resize(meshopt_encodeIndexBufferBound(stream.count, n));
        encoded.resize(
            meshopt_encodeIndexBuffer(encoded.data(), encoded.size(), flat.data(), flat.size()));
      } else {
        const std::vector<uint8_t>& bytes = stream.filter.empty() ? stream.data : stream.filtered;
        encoded.resize(meshopt_encodeVertexBufferBound(stream.count, stream.stride));
        encoded.resize(meshopt_encodeVertexBuffer(encoded.data(), encoded.size(), bytes.data(),
                                                  stream.count, stream.stride));
      }
      view["extensions"]["EXT_meshopt_compression"] = {
          {"buffer", 0},
          {"byteOffset", bin.size()},
          {"byteLength", encoded.size()},
          {"byteStride", stream.stride},
          {"count", stream.count},
          {"mode", stream.indices ? "TRIANGLES" : "ATTRIBUTES"}};
      if (!stream.filter.empty())
        view["extensions"]["EXT_meshopt_compression"]["filter"] = stream.filter;
      bin.insert(bin.end(), encoded.begin(), encoded.end());
    } else {
      view["byteOffset"] = bin.size();
      bin.insert(bin.end(), stream.data.begin(), stream.data.end());
    }
    bin.resize(padded(bin.size()), 0);
    views.push_back(std::move(view));
  }

  nlohmann::json node = {{"mesh", 0}};
  glm::dvec3 translation = lo;
  if (options.translate) translation += options.origin;
  node["translation"] = {translation.x, translation.y, translation.z};
  if (s.quantized) node["scale"] = {step, step, step};
  nlohmann::json buffers = nlohmann::json::array({{{"byteLength", bin.size()}}});
  std::vector<std::string> extensions = {"KHR_mesh_quantization"};
  if (options.compress) {
    buffers.push_back({{"byteLength", fallback},
                       {"extensions", {{"EXT_meshopt_compression", {{"fallback", true}}}}}});
    extensions.push_back("EXT_meshopt_compression");
  }
  std::vector<std::string> used = extensions;
  if (options.unlit) used.push_back("KHR_materials_unlit");  // used, not required
  nlohmann::json gltf = {{"asset", {{"version", "2.0"}, {"generator", "iso export"}}},
                         {"extensionsUsed", used},
                         {"extensionsRequired", extensions},
                         {"scene", 0},
                         {"scenes", {{{"nodes", {0}}}}},
                         {"nodes", {node}},
                         {"meshes", {{{"primitives", primitives}}}},
                         {"accessors", accessors},
                         {"bufferViews", views},
                         {"buffers", buffers}};
  // Double-sided: a scan's surface is open where the scan ends, and its inside shows there (as
  // iso view draws it); a viewer would cull those faces and leave holes. Otherwise the default
  // material, or for baked colors an unlit one (glTF 2.0 §3.9.2, KHR_materials_unlit).
  nlohmann::json material = {{"doubleSided", true}};
  if (options.unlit) {
    material["pbrMetallicRoughness"] = {{"baseColorFactor", {1.0, 1.0, 1.0, 1.0}},
                                        {"metallicFactor", 0.0},
                                        {"roughnessFactor", 1.0}};
    material["extensions"] = {{"KHR_materials_unlit", nlohmann::json::object()}};
  }
  gltf["materials"] = nlohmann::json::array({material});
  for (nlohmann::json& p : gltf["meshes"][0]["primitives"]) p["material"] = 0;
  std::string json = gltf.dump();
  json.resize(padded(json.size()), ' ');

  // The container: a 12-byte header, then the JSON and binary chunks (glTF 2.0 §4.4).
  std::vector<uint8_t> out(12 + 8 + json.size() + 8 + bin.size());
  put(out, 0, uint32_t(0x46546C67));  // "glTF"
  put(out, 4, uint32_t(2));
  put(out, 8, uint32_t(out.size()));
  put(out, 12, uint32_t(json.size()));
  put(out, 16, uint32_t(0x4E4F534A));  // "JSON"
  std::memcpy(out.data() + 20, json.data(), json.size());
  const size_t at = 20 + json.size();
  put(out, at, uint32_t(bin.size()));
  put(out, at + 4, uint32_t(0x004E4942));  // "BIN"
  std::memcpy(out.data() + at + 8, bin.data(), bin.size());
  s.bytes = out.size();
  if (stats) *stats = s;
  return out;
}

TriangleMesh decodeGlb(const std::vector<uint8_t>& bytes, const std::string& name,
                       bool surfaceOnly) {
  const auto fail = [&](const std::string& why) {
    return FileError(name, std::nullopt, "is not a glTF binary of one mesh: " + why);
  };
  const auto word = [&](size_t at) {
    if (at + 4 > bytes.size()) throw fail("truncated");
    uint32_t v = 0;
    std::memcpy(&v, bytes.data() + at, 4);
    return v;
  };
  if (word(0) != 0x46546C67 || word(4) != 2) throw fail("no glTF 2 header");
  const size_t jsonLength = word(12);
  if (word(16) != 0x4E4F534A || 20 + jsonLength + 8 > bytes.size()) throw fail("no JSON chunk");
  const size_t binAt = 20 + jsonLength + 8, binLength = word(20 + jsonLength);
  if (binAt + binLength > bytes.size()) throw fail("truncated binary chunk");
  try {
    const nlohmann::json gltf =
        nlohmann::json::parse(bytes.begin() + 20, bytes.begin() + 20 + long(jsonLength));
    // A buffer view's bytes, decoded by meshoptimizer when compressed.
    const auto view = [&](size_t v) {
      const nlohmann::json& b = gltf.at("bufferViews").at(v);
      std::vector<uint8_t> out(b.at("byteLength").get<size_t>());
      const nlohmann::json* c = nullptr;
      if (b.contains("extensions")) c = &b["extensions"].at("EXT_meshopt_compression");
      const size_t offset = (c ? *c : b).value("byteOffset", size_t{0});
      const size_t length = c ? c->at("byteLength").get<size_t>() : out.size();
      if (offset + length > binLength) throw fail("a buffer view past the binary chunk");
      const uint8_t* source = bytes.data() + binAt + offset;
      if (!c) {
        std::memcpy(out.data(), source, out.size());
        return out;
      }
      const size_t count = c->at("count"), stride = c->at("byteStride");
      if (count * stride > out.size()) throw fail("a compressed view larger than its fallback");
      const int result =
          c->at("mode") == "TRIANGLES"
              ? meshopt_decodeIndexBuffer(out.data(), count, stride, source, length)
              : meshopt_decodeVertexBuffer(out.data(), count, stride, source, length);
      if (result != 0) throw fail("a compressed view meshoptimizer cannot decode");
      return out;
    };
    const nlohmann::json& primitives = gltf.at("meshes").at(0).at("primitives");
    const nlohmann::json& primitive = primitives.at(0);
    const nlohmann::json& node = gltf.at("nodes").at(0);
    const nlohmann::json& positions =
        gltf.at("accessors").at(primitive.at("attributes").at("POSITION").get<size_t>());
    glm::dvec3 translation(0.0), scale(1.0);
    for (int a = 0; a < 3; ++a) {
      if (node.contains("translation")) translation[a] = node["translation"].at(size_t(a));
      if (node.contains("scale")) scale[a] = node["scale"].at(size_t(a));
    }
    TriangleMesh mesh;
    const size_t n = positions.at("count");
    const std::vector<uint8_t> p = view(positions.at("bufferView"));
    const bool shorts = positions.at("componentType") == kUnsignedShort;
    const size_t stride = shorts ? 8 : 12;
    if (p.size() < n * stride) throw fail("positions past their view");
    mesh.vertices.resize(n);
    for (size_t v = 0; v < n; ++v)
      for (size_t a = 0; a < 3; ++a) {
        double value = 0.0;
        if (shorts) {
          uint16_t q = 0;
          std::memcpy(&q, p.data() + v * stride + 2 * a, 2);
          value = q;
        } else {
          float f = 0.0f;
          std::memcpy(&f, p.data() + v * stride + 4 * a, 4);
          value = f;
        }
        mesh.vertices[v][int(a)] = translation[int(a)] + scale[int(a)] * value;
      }
    for (size_t k = 0; k < (surfaceOnly ? 1 : primitives.size()); ++k) {
      if (primitives.at(k).at("attributes").at("POSITION") != primitive["attributes"]["POSITION"])
        throw fail("primitives with their own positions");
      const nlohmann::json& indices =
          gltf.at("accessors").at(primitives[k].at("indices").get<size_t>());
      const size_t count = indices.at("count");
      const std::vector<uint8_t> i = view(indices.at("bufferView"));
      const size_t width = indices.at("componentType") == kUnsignedInt ? 4 : 2;
      if (i.size() < count * width || count % 3 != 0) throw fail("indices past their view");
      const size_t base = mesh.triangles.size();
      mesh.triangles.resize(base + count / 3);
      for (size_t j = 0; j < count; ++j) {
        uint32_t index = 0;
        std::memcpy(&index, i.data() + j * width, width);
        if (index >= n) throw fail("an index past the vertices");
        mesh.triangles[base + j / 3][j % 3] = index;
      }
    }
    return mesh;
  } catch (const nlohmann::json::exception& e) {
    throw fail(e.what());
  }
}

}  // namespace iso
