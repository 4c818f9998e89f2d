// Byte sizes as the command line reads them (base/text.h): exact whole numbers up to 2^64 − 1,
// binary units, and a reason for everything refused.
#include <gtest/gtest.h>

#include <limits>

#include "base/text.h"

namespace iso {
namespace {

constexpr uint64_t kMax = std::numeric_limits<uint64_t>::max();

TEST(ByteSize, unitsArePowersOf1024InEitherCaseAndSpelling) {
  EXPECT_EQ(parseByteSize("100000"), 100000u);
  EXPECT_EQ(parseByteSize("+7"), 7u);
  EXPECT_EQ(parseByteSize("1K"), 1024u);
  EXPECT_EQ(parseByteSize("512M"), 512u << 20);
  EXPECT_EQ(parseByteSize("2G"), uint64_t{2} << 30);
  EXPECT_EQ(parseByteSize("3T"), uint64_t{3} << 40);
  for (const char* same : {"2g", "2GB", "2GiB", "2gb", "2gib"})
    EXPECT_EQ(parseByteSize(same), uint64_t{2} << 30) << same;
  EXPECT_EQ(parseByteSize("1.5K"), 1536u);
  EXPECT_EQ(parseByteSize("1.5G"), uint64_t{3} << 29);
  EXPECT_EQ(parseByteSize("1e3"), 1000u);
  EXPECT_EQ(parseByteSize("2.9"), 2u);  // whole bytes, rounded down
}

TEST(ByteSize, wholeNumbersAreExactUpToTheLargestUnsigned64BitValue) {
  EXPECT_EQ(parseByteSize("18446744073709551615"), kMax);
  EXPECT_EQ(parseByteSize("18446744073709551614"), kMax - 1);
  EXPECT_EQ(parseByteSize("16777215T"), ((uint64_t{1} << 24) - 1) << 40);
  EXPECT_EQ(parseByteSize("17179869183G"), kMax - ((uint64_t{1} << 30) - 1));
}

TEST(ByteSize, sizesPastTwoToThe64AreRefusedAsTooLarge) {
  for (const char* text :
       {"18446744073709551616", "99999999999999999999", "99999999999999999999G", "16777216T",
        "17179869184G", "17179869184.5G", "1e20", "2e19K", "inf", "1e400"}) {
    std::string why;
    EXPECT_EQ(parseByteSize(text, &why), std::nullopt) << text;
    EXPECT_NE(why.find("more than 2^64"), std::string::npos) << text << ": " << why;
  }
}

TEST(ByteSize, nothingBelowOneByteIsASize) {
  for (const char* text : {"0", "0K", "-1", "-2G", "-0", "0.5", "0.0001K", "1e-9", "-inf"}) {
    std::string why;
    EXPECT_EQ(parseByteSize(text, &why), std::nullopt) << text;
    EXPECT_TRUE(why == "not positive" || why == "less than one byte") << text << ": " << why;
  }
}

TEST(ByteSize, textThatIsNotANumberIsRefusedWithAReason) {
  for (const char* text : {"", "G", "lots", "nan", "NaN", "-nan", "0x10", " 5G", "5G ", "5 G", "5X",
                           "5KK", "5iB", "1,5G", "++5", "+-5", "5E", "1KBB", "16384P0"}) {
    std::string why;
    EXPECT_EQ(parseByteSize(text, &why), std::nullopt) << "'" << text << "'";
    EXPECT_NE(why.find("not a number"), std::string::npos) << "'" << text << "': " << why;
  }
}

}  // namespace
}  // namespace iso
