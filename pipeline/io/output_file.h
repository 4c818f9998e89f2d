// A buffered output file written under a temporary name in the destination's directory and renamed
// into place by commit(), so that the destination holds either its old content or a complete file.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <span>
#include <string_view>

namespace iso::io {

class OutputFile {
 public:
  // Creates the temporary file. Every error throws iso::FileError naming the final path.
  explicit OutputFile(std::filesystem::path path);
  ~OutputFile();  // removes the temporary file unless committed
  OutputFile(const OutputFile&) = delete;
  OutputFile& operator=(const OutputFile&) = delete;

  void write(std::span<const std::byte> bytes);
  void write(std::string_view text) { write(std::as_bytes(std::span(text.data(), text.size()))); }
  // Flush, sync to disk and rename over the final path.
  void commit();

  const std::filesystem::path& temporaryPath() const { return temporary_; }

 private:
  void flush();
  [[noreturn]] void fail(const std::string& what, int error) const;

  std::filesystem::path path_;
  std::filesystem::path temporary_;
  int fd_ = -1;
  std::unique_ptr<std::byte[]> buffer_;
  size_t buffered_ = 0;
  bool isCommitted_ = false;
};

}  // namespace iso::io
