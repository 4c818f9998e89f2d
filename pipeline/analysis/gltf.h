// glTF 2.0 binary files (.glb) of the exports' triangle meshes (specs/pipeline.md §17): positions
// quantized to 16 bits (KHR_mesh_quantization) where that keeps them fine enough, normals
// octahedral in two bytes, linear colors in bytes, every stream compressed by meshoptimizer
// (EXT_meshopt_compression).
#pragma once

#include <cstddef>
#include <cstdint>
#include <glm/vec3.hpp>
#include <string>
#include <vector>

#include "pipeline/analysis/export.h"

namespace iso {

struct GlbOptions {
  // Positions in 16 bits when their step (the largest extent / 65,535) is at most this (world
  // units), else in float; 0: always 16 bits.
  double maxPositionStep = 0.0;
  // The 16-bit positions' step (world units) when it is coarser than the finest 16 bits allow
  // and 16 bits reach over the mesh with it: a grid of its multiples from `origin`, which
  // compresses better and which meshes written with one step share (0: the finest).
  double positionStep = 0.0;
  bool compress = true;  // EXT_meshopt_compression (off: plain buffers, for comparison)
  // Positions are stored relative to this point (world units), which the node's translation
  // adds back (a tileset's root transform may carry it instead: see `translate`).
  glm::dvec3 origin{0.0};
  bool translate = true;  // the node adds `origin` back
  // Z up (scans, 3D Tiles) to glTF's Y up: (x, y, z) - origin is stored as (x, z, -y), which a
  // 3D Tiles client turns back; the node leaves `origin` out (the tileset's root transform
  // carries it), whatever `translate` says.
  bool yUp = false;
  // Triangles from this one on are skirts (3D Tiles), a second primitive over the same vertices.
  size_t skirtsFrom = SIZE_MAX;
  // The colors are lit already (baked lighting): the primitives' material is unlit
  // (KHR_materials_unlit; viewers without it light a white matte material with them).
  bool unlit = false;
};

struct GlbStats {
  uint64_t bytes = 0;
  uint64_t vertices = 0, triangles = 0;
  bool quantized = false;   // 16-bit positions
  double positionStep = 0;  // world units (0 for float positions)
};

// The mesh as a .glb file's bytes: one mesh, one node, one scene; positions in the mesh's world
// axes (relative to options.origin); NORMAL and COLOR_0 when the attributes have them.
// Deterministic.
std::vector<uint8_t> encodeGlb(const TriangleMesh& mesh, const MeshAttributes& attributes,
                               const GlbOptions& options = {}, GlbStats* stats = nullptr);

// The triangles of a .glb file that encodeGlb wrote (one mesh, one node; 16-bit or float
// positions, meshopt-compressed or not), with the node's translation and scale applied: for
// measuring what a tileset holds. With surfaceOnly, the first primitive's (no skirts). Throws
// iso::FileError naming `name` for anything else.
TriangleMesh decodeGlb(const std::vector<uint8_t>& bytes, const std::string& name,
                       bool surfaceOnly = false);

}  // namespace iso
