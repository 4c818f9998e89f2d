// The hash tables of iso/flat_map.h against std::map on random keys, through many rehashes.
#include <gtest/gtest.h>

#include <cstdint>
#include <map>
#include <random>

#include "iso/flat_map.h"

namespace iso {
namespace {

// Keys with many collisions in their low bits and repeats, as corner grid points have.
Key128 randomKey(std::mt19937_64& random) {
  const uint64_t x = random() % 4096, y = random() % 64;
  return {x << 20 | y, (random() % 16) << 40};
}

struct KeyOrder {
  bool operator()(const Key128& x, const Key128& y) const {
    return x.a != y.a ? x.a < y.a : x.b < y.b;
  }
};

TEST(KeyIndex, numbersKeysInInsertionOrderAndFindsThemAfterRehashes) {
  std::mt19937_64 random(7);
  KeyIndex<Key128> index;  // starts small: grows through many rehashes
  std::map<Key128, uint32_t, KeyOrder> truth;
  for (int i = 0; i < 200000; ++i) {
    const Key128 key = randomKey(random);
    const auto [number, added] = index.insert(key);
    const auto [it, inserted] = truth.insert({key, uint32_t(truth.size())});
    ASSERT_EQ(added, inserted);
    ASSERT_EQ(number, it->second);
  }
  ASSERT_EQ(index.size(), truth.size());
  ASSERT_GT(truth.size(), 100000u);  // the repeats were real, and so were the new keys
  for (const auto& [key, number] : truth) {
    ASSERT_EQ(index.find(key), number);
    ASSERT_EQ(index.key(number), key);
  }
  for (int i = 0; i < 10000; ++i) {  // keys never inserted
    const Key128 key{random() | uint64_t{1} << 63, random()};
    EXPECT_EQ(index.find(key), KeyIndex<Key128>::kNone);
  }
}

TEST(FlatMap, keepsTheFirstValueOfEachKeyAfterRehashes) {
  std::mt19937_64 random(11);
  FlatMap<uint64_t, uint32_t> map;
  std::map<uint64_t, uint32_t> truth;
  for (uint32_t i = 0; i < 100000; ++i) {
    const uint64_t key = random() % 60000;
    const auto [value, added] = map.insert(key, i);
    const auto [it, inserted] = truth.insert({key, i});
    ASSERT_EQ(added, inserted);
    ASSERT_EQ(*value, it->second);
  }
  ASSERT_EQ(map.size(), truth.size());
  for (const auto& [key, value] : truth) ASSERT_EQ(*map.find(key), value);
  EXPECT_EQ(map.find(60000), nullptr);
}

}  // namespace
}  // namespace iso
