// A distributed conversion's ranks through MPI (`mpirun -np N iso convert ...`; Debian's OpenMPI,
// or any MPI launcher: Slurm's srun, a hostfile across nodes). The point stages are split between
// the ranks (pipeline/outofcore/outofcore.h, Ranks); this file is the engine's side.
#pragma once

#include <filesystem>
#include <optional>

#include "pipeline/outofcore/outofcore.h"

namespace iso::cli {

// How many ranks a launcher started this process among (its environment: OMPI_COMM_WORLD_SIZE,
// PMI_SIZE or PMIX_SIZE, which srun sets too); 1 when none did.
int launchedRanks();

// MPI for the life of the object (initialized, finalized at the end).
class MpiRanks {
 public:
  MpiRanks();  // UsageError when this build has no MPI
  ~MpiRanks();
  MpiRanks(const MpiRanks&) = delete;
  MpiRanks& operator=(const MpiRanks&) = delete;

  int rank() const { return rank_; }
  int count() const { return count_; }
  // The ranks of the point stages, their results in rank 0's directory `shared` (on a file system
  // every rank sees; FileError on every rank when one of them cannot see it).
  Ranks ranks(const std::filesystem::path& shared) const;
  // End every rank now (one rank failed: the others would wait for it forever).
  [[noreturn]] void abort(int exitCode) const;

 private:
  int rank_ = 0, count_ = 1;
};

}  // namespace iso::cli
