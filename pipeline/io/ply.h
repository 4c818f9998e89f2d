// PLY meshes and PLY output.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "pipeline/io/point_cloud.h"

namespace iso {

// Read the vertices and faces of a PLY mesh (ASCII or binary, optionally .gz). Polygons with more
// than three vertices are fanned into triangles. Throws iso::FileError (file, offset or line,
// reason) for malformed or truncated files and for files without faces.
TriangleMesh readPlyMesh(const std::filesystem::path& path);

struct PlyWriteOptions {
  bool binary = true;            // binary little endian, else ASCII
  bool doublePositions = true;   // x y z as double (keeps large offsets exact), else float
  std::vector<std::string> comments = {};  // "comment" lines in the header
  // The points' extras, written as double properties of these names (the points' extraNames
  // must be these); empty: extras are not written.
  std::vector<std::string> extraNames = {};
};

// Write points (with their normals and colors when present; colors as uchar sRGB; extras as
// PlyWriteOptions::extraNames says) to a PLY file,
// atomically: a temporary file renamed into place. Throws iso::FileError on failure.
void writePly(const std::filesystem::path& path, const PointCloud& points,
              const PlyWriteOptions& options = {});

// The same for points given batch by batch: a header for `count` points, then write() until
// that many are written, then commit(). Nothing appears at path unless commit() succeeds.
class AtomicFile;
class PlyPointWriter {
 public:
  PlyPointWriter(const std::filesystem::path& path, uint64_t count, bool normals, bool colors,
                 const PlyWriteOptions& options = {});
  ~PlyPointWriter();
  void write(const PointCloud& points);  // with normals and colors as declared
  void commit();

 private:
  std::unique_ptr<AtomicFile> file_;
  PlyWriteOptions options_;
  uint64_t count_, written_ = 0;
  bool normals_, colors_;
};

// Write a triangle mesh as PLY (binary little endian, float positions).
void writePlyMesh(const std::filesystem::path& path, const TriangleMesh& mesh,
                  bool doublePositions = false);

}  // namespace iso
