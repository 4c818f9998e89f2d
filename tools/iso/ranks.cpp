#include "tools/iso/ranks.h"

#include <cstdlib>
#include <string>
#include <vector>

#include "iso/error.h"

#if ISO_WITH_MPI
#define OMPI_SKIP_MPICXX 1  // the C interface only
#define MPICH_SKIP_MPICXX 1
#include <mpi.h>
#endif

namespace iso::cli {

int launchedRanks() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "PMIX_SIZE"})
    if (const char* value = std::getenv(name)) return std::max(1, std::atoi(value));
  return 1;
}

#if ISO_WITH_MPI

MpiRanks::MpiRanks() {
  int provided = 0;
  // Only the main thread calls MPI; the stages' threads never do.
  MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &count_);
}

MpiRanks::~MpiRanks() { MPI_Finalize(); }

Ranks MpiRanks::ranks(const std::filesystem::path& shared) const {
  Ranks r;
  r.rank = rank_;
  r.count = count_;
  r.barrier = [] { MPI_Barrier(MPI_COMM_WORLD); };
  r.broadcast = [](std::vector<std::byte>& bytes) {
    auto size = uint64_t(bytes.size());
    MPI_Bcast(&size, 1, MPI_UINT64_T, 0, MPI_COMM_WORLD);
    bytes.resize(size);
    for (uint64_t done = 0; done < size;) {  // MPI counts are ints
      const int n = int(std::min<uint64_t>(size - done, 1u << 30));
      MPI_Bcast(bytes.data() + done, n, MPI_BYTE, 0, MPI_COMM_WORLD);
      done += uint64_t(n);
    }
  };
  std::string path = shared.string();
  std::vector<std::byte> text(reinterpret_cast<const std::byte*>(path.data()),
                              reinterpret_cast<const std::byte*>(path.data() + path.size()));
  r.broadcast(text);
  r.shared = std::string(reinterpret_cast<const char*>(text.data()), text.size());
  std::error_code error;
  int seen = std::filesystem::is_directory(r.shared, error) ? 1 : 0, all = 0;
  MPI_Allreduce(&seen, &all, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  if (all == 0)
    throw FileError(r.shared.string(), std::nullopt,
                    seen == 0 ? "rank " + std::to_string(rank_) +
                                    " cannot see rank 0's temporary directory: the ranks of a "
                                    "distributed run need --tmp on a file system they all see"
                              : "another rank cannot see this temporary directory: the ranks of "
                                "a distributed run need --tmp on a file system they all see");
  return r;
}

void MpiRanks::abort(int exitCode) const {
  MPI_Abort(MPI_COMM_WORLD, exitCode);
  std::exit(exitCode);
}

#else

MpiRanks::MpiRanks() {
  throw UsageError(
      "started as one of several ranks (mpirun), but this build of iso has no MPI: install "
      "libopenmpi-dev (tools/run setup) and build again");
}
MpiRanks::~MpiRanks() = default;
Ranks MpiRanks::ranks(const std::filesystem::path&) const { return {}; }
void MpiRanks::abort(int exitCode) const { std::exit(exitCode); }

#endif

}  // namespace iso::cli
