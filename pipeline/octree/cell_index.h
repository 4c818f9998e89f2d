// Grid keys numbered in insertion order, as KeyIndex (iso/flat_map.h) numbers them, with a table
// that can be cut by space (specs/pipeline.md §15, "Chunk runs of the octree stages"). A key is a
// grid point's (gridKey, lodKey: x | y << 32 in `a`, z in the low 32 bits of `b`). Uncut, it is
// one table, like KeyIndex. Cut into parts, Morton ranges of cells of one level, each part opened
// in turn gets its own stretch of the table for the keys of its cells added while it is open, so
// that stages visiting keys in Morton order (the chunk merge, the writer) touch a few pages of the
// table rather than one at random per key; keys added otherwise (another part's, after closeParts)
// go to a shared table. The numbers do not depend on the cut.
//
// Threading: like std containers (concurrent const use only).
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

#include "iso/flat_map.h"
#include "pipeline/base/buffers.h"

namespace iso {

// Parts of space: the Morton ranges [firstCell[p], firstCell[p + 1]) of cells of `level` (the last
// to the end). Empty: no cut.
struct CellCut {
  uint8_t level = 0;
  std::vector<uint64_t> firstCell;
  // The part of the node (level, key) at or below the cut's level; kNoPart above it.
  static constexpr size_t kNoPart = ~size_t{0};
  size_t partOfNode(uint8_t nodeLevel, uint64_t nodeKey) const;
};

class CellKeyIndex {
 public:
  static constexpr uint32_t kNone = 0xffffffffu;

  // Room for `expected` keys in the shared table; the key array reserved for as many.
  explicit CellKeyIndex(size_t expected = 16);
  // Reserve the key array only (address space: pages count once written).
  void reserveKeys(size_t expected) { keys_.reserve(expected); }

  // Cut the table: keys in the cells of part p belong to part p. `expectedKeys`: room reserved
  // for the parts' stretches.
  void cutByCells(const CellCut& cut, size_t expectedKeys);
  // Give part p a stretch for about `expected` keys; until the next openPart or closeParts, the
  // new keys of part p go there.
  void openPart(size_t part, size_t expected);
  void closeParts() { open_ = kNoPart; }

  // The number of key, which is added (as the next number) when new; second: whether it was.
  std::pair<uint32_t, bool> insert(const Key128& key);
  // The number of key, or kNone.
  uint32_t find(const Key128& key) const;

  size_t size() const { return keys_.size(); }
  const Key128& key(uint32_t number) const { return keys_[number]; }
  const auto& keys() const { return keys_; }  // in number order

 private:
  using Slots = std::vector<uint32_t, SpillAllocator<uint32_t, true>>;
  static constexpr size_t kNoPart = CellCut::kNoPart;
  struct Stretch {
    size_t offset = 0, capacity = 0, count = 0;  // capacity 0: never opened
  };

  size_t partOf(const Key128& key) const;
  uint32_t findIn(const Slots& slots, size_t offset, size_t mask, const Key128& key) const;
  uint32_t findShared(const Key128& key) const;
  void rehashShared(size_t capacity);

  std::vector<Key128, SpillAllocator<Key128, true>> keys_;
  Slots shared_;
  size_t sharedMask_ = 0, sharedCount_ = 0;
  CellCut cut_;  // when there is one
  std::vector<Stretch> stretches_;
  Slots partSlots_;
  size_t open_ = kNoPart;
};

}  // namespace iso
