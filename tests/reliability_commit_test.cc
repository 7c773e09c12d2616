// The output-commit mechanism (core/atomic_file.h): what a writer may and may not replace,
// symbolic links, stale temporaries of killed runs, and transactions that commit several
// outputs together or not at all.
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include "ptmkit/core/atomic_file.h"
#include "ptmkit/core/error.h"
#include "reliability_util.h"
#include "test_util.h"

namespace fs = std::filesystem;

namespace ptmkit {
namespace {

using test::slurp;
using test::spit;

// A process id that no longer exists (a child that has exited and been reaped).
pid_t dead_pid() {
  const pid_t pid = ::fork();
  if (pid == 0) ::_exit(0);
  int status = 0;
  ::waitpid(pid, &status, 0);
  return pid;
}

TEST(ReliabilityCommit, ReplacesARegularFileAndLeavesNoTemporary) {
  test::ScratchDir dir;
  spit(dir / "a.txt", "old");
  write_file_atomic(dir / "a.txt", "new");
  EXPECT_EQ(slurp(dir / "a.txt"), "new");
  EXPECT_EQ(test::list_files(dir.path()), std::vector<std::string>{"a.txt"});
}

TEST(ReliabilityCommit, RefusesAFifoASocketAndAFolder) {
  test::ScratchDir dir;
  const fs::path fifo = dir / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  EXPECT_THROW(write_file_atomic(fifo, "x"), Error);
  EXPECT_TRUE(fs::is_fifo(fifo));

  const fs::path sock = dir / "sock";
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un addr{};
  addr.sun_family = AF_UNIX;
  ASSERT_LT(sock.string().size(), sizeof(addr.sun_path));
  std::snprintf(addr.sun_path, sizeof(addr.sun_path), "%s", sock.c_str());
  ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0);
  try {
    write_file_atomic(sock, "x");
    ADD_FAILURE() << "a socket was replaced";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_socket(sock));
  ::close(fd);

