// A scan's CompressedVector binary section (ASTM E2807 section 9.9.3, Tables 27–31): a 32-byte
// section header (sectionId 1, the section's logical length, the physical offsets of its first data
// packet and of its index), then packets in the logical stream, each a multiple of 4 bytes and at
// most 64 KiB: data packets (type 1) carry a buffer of each prototype field's bytestream, index
// packets (type 0) and empty packets (type 2) are skipped. All fields little endian.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "pipeline/io/e57_bitpack.h"
#include "pipeline/io/e57_pages.h"
#include "pipeline/io/e57_xml.h"

namespace iso::io {

// The bytes of all fields that data packets brought ahead of the records decoded: more is refused
// (a file that stores one field's values long before the others'), so memory stays bounded
// whatever the file.
inline constexpr size_t kE57MaxPendingBytes = size_t{64} << 20;

// Where a section lies in the logical stream.
struct E57Section {
  uint64_t begin = 0;      // its header
  uint64_t end = 0;        // one past its last byte
  uint64_t dataBegin = 0;  // its first data packet
};

// Read and check the section header of a scan with records: inside the file, id 1, its data inside
// it, and large enough for the scan's records at the prototype's bits per record. Throws
// iso::FileError naming the scan (`label`).
E57Section readE57Section(E57Pages& pages, const E57Scan& scan, const std::string& label);

// The packets of one section in order, feeding the fields' bytestreams.
class E57PacketReader {
 public:
  E57PacketReader(E57Pages& pages, const E57Section& section, const E57Scan& scan,
                  std::string label);

  std::vector<E57ByteStream>& streams() { return streams_; }
  // Read the next packet, appending a data packet's buffers to the streams; false when the section
  // has no packet left. Throws iso::FileError for a malformed packet or when the pending bytes
  // exceed kE57MaxPendingBytes.
  bool readPacket();

 private:
  [[noreturn]] void failAt(uint64_t logical, const std::string& reason) const;
  void readDataPacket(uint64_t at, size_t length);
  void checkPendingBytes(uint64_t at) const;

  E57Pages& pages_;
  E57Section section_;
  const E57Scan& scan_;
  std::string label_;
  uint64_t next_;  // logical offset of the next packet
  std::vector<E57ByteStream> streams_;
  std::vector<std::byte> packet_;
};

}  // namespace iso::io
