// A bounding volume hierarchy over axis-aligned boxes (the mesh shape's triangles), built by binned
// SAH and stored as a flat array of 32-byte nodes for stack-based traversal.
#pragma once

#include <cstdint>
#include <glm/vec3.hpp>
#include <span>
#include <vector>

namespace iso {

struct Box {
  glm::dvec3 lower;
  glm::dvec3 upper;
};

// Bounds are floats relative to Bvh::origin, rounded outwards so that a node contains the double
// boxes of its primitives.
struct BvhNode {
  float lower[3];
  float upper[3];
  uint32_t first;  // interior: the left child (the right child is first + 1); leaf: first primitive
  uint32_t count;  // a leaf's primitives, order[first, first + count); 0 for an interior node

  bool isLeaf() const { return count != 0; }
};
static_assert(sizeof(BvhNode) == 32);

// Two siblings in one 64-byte cache line: a traversal step reads both children's boxes at once.
struct alignas(64) BvhNodePair {
  BvhNode node[2];
};

struct Bvh {
  // The longest root-to-leaf path has fewer nodes than this (see bvh.cpp), so a traversal stack
  // holding one entry per level never overflows.
  static constexpr int kMaxDepth = 128;

  glm::dvec3 origin{0.0};          // the centre of the root's bounds
  std::vector<BvhNodePair> pairs;  // node i is pairs[i / 2].node[i % 2]; the root is node 0
  std::vector<uint32_t> order;     // leaf position -> index of the input box

  const BvhNode& node(uint32_t i) const { return pairs[i >> 1].node[i & 1]; }
};

// Build over `boxes` with TBB tasks; no boxes give no nodes. The tree depends only on the boxes,
// never on the number of threads.
Bvh buildBvh(std::span<const Box> boxes);

}  // namespace iso
