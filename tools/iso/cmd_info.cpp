// `iso info FILE`: what a file holds, for people or (--json) for programs.
#include <fmt/core.h>

#include <cstdint>
#include <map>
#include <nlohmann/json.hpp>

#include "iso/lighting.h"
#include "iso/points.h"
#include "iso/reader.h"
#include "tools/iso/commands.h"
#include "tools/iso/text.h"

namespace iso::cli {
namespace {

// What info reads: the header, the chunk table and the metadata, which opening checks
// (specs/iso-format.md, "What readers check"); every figure it prints about the chunks is the
// table's. Reading every payload would make it as slow as `iso verify` on a large file, so it says
// that it did not.
constexpr const char* kPayloadsNotChecked =
    "not checked (the figures above are the chunk table's): iso verify checks them";

struct LevelSummary {
  uint64_t chunks = 0, storedBytes = 0, rawBytes = 0, points = 0;
};

struct Summary {
  uint64_t storedBytes = 0, rawBytes = 0;
  uint64_t points = 0;  // input points represented, counted over the chunks without a parent
  std::map<std::string, uint64_t> codecs;
  std::map<int, LevelSummary> levels;  // of the surface (and other non-points) chunks
  LevelSummary kept;                   // the points chunks: the original points
  LevelSummary subsamples;             // the points chunks that are subsamples of others
  LevelSummary values;                 // values chunks (their points: the values)
  LevelSummary volume;                 // volume points chunks
  LevelSummary lighting;               // lighting chunks (their points: none)
};

// Point counts summed, stopping at 2^64 - 1: a file's surface and points chunks keep these sums
// far below it (specs/iso-format.md, "Chunk table"), but chunks of other kinds have no rule.
void addPoints(uint64_t& sum, uint64_t count) {
  sum = count > UINT64_MAX - sum ? UINT64_MAX : sum + count;
}

Summary summarize(const Reader& reader) {
  Summary s;
  const std::vector<bool> subsample = subsampleChunks(reader);
  for (const ChunkInfo& c : reader.chunks()) {
    s.storedBytes += c.storedSize;
    s.rawBytes += c.rawSize;
    ++s.codecs[std::string(codecName(c.codec))];
    const bool points = c.kind == kPointsKind;
    const bool values = c.kind == kValuesKind, volume = c.kind == kVolumePointsKind;
    const bool lighting = c.kind == kLightingKind;
    if (c.parent == kNoParent && !points && !values && !volume)
      addPoints(s.points, c.pointCount);  // roots: all once
    LevelSummary& level = points     ? (subsample[c.id] ? s.subsamples : s.kept)
                          : values   ? s.values
                          : volume   ? s.volume
                          : lighting ? s.lighting
                                     : s.levels[c.level];
    ++level.chunks;
    level.storedBytes += c.storedSize;
    level.rawBytes += c.rawSize;
    addPoints(level.points, c.pointCount);
  }
  return s;
}

// The coordinate system the metadata records ("crs", an object), or null.
nlohmann::json coordinateSystemIn(const nlohmann::json& metadata) {
  if (!metadata.is_object() || !metadata.contains("crs") || !metadata["crs"].is_object())
    return nullptr;
  return metadata["crs"];
}

nlohmann::json attributeJson(const AttributeDesc& a) {
  return {{"semantic", semanticName(a.semantic)},
          {"encoding", encodingName(a.encoding)},
          {"components", a.components},
          {"scale", a.scale}};
}

nlohmann::json chunkJson(const ChunkInfo& c) {
  return {{"id", c.id},
          {"parent", c.parent == kNoParent ? nlohmann::json(nullptr) : nlohmann::json(c.parent)},
          {"level", c.level},
          {"key", c.key},
          {"kind", chunkKindName(c.kind)},
          {"kind_id", c.kind},
          {"codec", codecName(c.codec)},
          {"offset", c.offset},
          {"stored_bytes", c.storedSize},
          {"raw_bytes", c.rawSize},
          {"checksum", fmt::format("{:016x}", c.checksum)},
          {"points", c.pointCount},
          {"nodes", c.nodeCount},
          {"leaves", c.leafCount},
          {"geometric_error", c.geometricError}};
}

nlohmann::json infoJson(const Reader& reader, bool withChunks) {
  const FileHeader& h = reader.header();
  const Summary s = summarize(reader);
  nlohmann::json j;
  j["file"] = reader.name();
  j["file_size"] = reader.fileSize();
  j["format_version"] = fmt::format("{}.{}", h.versionMajor, h.versionMinor);
  j["flags"] = h.flags;
  j["frame"] = {{"origin", h.frame.origin}, {"size", h.frame.size}};
  j["max_level"] = h.maxLevel;
  j["payload_alignment"] = h.payloadAlignment();
  j["attributes"] = nlohmann::json::array();
  for (const AttributeDesc& a : h.attributes) j["attributes"].push_back(attributeJson(a));
  j["chunk_count"] = reader.chunks().size();
  j["stored_bytes"] = s.storedBytes;
  j["raw_bytes"] = s.rawBytes;
  j["point_count"] = s.points;
  j["codecs"] = s.codecs;
  j["kept_points"] = {
      {"chunks", s.kept.chunks},
      {"points", s.kept.points},
      {"stored_bytes", s.kept.storedBytes},
      {"subsample_chunks", s.subsamples.chunks},
      {"subsample_points", s.subsamples.points},
      {"subsample_stored_bytes", s.subsamples.storedBytes}};
  j["values"] = {{"chunks", s.values.chunks},
                 {"values", s.values.points},
                 {"stored_bytes", s.values.storedBytes}};
  j["volume_points"] = {{"chunks", s.volume.chunks},
                        {"points", s.volume.points},
                        {"stored_bytes", s.volume.storedBytes}};
  j["lighting"] = {{"chunks", s.lighting.chunks}, {"stored_bytes", s.lighting.storedBytes}};
  j["levels"] = nlohmann::json::array();
  for (const auto& [level, l] : s.levels)
    j["levels"].push_back({{"level", level},
                           {"chunks", l.chunks},
                           {"stored_bytes", l.storedBytes},
                           {"raw_bytes", l.rawBytes},
                           {"points", l.points}});
  const nlohmann::json metadata = nlohmann::json::parse(reader.metadata(), nullptr, false);
  if (metadata.is_discarded()) {
    j["metadata"] = std::string(reader.metadata());
    j["metadata_error"] = "not valid JSON";
  } else {
    j["metadata"] = metadata;
  }
  j["crs"] = coordinateSystemIn(metadata);
  j["payloads_checked"] = false;  // the figures are the chunk table's (kPayloadsNotChecked)
  if (withChunks) {
    j["chunks"] = nlohmann::json::array();
    for (const ChunkInfo& c : reader.chunks()) j["chunks"].push_back(chunkJson(c));
  }
  return j;
}

void printChunkTable(const Reader& reader) {
  fmt::print("\n{:>6} {:>6} {:>5} {:>18} {:>6} {:>5} {:>12} {:>12} {:>10} {:>8} {:>8} {:>10}\n",
             "chunk", "parent", "level", "key", "kind", "codec", "stored", "raw", "points", "nodes",
             "leaves", "error");
  for (const ChunkInfo& c : reader.chunks())
    fmt::print(
        "{:>6} {:>6} {:>5} {:>#18x} {:>6} {:>5} {:>12} {:>12} {:>10} {:>8} {:>8} {:>10.4g}\n", c.id,
        c.parent == kNoParent ? std::string("-") : std::to_string(c.parent), c.level, c.key,
        chunkKindName(c.kind), codecName(c.codec), c.storedSize, c.rawSize, c.pointCount,
        c.nodeCount, c.leafCount, c.geometricError);
}

void printInfo(const Reader& reader, bool withChunks) {
  const FileHeader& h = reader.header();
  const Summary s = summarize(reader);
  fmt::print("{:<12}{}\n", "file", reader.name());
  fmt::print("{:<12}{} bytes ({})\n", "size", withSeparators(reader.fileSize()),
             byteSize(reader.fileSize()));
  fmt::print("{:<12}{}.{}\n", "format", h.versionMajor, h.versionMinor);
  fmt::print("{:<12}origin ({}, {}, {}), size {}\n", "frame", h.frame.origin[0], h.frame.origin[1],
             h.frame.origin[2], h.frame.size);
  std::string attributes;
  for (const AttributeDesc& a : h.attributes) {
    if (!attributes.empty()) attributes += ", ";
    attributes += fmt::format("{} {}", semanticName(a.semantic), encodingName(a.encoding));
    if (a.semantic == Semantic::SignedDistance)
      attributes += fmt::format(" (range {:g} diagonals)", a.scale);
  }
  fmt::print("{:<12}{}\n", "attributes", attributes);
  fmt::print("{:<12}max level {}, payloads aligned to {} bytes\n", "octree", h.maxLevel,
             h.payloadAlignment());
  std::string codecs;
  for (const auto& [codec, count] : s.codecs) codecs += fmt::format(", {} {}", count, codec);
  fmt::print("{:<12}{}{}; {} stored for {} of data", "chunks",
             withSeparators(reader.chunks().size()), codecs, byteSize(s.storedBytes),
             byteSize(s.rawBytes));
  if (s.rawBytes > 0) fmt::print(" ({:.1f}%)", 100.0 * double(s.storedBytes) / double(s.rawBytes));
  fmt::print("\n");
  for (const auto& [level, l] : s.levels)
    fmt::print("  level {:<4}{} chunk{}, {} stored, {} points\n", level, withSeparators(l.chunks),
               l.chunks == 1 ? "" : "s", byteSize(l.storedBytes), withSeparators(l.points));
  fmt::print("{:<12}{}\n", "points", withSeparators(s.points));
  // A line for each kind of points chunk the file has.
  const auto line = [](const char* label, const LevelSummary& l, const char* what) {
    if (l.chunks == 0) return;
    fmt::print("{:<12}{} {} in {} chunk{}, {} stored\n", label, withSeparators(l.points), what,
               withSeparators(l.chunks), l.chunks == 1 ? "" : "s", byteSize(l.storedBytes));
  };
  line("kept", s.kept, "original points");
  line("", s.subsamples, "of them again as subsamples");
  line("volume", s.volume, "volume points");
  line("values", s.values, "point values");
  if (s.lighting.chunks > 0)
    fmt::print("{:<12}baked irradiance in {} chunk{}, {} stored (iso bake)\n", "lighting",
               withSeparators(s.lighting.chunks), s.lighting.chunks == 1 ? "" : "s",
               byteSize(s.lighting.storedBytes));
  fmt::print("{:<12}{}\n", "payloads", kPayloadsNotChecked);
  const nlohmann::json metadata = nlohmann::json::parse(reader.metadata(), nullptr, false);
  if (const nlohmann::json crs = coordinateSystemIn(metadata); !crs.is_null())
    fmt::print("{:<12}{}\n", "crs", describeCoordinateSystem(crs));
  if (metadata.is_discarded())
    fmt::print("{:<12}(not valid JSON, {} bytes)\n", "metadata", reader.metadata().size());
  else
    fmt::print(
        "{:<12}{}\n", "metadata",
        indentLines(metadata.dump(2, ' ', false, nlohmann::json::error_handler_t::replace), 12));
  if (withChunks) printChunkTable(reader);
}

}  // namespace

void addInfoCommand(CLI::App& app, int& exitCode) {
  struct Options {
    std::string file;
    bool json = false;
    bool chunks = false;
  };
  auto options = std::make_shared<Options>();
  CLI::App* command =
      app.add_subcommand("info", "Describe an .iso file: frame, attributes, chunks, metadata");
  command->add_option("file", options->file, ".iso file")->required();
  command->add_flag("--json", options->json, "Print JSON for programs");
  command->add_flag("--chunks", options->chunks, "Also list every chunk");
  command->callback([options, &exitCode] {
    exitCode = runGuarded("info", [&] {
      const Reader reader = Reader::open(options->file);
      if (options->json)
        fmt::print("{}\n", infoJson(reader, options->chunks)
                               .dump(2, ' ', false, nlohmann::json::error_handler_t::replace));
      else
        printInfo(reader, options->chunks);
      return kExitOk;
    });
  });
}

}  // namespace iso::cli
