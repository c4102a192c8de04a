// Output paths that are not plain files (issue 26 N16). AtomicFileWriter
// (io/atomic_file.hpp) wrote a temporary file next to the path and renamed it
// over the path, whatever the path was: `imuemu generate --out /dev/stdout`
// run as root replaced the system's /dev/stdout symlink with a regular file.
// Now a symlink is written through (the file it names is replaced
// atomically, the link stays), a FIFO or character device is written
// directly as a stream, and a directory, block device or socket is refused
// before anything is written. Each case in a temporary directory, with what
// the old code did; the real /dev is never written (the tests run as root).
#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <system_error>
#include <thread>

#include "io/atomic_file.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace imuemu::io {}
namespace unity_io_test_output_paths {
namespace imuemu { using namespace ::imuemu; }
namespace imuemu::io { using namespace ::imuemu::io; }

namespace imuemu::io {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

struct Dir {
  fs::path path;
  Dir() {
    char name[] = "/tmp/imuemu_test_out.XXXXXX";
    if (::mkdtemp(name) == nullptr) throw std::runtime_error("mkdtemp failed");
    path = name;
  }
  ~Dir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
  std::string operator/(const std::string& name) const { return (path / name).string(); }
  std::vector<std::string> names() const {
    std::vector<std::string> out;
    for (const auto& e : fs::directory_iterator(path)) out.push_back(e.path().filename().string());
    std::sort(out.begin(), out.end());
    return out;
  }
};

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

bool is_symlink(const std::string& path) {
  struct stat st {};
  return ::lstat(path.c_str(), &st) == 0 && S_ISLNK(st.st_mode);
}

// Old: the link was replaced by a regular file with the new content, and
// the file it named kept its old content.
TEST(OutputPaths, ASymlinkIsWrittenThroughAndStaysALink) {
  Dir dir;
  fs::create_directory(dir.path / "data");
  const std::string target = dir / "data/imu.csv", link = dir / "latest.csv";
  write_file_atomically(target, "old\n");
  ASSERT_EQ(::symlink("data/imu.csv", link.c_str()), 0);  // relative, as `ln -s` makes them
  write_file_atomically(link, "new\n");
  EXPECT_TRUE(is_symlink(link)) << "the link was replaced";
  EXPECT_EQ(fs::read_symlink(link), "data/imu.csv");
  EXPECT_EQ(slurp(target), "new\n");
  EXPECT_EQ(dir.names(), (std::vector<std::string>{"data", "latest.csv"}));
  std::vector<std::string> in_data;
  for (const auto& e : fs::directory_iterator(dir.path / "data")) in_data.push_back(e.path().filename().string());
  EXPECT_EQ(in_data, std::vector<std::string>{"imu.csv"}) << "no temporary file left beside the target";

  // A chain of links (absolute, then relative) ends at the same file.
  const std::string chain = dir / "chain.csv";
  ASSERT_EQ(::symlink(link.c_str(), chain.c_str()), 0);
  write_file_atomically(chain, "third\n");
  EXPECT_TRUE(is_symlink(chain) && is_symlink(link));
  EXPECT_EQ(slurp(target), "third\n");
}

// Old: the dangling link was replaced by a regular file. Now the file it
// names is created (as a shell's `> link` does); the link stays.
TEST(OutputPaths, ADanglingSymlinkCreatesItsTarget) {
  Dir dir;
  const std::string link = dir / "out.csv";
  ASSERT_EQ(::symlink("new_run.csv", link.c_str()), 0);
  write_file_atomically(link, "rows\n");
  EXPECT_TRUE(is_symlink(link));
  EXPECT_EQ(slurp(dir / "new_run.csv"), "rows\n");
  // A link into a directory that does not exist: refused, naming the path.
  const std::string nowhere = dir / "nowhere.csv";
  ASSERT_EQ(::symlink("missing_dir/x.csv", nowhere.c_str()), 0);
  try {
    write_file_atomically(nowhere, "x");
    ADD_FAILURE() << "wrote into a missing directory";
  } catch (const std::system_error& e) {
    EXPECT_NE(std::string(e.what()).find("missing_dir/x.csv"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(is_symlink(nowhere));
  // A loop of links: refused (ELOOP), nothing replaced.
  const std::string a = dir / "a", b = dir / "b";
  ASSERT_EQ(::symlink("b", a.c_str()), 0);
  ASSERT_EQ(::symlink("a", b.c_str()), 0);
  EXPECT_THROW(write_file_atomically(a, "x"), std::system_error);
  EXPECT_TRUE(is_symlink(a) && is_symlink(b));
}

// Old: the FIFO was replaced by a regular file; the reader waiting on it
// never got a byte. Now the bytes go down the FIFO (a stream: not atomic).
TEST(OutputPaths, AFifoWithAReaderIsWrittenAsAStream) {
  Dir dir;
  const std::string fifo = dir / "pipe";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const std::string content = std::string(200'000, 'x') + "\n";  // more than a pipe's 64 KiB buffer
  std::string got;
  std::thread reader([&] {
    const int fd = ::open(fifo.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) return;
    const auto deadline = std::chrono::steady_clock::now() + 10s;
    char buffer[65536];
    while (got.size() < content.size() && std::chrono::steady_clock::now() < deadline) {
      const ssize_t n = ::read(fd, buffer, sizeof buffer);
      if (n > 0) got.append(buffer, static_cast<std::size_t>(n));
      else std::this_thread::sleep_for(1ms);
    }
    ::close(fd);
  });
  // The writer must not wait forever if the reader is gone: a short wait for it.
  std::this_thread::sleep_for(20ms);
  {
    AtomicFileWriter w(fifo, 4096);
    EXPECT_TRUE(w.streaming());
    EXPECT_TRUE(w.temp_path().empty());
    w.write(content);
    w.commit();
  }
  reader.join();
  EXPECT_EQ(got.size(), content.size());
  EXPECT_TRUE(got == content);
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO was replaced";
  EXPECT_EQ(dir.names(), std::vector<std::string>{"pipe"});
}

// /dev/null through a link in the temporary directory (the real /dev/null
// is never at stake: the old code replaced the link, not the device). And a
// descriptor link like /dev/stdout (/proc/self/fd/N) to a pipe: old, the
// link was replaced and the pipe saw nothing.
TEST(OutputPaths, ACharacterDeviceAndADescriptorLinkAreWrittenDirectly) {
  Dir dir;
  const std::string null_link = dir / "null";
  ASSERT_EQ(::symlink("/dev/null", null_link.c_str()), 0);
  {
    AtomicFileWriter w(null_link);
    EXPECT_TRUE(w.streaming());
    w.write("discarded\n");
    w.commit();
  }
  EXPECT_TRUE(is_symlink(null_link));
  EXPECT_EQ(dir.names(), std::vector<std::string>{"null"});

  int fds[2];
  ASSERT_EQ(::pipe2(fds, O_CLOEXEC), 0);
  const std::string stdout_like = dir / "stdout";
  const std::string proc_fd = "/proc/self/fd/" + std::to_string(fds[1]);
  ASSERT_EQ(::symlink(proc_fd.c_str(), stdout_like.c_str()), 0);
  write_file_atomically(stdout_like, "through the pipe\n");
  EXPECT_TRUE(is_symlink(stdout_like));
  ::close(fds[1]);
  char buffer[64] = {};
  const ssize_t n = ::read(fds[0], buffer, sizeof buffer);
  ::close(fds[0]);
  EXPECT_EQ(std::string(buffer, n > 0 ? static_cast<std::size_t>(n) : 0), "through the pipe\n");

  // A regular file behind a descriptor link (`imuemu generate --out /dev/stdout >> log`):
  // appended through the descriptor's file, not renamed over it.
  const std::string log = dir / "log.txt";
  const int fd = ::open(log.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0600);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::write(fd, "before\n", 7), 7);
  const std::string via = "/proc/self/fd/" + std::to_string(fd);
  write_file_atomically(via, "after\n");
  ::close(fd);
  EXPECT_EQ(slurp(log), "before\nafter\n");
}

// Old: the whole output was computed and written to a temporary file, then
// the rename failed (EISDIR) at the end. Now refused at once, saying why,
// with nothing created.
TEST(OutputPaths, ADirectoryIsRefusedBeforeAnythingIsWritten) {
  Dir dir;
  fs::create_directory(dir.path / "out");
  try {
    AtomicFileWriter w(dir / "out");
    ADD_FAILURE() << "a directory was accepted as an output file";
  } catch (const std::system_error& e) {
    EXPECT_EQ(e.code().value(), EISDIR);
    EXPECT_NE(std::string(e.what()).find("is a directory"), std::string::npos) << e.what();
  }
  const std::string link = dir / "to_dir";
  ASSERT_EQ(::symlink("out", link.c_str()), 0);
  EXPECT_THROW(AtomicFileWriter w(link), std::system_error);
  EXPECT_EQ(dir.names(), (std::vector<std::string>{"out", "to_dir"}));
  EXPECT_TRUE(fs::is_empty(dir.path / "out"));
}

// The commands a user runs: `imuemu sample-trajectory --out LINK` where LINK
// names a file in another directory, and `imuemu generate --out` on a link to
// the descriptor of a pipe (what /dev/stdout is).
TEST(OutputPaths, TheCliWritesThroughALinkAndToAPipe) {
  Dir dir;
  const std::string link = dir / "trajectory.csv";
  ASSERT_EQ(::symlink("runs/today.csv", link.c_str()), 0);
  fs::create_directory(dir.path / "runs");
  const std::string cli = IMUEMU_CLI_PATH;
  ASSERT_EQ(std::system((cli + " sample-trajectory --kind circle --duration-s 4 --out " + link + " >/dev/null 2>&1").c_str()), 0);
  EXPECT_TRUE(is_symlink(link));
  const std::string trajectory = dir / "runs/today.csv";
  EXPECT_GT(slurp(trajectory).size(), 100u);

  const std::string generate = cli + " generate --in " + trajectory + " --scene flat --rate 50 --out ";
  ASSERT_EQ(std::system((generate + (dir / "imu.csv") + " >/dev/null 2>&1").c_str()), 0);
  const std::string written = slurp(dir / "imu.csv");
  ASSERT_GT(written.size(), 100u);
  // The child's /dev/stdout is a pipe to this test: a link to /proc/self/fd/1
  // in the temporary directory stands for it (so the real /dev/stdout is
  // never at stake, even with the old code, which replaced the link).
  const std::string out_link = dir / "stdout";
  ASSERT_EQ(::symlink("/proc/self/fd/1", out_link.c_str()), 0);
  FILE* p = ::popen((generate + out_link + " 2>/dev/null").c_str(), "r");
  ASSERT_NE(p, nullptr);
  std::string piped;
  char buffer[4096];
  while (const std::size_t n = std::fread(buffer, 1, sizeof buffer, p)) piped.append(buffer, n);
  EXPECT_EQ(::pclose(p), 0);
  EXPECT_TRUE(piped == written) << piped.size() << " bytes through the pipe, " << written.size() << " in the file";
  EXPECT_TRUE(is_symlink(out_link)) << "the link was replaced by a file";
}

}  // namespace
}  // namespace imuemu::io
}  // namespace unity_io_test_output_paths