  fs::create_directory(dir / "folder");
  EXPECT_THROW(write_file_atomic(dir / "folder", "x"), Error);
  EXPECT_TRUE(fs::is_directory(dir / "folder"));
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityCommit, RefusesADeviceNode) {
  test::ScratchDir dir;
  // A copy of /dev/null's node (major 1, minor 3): needs root, as replacing /dev/null would.
  const fs::path node = dir / "null";
  if (::mknod(node.c_str(), S_IFCHR | 0666, makedev(1, 3)) != 0) {
    GTEST_SKIP() << "cannot create a device node here (not root, or nodev): " << node;
  }
  try {
    write_file_atomic(node, "report");
    ADD_FAILURE() << "a device node was replaced";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("not a regular file"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(fs::is_character_file(node));
}

TEST(ReliabilityCommit, WritesThroughASymbolicLink) {
  test::ScratchDir dir;
  fs::create_directory(dir / "real");
  spit(dir / "real" / "target.txt", "old");
  fs::create_symlink(dir / "real" / "target.txt", dir / "link.txt");
  write_file_atomic(dir / "link.txt", "new");
  EXPECT_TRUE(fs::is_symlink(dir / "link.txt"));
  EXPECT_EQ(slurp(dir / "real" / "target.txt"), "new");
  // A link to nothing is refused (writing would have to guess where).
  fs::create_symlink(dir / "missing.txt", dir / "dangling.txt");
  EXPECT_THROW(write_file_atomic(dir / "dangling.txt", "x"), Error);
  EXPECT_TRUE(fs::is_symlink(dir / "dangling.txt"));
  EXPECT_FALSE(fs::exists(dir / "missing.txt"));
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityCommit, RemovesStaleTemporariesOfDeadProcessesOnly) {
  test::ScratchDir dir;
  const std::string dead = ".ptmkit-tmp-" + std::to_string(dead_pid()) + "-0.ptm";
  const std::string alive = ".ptmkit-tmp-" + std::to_string(::getppid()) + "-0.png";
  spit(dir / dead, "partial");
  spit(dir / alive, "someone else's, still running");
  spit(dir / ".other.tmp", "not ours");
  write_file_atomic(dir / "out.txt", "x");
  EXPECT_FALSE(fs::exists(dir / dead));
  EXPECT_TRUE(fs::exists(dir / alive));
  EXPECT_TRUE(fs::exists(dir / ".other.tmp"));
}

// A folder of outputs being staged (a web export, a .ptm8 container) by a run that was killed:
// removed like a file, with what it holds; a live process's is kept.
TEST(ReliabilityCommit, RemovesStaleTemporaryFoldersOfDeadProcesses) {
  test::ScratchDir dir;
  const fs::path dead = dir / (".ptmkit-tmp-" + std::to_string(dead_pid()) + "-3.web");
  const fs::path alive = dir / (".ptmkit-tmp-" + std::to_string(::getppid()) + "-3.web");
  for (const fs::path& d : {dead, alive}) {
    fs::create_directories(d / "plane_0_files" / "0");
    spit(d / "info.json", "{}");
    spit(d / "plane_0_files" / "0" / "0_0.jpg", "partial");
  }
  const fs::path staged = temporary_path(dir.path(), ".web");
  EXPECT_EQ(staged.parent_path(), dir.path());
  EXPECT_EQ(staged.filename().string().rfind(std::string(kTempPrefix), 0), 0u);
  EXPECT_FALSE(fs::exists(dead));
  EXPECT_TRUE(fs::exists(alive / "info.json"));
}

TEST(ReliabilityCommit, WriteFailureOfATextOutputKeepsTheEarlierFile) {
  // A full disk for reports, light files and JSON: in a child whose file-size limit makes
  // the write fail (EFBIG, as ENOSPC on a full disk).
  test::ScratchDir dir;
  spit(dir / "report.json", "earlier");
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::signal(SIGXFSZ, SIG_IGN);
    const rlimit rl{1000, 1000};
    ::setrlimit(RLIMIT_FSIZE, &rl);
    try {
      write_file_atomic(dir / "report.json", std::string(5000, 'x'));
    } catch (const Error& e) {
      ::_exit(std::string(e.what()).find("report.json") != std::string::npos ? 3 : 4);
    }
    ::_exit(0);
  }
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 3) << "no error naming the file";
  EXPECT_EQ(slurp(dir / "report.json"), "earlier");
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityCommit, TransactionCommitsEverythingAtTheEnd) {
  test::ScratchDir dir;
  spit(dir / "a.txt", "old a");
  {
    OutputTransaction t;
    write_file_atomic(dir / "a.txt", "new a");
    write_file_atomic(dir / "b.txt", "new b");
    EXPECT_EQ(t.queued(), 2u);
    EXPECT_EQ(slurp(dir / "a.txt"), "old a");  // nothing replaced yet
    EXPECT_FALSE(fs::exists(dir / "b.txt"));
    t.commit();
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "new a");
  EXPECT_EQ(slurp(dir / "b.txt"), "new b");
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityCommit, TransactionWithoutCommitLeavesEverythingAsItWas) {
  test::ScratchDir dir;
  spit(dir / "a.txt", "old a");
  try {
    OutputTransaction t;
    ensure_directory(dir / "new" / "deeper");
    write_file_atomic(dir / "a.txt", "new a");
    write_file_atomic(dir / "new" / "deeper" / "c.txt", "c");
    throw Error("a later step failed");
  } catch (const Error&) {
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "old a");
  EXPECT_FALSE(fs::exists(dir / "new"));  // the folders it created are gone again
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityCommit, FailedCommitPutsBackWhatItHadReplaced) {
  test::ScratchDir dir;
  spit(dir / "a.txt", "old a");
  spit(dir / "b.txt", "old b");
  OutputTransaction t;
  write_file_atomic(dir / "a.txt", "new a");
  write_file_atomic(dir / "c.txt", "new c");
  write_file_atomic(dir / "b.txt", "new b");
  // Between queueing and committing, b.txt becomes a folder: its rename must fail.
  fs::remove(dir / "b.txt");
  fs::create_directory(dir / "b.txt");
  spit(dir / "b.txt" / "inside", "x");
  EXPECT_THROW(t.commit(), Error);
  EXPECT_EQ(slurp(dir / "a.txt"), "old a");  // restored
  EXPECT_FALSE(fs::exists(dir / "c.txt"));   // new, removed
  EXPECT_TRUE(fs::is_directory(dir / "b.txt"));
  EXPECT_TRUE(test::temporaries(dir.path()).empty());
}

TEST(ReliabilityCommit, NestedTransactionJoinsTheOuterOne) {
  test::ScratchDir dir;
  OutputTransaction outer;
  {
    OutputTransaction inner;
    write_file_atomic(dir / "a.txt", "a");
    inner.commit();  // joined: the outer one decides
  }
  EXPECT_FALSE(fs::exists(dir / "a.txt"));
  outer.commit();
  EXPECT_EQ(slurp(dir / "a.txt"), "a");
}

TEST(ReliabilityCommit, ImmediateCommitsInsideATransaction) {
  test::ScratchDir dir;
  OutputTransaction t;
  {
    OutputTransaction::Immediate now;
    write_file_atomic(dir / "a.txt", "a");
  }
  EXPECT_EQ(slurp(dir / "a.txt"), "a");
  t.commit();
}

}  // namespace
}  // namespace ptmkit
