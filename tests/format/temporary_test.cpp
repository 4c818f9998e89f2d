// Temporary files: their names, removal of the files of processes that are gone, and the
// registration the interrupt handlers use.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <fstream>
#include <vector>

#include "iso/atomic_file.h"
#include "iso/temporary_files.h"
#include "tests/support/support.h"

namespace iso {
namespace {

// The id of a process that has ended (a child that exited and was reaped).
long deadPid() {
  const pid_t child = ::fork();
  if (child == 0) ::_exit(0);
  int status = 0;
  ::waitpid(child, &status, 0);
  return long(child);
}

void touch(const std::filesystem::path& path) { std::ofstream(path) << "x"; }

TEST(TemporaryFiles, namesCarryTheWritingProcess) {
  long pid = 0;
  EXPECT_TRUE(parseTemporaryName(".out.iso.1234-7.isotmp", pid));
  EXPECT_EQ(pid, 1234);
  EXPECT_TRUE(parseTemporaryName(".a.b.c.99-0.isotmp", pid));
  EXPECT_EQ(pid, 99);
  for (const char* name : {"out.iso", ".out.iso.isotmp", "out.iso.12-3.isotmp", ".x.-3.isotmp",
                           ".x.12a-3.isotmp", ".x.0-1.isotmp", ".x.12.isotmp", ".isotmp"})
    EXPECT_FALSE(parseTemporaryName(name, pid)) << name;
}

TEST(TemporaryFiles, onlyFilesOfEndedProcessesAreRemoved) {
  test::TempDir dir;
  const long gone = deadPid();
  const std::string mine = std::to_string(::getpid());
  touch(dir / (".a.iso." + std::to_string(gone) + "-0.isotmp"));
  std::filesystem::create_directory(dir / (".spill." + std::to_string(gone) + "-1.isotmp"));
  touch(dir / (".spill." + std::to_string(gone) + "-1.isotmp") / "points");
  touch(dir / (".b.iso." + mine + "-0.isotmp"));  // this process is alive
  touch(dir / "keep.iso");
  touch(dir / ("keep." + std::to_string(gone) + "-0.isotmp"));  // no leading dot: not ours
  EXPECT_EQ(removeStaleTemporaries(dir.path()), 2u);
  EXPECT_FALSE(std::filesystem::exists(dir / (".a.iso." + std::to_string(gone) + "-0.isotmp")));
  EXPECT_FALSE(std::filesystem::exists(dir / (".spill." + std::to_string(gone) + "-1.isotmp")));
  EXPECT_TRUE(std::filesystem::exists(dir / (".b.iso." + mine + "-0.isotmp")));
  EXPECT_TRUE(std::filesystem::exists(dir / "keep.iso"));
  EXPECT_TRUE(std::filesystem::exists(dir / ("keep." + std::to_string(gone) + "-0.isotmp")));
  EXPECT_EQ(removeStaleTemporaries(dir / "missing"), 0u);
}

TEST(TemporaryFiles, anInterruptRemovesTheFilesBeingWritten) {
  test::TempDir dir;
  const pid_t child = ::fork();
  if (child == 0) {  // write a file, then get Ctrl-C before committing it
    installInterruptCleanup();
    AtomicFile file(dir / "out.iso");
    file.write(std::string_view("partial"));
    file.flush();
    ::raise(SIGINT);
    ::_exit(3);  // not reached: the handler ends the process with SIGINT
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(WTERMSIG(status), SIGINT);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path())) << "a temporary file was left behind";
}

TEST(TemporaryFiles, anInterruptRemovesNestedDirectoriesDeepestFirst) {
  test::TempDir dir;
  const pid_t child = ::fork();
  if (child == 0) {  // directories registered outermost first, as they are made, and a file
    installInterruptCleanup();
    std::vector<TemporaryRegistration> registrations;
    for (const char* name : {"a", "a/b", "a/b/c"}) {
      registrations.emplace_back(dir / name);
      std::filesystem::create_directory(dir / name);
    }
    registrations.emplace_back(dir / "a/b/c/points");
    touch(dir / "a/b/c/points");
    ::raise(SIGTERM);
    ::_exit(3);
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(WTERMSIG(status), SIGTERM);
  EXPECT_TRUE(std::filesystem::is_empty(dir.path())) << "a directory was left behind";
}

TEST(TemporaryFiles, aSignalIgnoredAtStartStaysIgnored) {
  test::TempDir dir;
  const pid_t child = ::fork();
  if (child == 0) {  // as under nohup: the terminal closing must not end the process
    ::signal(SIGHUP, SIG_IGN);
    installInterruptCleanup();
    AtomicFile file(dir / "out.iso");
    file.write(std::string_view("complete"));
    ::raise(SIGHUP);
    file.commit();
    ::_exit(7);
  }
  int status = 0;
  ::waitpid(child, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 7);
  EXPECT_TRUE(std::filesystem::exists(dir / "out.iso"));
}

}  // namespace
}  // namespace iso
