// LAS output: what is written reads back through the LAS reader (positions to half the scale,
// colors as the same 8-bit codes), the fixed fields are where LAS 1.2 puts them, and a write that
// fails leaves nothing behind.
#include <cstring>
#include <fstream>
#include <random>

#include "iso/error.h"
#include "iso/quantize.h"
#include "pipeline/io/las.h"
#include "tests/io/io_test_util.h"

namespace iso {
namespace {

PointCloud cloudAt(glm::dvec3 base, double extent, size_t count, bool colors) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> coordinate(0.0, extent);
  std::uniform_real_distribution<float> unit(0.0f, 1.0f);
  PointCloud cloud;
  for (size_t i = 0; i < count; ++i) {
    cloud.positions.push_back(base + glm::dvec3(coordinate(rng), coordinate(rng), coordinate(rng)));
    if (colors) cloud.colors.emplace_back(unit(rng), unit(rng), unit(rng));
  }
  return cloud;
}

std::vector<char> fileBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

template <typename T>
T at(const std::vector<char>& bytes, size_t offset) {
  T value;
  std::memcpy(&value, bytes.data() + offset, sizeof(T));
  return value;
}

TEST(LasWriter, readsBackToHalfTheScaleWithTheSameColorCodes) {
  // A small object far from the origin (a UTM scan of a statue) and a large one near it.
  for (const auto& [base, extent] : {std::pair{glm::dvec3(515000.25, 4918000.5, 300.0), 0.25},
                                     std::pair{glm::dvec3(-20.0, 3.0, -7.5), 900.0}}) {
    const PointCloud written = cloudAt(base, extent, 5000, true);
    test::TempDir dir;
    writeLas(dir / "scan.las", written);
    const std::vector<char> bytes = fileBytes(dir / "scan.las");
    ASSERT_EQ(bytes.size(), 227u + 26u * written.size());
    EXPECT_EQ(std::string(bytes.data(), 4), "LASF");
    EXPECT_EQ(at<uint8_t>(bytes, 104), 2u);  // point data format 2: with RGB
    const double scale = at<double>(bytes, 131);
    // The finest power of ten whose integers (within 2^31) hold the extent from the offset.
    EXPECT_LE(extent + 1.0, scale * double(1 << 30) * 2.0);
    EXPECT_GT(extent, scale * double(1 << 30) / 10.0 - 1.0);
    const PointCloud read = readPointFile(dir / "scan.las");
    ASSERT_EQ(read.size(), written.size());
    ASSERT_TRUE(read.hasColors());
    for (size_t i = 0; i < read.size(); ++i) {
      for (int axis = 0; axis < 3; ++axis)
        ASSERT_LE(std::abs(read.positions[i][axis] - written.positions[i][axis]),
                  0.5 * scale * (1.0 + 1e-9) + 1e-9 * std::abs(written.positions[i][axis]))
            << i;
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(linearToSrgb8(read.colors[i][c]), linearToSrgb8(written.colors[i][c])) << i;
    }
  }
}

TEST(LasWriter, writesFormatZeroWithoutColorsAndNoFileWhenItFails) {
  const PointCloud written = cloudAt(glm::dvec3(1.0), 2.0, 100, false);
  test::TempDir dir;
  writeLas(dir / "plain.las", written);
  const std::vector<char> bytes = fileBytes(dir / "plain.las");
  ASSERT_EQ(bytes.size(), 227u + 20u * 100u);
  EXPECT_EQ(at<uint8_t>(bytes, 24), 1u);  // version 1.2
  EXPECT_EQ(at<uint8_t>(bytes, 25), 2u);
  EXPECT_EQ(at<uint32_t>(bytes, 96), 227u);  // points right after the header
  EXPECT_EQ(at<uint8_t>(bytes, 104), 0u);
  EXPECT_EQ(at<uint16_t>(bytes, 105), 20u);
  EXPECT_EQ(at<uint32_t>(bytes, 107), 100u);
  EXPECT_FALSE(readPointFile(dir / "plain.las").hasColors());
  // Into a folder that does not exist: an error naming the file, and nothing written.
  const std::filesystem::path missing = dir / "no" / "such.las";
  try {
    writeLas(missing, written);
    FAIL() << "expected a FileError";
  } catch (const FileError& e) {
    EXPECT_NE(std::string(e.what()).find("such.las"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "no"));
}

}  // namespace
}  // namespace iso
