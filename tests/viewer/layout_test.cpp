// The structs of shaders/shared.h as the compiled shader lays them out (read from the SPIR-V's
// member names and Offset decorations) against the C++ side's offsetof and sizeof.
#include <gtest/gtest.h>

#include <cstddef>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "shaders/shared.h"
#include "tests/support/support.h"

namespace iso::test {
namespace {

struct SpirvLayout {
  std::map<uint32_t, std::string> names;                             // id → name
  std::map<std::pair<uint32_t, uint32_t>, std::string> memberNames;  // (struct, member) → name
  std::map<std::pair<uint32_t, uint32_t>, uint32_t> offsets;         // (struct, member) → offset
  std::map<uint32_t, uint32_t> arrayStrides;                         // array type → stride

  // Offsets of a struct's members by name.
  std::map<std::string, uint32_t> membersOf(const std::string& structName) const {
    std::map<std::string, uint32_t> out;
    for (const auto& [id, name] : names) {
      if (name != structName) continue;
      for (const auto& [key, offset] : offsets)
        if (key.first == id && memberNames.contains(key)) out[memberNames.at(key)] = offset;
    }
    return out;
  }
};

SpirvLayout readSpirv(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::vector<uint32_t> words;
  uint32_t w;
  while (in.read(reinterpret_cast<char*>(&w), 4)) words.push_back(w);
  EXPECT_GT(words.size(), 5u);
  EXPECT_EQ(words[0], 0x07230203u);  // SPIR-V magic
  SpirvLayout layout;
  const auto text = [&](size_t at, size_t end) {
    std::string s;
    for (size_t i = at; i < end; ++i)
      for (int b = 0; b < 4; ++b) {
        const char c = char(words[i] >> (8 * b));
        if (c == 0) return s;
        s += c;
      }
    return s;
  };
  for (size_t i = 5; i < words.size();) {
    const uint32_t count = words[i] >> 16, opcode = words[i] & 0xFFFF;
    if (count == 0) break;
    if (opcode == 5) layout.names[words[i + 1]] = text(i + 2, i + count);  // OpName
    if (opcode == 6) layout.memberNames[{words[i + 1], words[i + 2]}] = text(i + 3, i + count);
    if (opcode == 72 && words[i + 3] == 35)
      layout.offsets[{words[i + 1], words[i + 2]}] = words[i + 4];
    if (opcode == 71 && words[i + 2] == 6) layout.arrayStrides[words[i + 1]] = words[i + 3];
    i += count;
  }
  return layout;
}

TEST(ViewerLayout, theShaderLaysOutSharedStructsAsTheCppSideDoes) {
  const SpirvLayout spirv = readSpirv(builtPath("ISO_TRACE_DEBUG_SPIRV", ISO_TRACE_DEBUG_SPIRV));
  using gpu::FrameParams;
  const std::map<std::string, uint32_t> frame = {
      {"eye", offsetof(FrameParams, eye)},
      {"right", offsetof(FrameParams, right)},
      {"up", offsetof(FrameParams, up)},
      {"forward", offsetof(FrameParams, forward)},
      {"image", offsetof(FrameParams, image)},
      {"options", offsetof(FrameParams, options)},
      {"pool", offsetof(FrameParams, pool)},
      {"lod", offsetof(FrameParams, lod)},
      {"ambient", offsetof(FrameParams, ambient)},
      {"albedo", offsetof(FrameParams, albedo)},
      {"material", offsetof(FrameParams, material)},
      {"medium", offsetof(FrameParams, medium)},
      {"skyTop", offsetof(FrameParams, skyTop)},
      {"skyBottom", offsetof(FrameParams, skyBottom)},
      {"worldUp", offsetof(FrameParams, worldUp)},
      {"backface", offsetof(FrameParams, backface)},
      {"surface", offsetof(FrameParams, surface)},
      {"lights", offsetof(FrameParams, lights)},
      {"poolAddress", offsetof(FrameParams, poolAddress)},
      {"srgbToLinear", offsetof(FrameParams, srgbToLinear)},
      {"srgbBounds", offsetof(FrameParams, srgbBounds)},
      {"contentLo", offsetof(FrameParams, contentLo)},
      {"contentHi", offsetof(FrameParams, contentHi)},
      {"splatIndex", offsetof(FrameParams, splatIndex)},
      {"splat", offsetof(FrameParams, splat)},
      {"ground", offsetof(FrameParams, ground)},
      {"groundColor", offsetof(FrameParams, groundColor)},
      {"caustics", offsetof(FrameParams, caustics)},
      {"causticDisc", offsetof(FrameParams, causticDisc)},
      {"causticU", offsetof(FrameParams, causticU)},
      {"causticV", offsetof(FrameParams, causticV)}};
  EXPECT_EQ(spirv.membersOf("FrameParams"), frame);
  const std::map<std::string, uint32_t> light = {{"position", offsetof(gpu::Light, position)},
                                                 {"color", offsetof(gpu::Light, color)},
                                                 {"u", offsetof(gpu::Light, u)},
                                                 {"v", offsetof(gpu::Light, v)}};
  EXPECT_EQ(spirv.membersOf("Light"), light);
  EXPECT_EQ(spirv.membersOf("ChunkEntry"), (std::map<std::string, uint32_t>{{"state", 0}}));
  // Arrays: the lights (64 bytes apart), the chunk table (16) and the pool addresses (16).
  std::multiset<uint32_t> strides;
  for (const auto& [id, stride] : spirv.arrayStrides) strides.insert(stride);
  EXPECT_TRUE(strides.contains(sizeof(gpu::Light)));
  EXPECT_TRUE(strides.contains(sizeof(gpu::ChunkEntry)));
}

}  // namespace
}  // namespace iso::test
