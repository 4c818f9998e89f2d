// Compact open-addressing hash tables (linear probing, power-of-two capacity, at most half full,
// no erase) for the many small integer keys of octree work: corner positions, node codes. Much
// faster and smaller than std::unordered_map for that use.
//
//   FlatMap   key-value pairs in the table itself: for small values and tables
//   KeyIndex  keys numbered in insertion order, in a dense array, found through a table of 4-byte
//             numbers: a 16-byte key takes 24 to 32 bytes, where FlatMap<Key128, uint32_t> takes
//             50 to 100 (millions of corners)
//
// Threading: like std containers (concurrent const use only).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>
#include <vector>

namespace iso {

// A 128-bit key; hashed with a 64-bit mix of both halves.
struct Key128 {
  uint64_t a = 0, b = 0;
  bool operator==(const Key128&) const = default;
};

inline uint64_t hashBits(uint64_t x) {  // the splitmix64 finalizer
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

struct KeyHash {
  uint64_t operator()(uint64_t k) const { return hashBits(k); }
  uint64_t operator()(const Key128& k) const {
    return hashBits(k.a ^ hashBits(k.b + 0x9e3779b97f4a7c15ull));
  }
};

// Slots for `expected` keys in a table at most half full: a power of two, at least 16.
inline size_t tableCapacity(size_t expected) {
  size_t c = 16;
  while (c < expected * 2) c *= 2;
  return c;
}

// Both tables take an allocator for their arrays (the pipeline keeps large ones in files).
template <typename Key, typename Value, typename Allocator = std::allocator<std::pair<Key, Value>>>
class FlatMap {
 public:
  explicit FlatMap(size_t expected = 16) { rehash(tableCapacity(expected)); }

  // The value for key, inserting `value` first when the key is new; second is true when inserted.
  std::pair<Value*, bool> insert(const Key& key, const Value& value) {
    if ((size_ + 1) * 2 > slots_.size()) rehash(slots_.size() * 2);
    size_t i = KeyHash{}(key)&mask_;
    while (used_[i]) {
      if (slots_[i].first == key) return {&slots_[i].second, false};
      i = (i + 1) & mask_;
    }
    used_[i] = 1;
    slots_[i] = {key, value};
    ++size_;
    return {&slots_[i].second, true};
  }

  const Value* find(const Key& key) const {
    size_t i = KeyHash{}(key)&mask_;
    while (used_[i]) {
      if (slots_[i].first == key) return &slots_[i].second;
      i = (i + 1) & mask_;
    }
    return nullptr;
  }
  Value* find(const Key& key) { return const_cast<Value*>(std::as_const(*this).find(key)); }

  size_t size() const { return size_; }

  template <typename F>
  void forEach(F&& f) const {
    for (size_t i = 0; i < slots_.size(); ++i)
      if (used_[i]) f(slots_[i].first, slots_[i].second);
  }

 private:
  void rehash(size_t capacity) {
    Slots old = std::move(slots_);
    Used oldUsed = std::move(used_);
    slots_.assign(capacity, {});
    used_.assign(capacity, 0);
    mask_ = capacity - 1;
    size_ = 0;
    for (size_t i = 0; i < old.size(); ++i)
      if (oldUsed[i]) insert(old[i].first, old[i].second);
  }

  using Slots = std::vector<
      std::pair<Key, Value>,
      typename std::allocator_traits<Allocator>::template rebind_alloc<std::pair<Key, Value>>>;
  using Used =
      std::vector<uint8_t,
                  typename std::allocator_traits<Allocator>::template rebind_alloc<uint8_t>>;
  Slots slots_;
  Used used_;
  size_t mask_ = 0;
  size_t size_ = 0;
};

// Keys numbered 0, 1, 2, ... in the order they were first inserted. The allocator serves the key
// array and the table.
template <typename Key, typename KeyAllocator = std::allocator<Key>>
class KeyIndex {
 public:
  static constexpr uint32_t kNone = 0xffffffffu;

  // Room for `expected` keys: the table is made (4 bytes a slot), the key array reserved.
  explicit KeyIndex(size_t expected = 16) {
    reserveKeys(expected);
    rehash(tableCapacity(expected));
  }

  // Reserve the key array only (address space: pages count once written); the table still grows
  // by doubling, so that an estimate too high never doubles its resident size.
  void reserveKeys(size_t expected) { keys_.reserve(expected); }

  // The number of key, which is added (as the next number) when new; second: whether it was.
  std::pair<uint32_t, bool> insert(const Key& key) {
    if ((keys_.size() + 1) * 2 > slots_.size()) rehash(slots_.size() * 2);
    size_t i = KeyHash{}(key)&mask_;
    for (; slots_[i] != kNone; i = (i + 1) & mask_)
      if (keys_[slots_[i]] == key) return {slots_[i], false};
    slots_[i] = uint32_t(keys_.size());
    keys_.push_back(key);
    return {slots_[i], true};
  }

  // The number of key, or kNone.
  uint32_t find(const Key& key) const {
    for (size_t i = KeyHash{}(key)&mask_; slots_[i] != kNone; i = (i + 1) & mask_)
      if (keys_[slots_[i]] == key) return slots_[i];
    return kNone;
  }

  size_t size() const { return keys_.size(); }
  const Key& key(uint32_t number) const { return keys_[number]; }
  const auto& keys() const { return keys_; }  // in number order

 private:
  void rehash(size_t capacity) {
    slots_.assign(capacity, kNone);
    mask_ = capacity - 1;
    for (uint32_t n = 0; n < keys_.size(); ++n) {
      size_t i = KeyHash{}(keys_[n]) & mask_;
      while (slots_[i] != kNone) i = (i + 1) & mask_;
      slots_[i] = n;
    }
  }

  std::vector<uint32_t,
              typename std::allocator_traits<KeyAllocator>::template rebind_alloc<uint32_t>>
      slots_;
  std::vector<Key, KeyAllocator> keys_;
  size_t mask_ = 0;
};

}  // namespace iso
