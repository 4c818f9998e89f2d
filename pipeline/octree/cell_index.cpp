// Grid keys in a table cut by space (cell_index.h).
#include "pipeline/octree/cell_index.h"

#include <algorithm>

#include "iso/format.h"
#include "iso/surface.h"

namespace iso {

CellKeyIndex::CellKeyIndex(size_t expected) {
  reserveKeys(expected);
  rehashShared(tableCapacity(expected));
}

size_t CellCut::partOfNode(uint8_t nodeLevel, uint64_t nodeKey) const {
  if (nodeLevel < level) return kNoPart;
  const uint64_t cell = nodeKey >> (3 * (nodeLevel - level));
  return size_t(std::upper_bound(firstCell.begin(), firstCell.end(), cell) - firstCell.begin()) - 1;
}

void CellKeyIndex::cutByCells(const CellCut& cut, size_t expectedKeys) {
  cut_ = cut;
  stretches_.assign(cut_.firstCell.size(), {});
  partSlots_.reserve(2 * expectedKeys + 16 * cut_.firstCell.size());
}

void CellKeyIndex::openPart(size_t part, size_t expected) {
  open_ = part;
  Stretch& s = stretches_[part];
  if (s.capacity > 0) return;  // opened before: its stretch stays as it is
  s.offset = partSlots_.size();
  s.capacity = tableCapacity(expected);
  partSlots_.resize(s.offset + s.capacity, kNone);
}

size_t CellKeyIndex::partOf(const Key128& key) const {
  const int shift = kMaxLevel - cut_.level;
  const uint32_t last = (1u << cut_.level) - 1;
  const auto cell = [&](uint32_t v) { return std::min(v >> shift, last); };
  const uint64_t code =
      mortonEncode(cell(uint32_t(key.a)), cell(uint32_t(key.a >> 32)), cell(uint32_t(key.b)));
  return size_t(std::upper_bound(cut_.firstCell.begin(), cut_.firstCell.end(), code) -
                cut_.firstCell.begin()) -
         1;
}

uint32_t CellKeyIndex::findIn(const Slots& slots, size_t offset, size_t mask,
                              const Key128& key) const {
  for (size_t i = KeyHash{}(key)&mask; slots[offset + i] != kNone; i = (i + 1) & mask)
    if (keys_[slots[offset + i]] == key) return slots[offset + i];
  return kNone;
}

uint32_t CellKeyIndex::findShared(const Key128& key) const {
  return findIn(shared_, 0, sharedMask_, key);
}

uint32_t CellKeyIndex::find(const Key128& key) const {
  if (!cut_.firstCell.empty()) {
    const Stretch& s = stretches_[partOf(key)];
    if (s.capacity > 0) {
      const uint32_t n = findIn(partSlots_, s.offset, s.capacity - 1, key);
      if (n != kNone) return n;
    }
  }
  return findShared(key);
}

std::pair<uint32_t, bool> CellKeyIndex::insert(const Key128& key) {
  const uint32_t number = uint32_t(keys_.size());
  if (!cut_.firstCell.empty()) {
    const size_t part = partOf(key);
    Stretch& s = stretches_[part];
    const size_t mask = s.capacity - 1;
    if (s.capacity > 0) {
      size_t i = KeyHash{}(key)&mask;
      for (; partSlots_[s.offset + i] != kNone; i = (i + 1) & mask)
        if (keys_[partSlots_[s.offset + i]] == key) return {partSlots_[s.offset + i], false};
      // Not in its stretch: in the shared table, or new.
      if (const uint32_t n = findShared(key); n != kNone) return {n, false};
      if (part == open_ && (s.count + 1) * 2 <= s.capacity) {
        partSlots_[s.offset + i] = number;
        ++s.count;
        keys_.push_back(key);
        return {number, true};
      }
    }
  }
  if ((sharedCount_ + 1) * 2 > shared_.size()) rehashShared(shared_.size() * 2);
  size_t i = KeyHash{}(key)&sharedMask_;
  for (; shared_[i] != kNone; i = (i + 1) & sharedMask_)
    if (keys_[shared_[i]] == key) return {shared_[i], false};
  shared_[i] = number;
  ++sharedCount_;
  keys_.push_back(key);
  return {number, true};
}

void CellKeyIndex::rehashShared(size_t capacity) {
  // Only the keys in the shared table are placed again: a key in a stretch is found there.
  Slots old = std::move(shared_);
  shared_.assign(capacity, kNone);
  sharedMask_ = capacity - 1;
  for (const uint32_t n : old) {
    if (n == kNone) continue;
    size_t i = KeyHash{}(keys_[n]) & sharedMask_;
    while (shared_[i] != kNone) i = (i + 1) & sharedMask_;
    shared_[i] = n;
  }
}

}  // namespace iso
