// The rules of the chunk table (specs/iso-format.md, "Chunk table"): the one statement of them,
// which the reader checks when it opens a file and the writer before it writes an entry, so that
// the writer never makes a file the reader refuses.
#pragma once

#include <cstdint>
#include <optional>
#include <span>

#include "iso/format.h"
#include "layout.h"

namespace iso::detail {

// The first rule that entry `c`, the table's entry `index`, breaks on its own (its id, codec,
// level, key, sizes, payload offset, geometric error, and the entry rules of its kind): the
// offset of the field in the entry and the reason. `maxLevel` is the header's; `expectedOffset`
// is where the layout puts the payload, and the payload must end by `payloadsEnd` (the chunk
// table's offset).
std::optional<FieldProblem> chunkEntryProblem(const ChunkInfo& c, uint32_t index, uint8_t maxLevel,
                                              uint64_t expectedOffset, uint64_t payloadsEnd);

// A rule that a table breaks: the chunk whose entry breaks it and the field's offset in that
// entry, and the reason.
struct ChunkProblem {
  uint32_t chunk;
  FieldProblem field;
};

// The first parent link of a table (in chunk order) that is not to an existing, coarser cell
// containing the chunk's, or that gives a points chunk a parent of another kind.
std::optional<ChunkProblem> parentProblem(std::span<const ChunkInfo> chunks);

// The first point count of a surface chunk (in chunk order) that brings the counts of the surface
// chunks with the same surface parent over the parent's, or those of the other surface chunks
// over kMaxPointCount. The parent links must be valid (parentProblem empty).
std::optional<ChunkProblem> surfacePointCountProblem(std::span<const ChunkInfo> chunks);

}  // namespace iso::detail
