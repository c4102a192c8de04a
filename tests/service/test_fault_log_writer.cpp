// imuemud's fault-log writer (daemon/service/fault_log_writer.hpp, issue 26
// N13): a disk that fills up mid-line leaves only whole JSON lines in the
// file, the lines that did not fit are counted, and the recording resumes
// when there is room again. The disk is a write(2) seam that writes part of a
// line and then answers ENOSPC, as a filesystem does at its last block.
#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "daemon/service/fault_log_writer.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_service_test_fault_log_writer {
namespace imuemu { using namespace ::imuemu; }

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using imuemu::service::FaultLogWriter;

std::atomic<bool> g_disk_full{false};
std::atomic<bool> g_cut_next{false};

// While "full": the first call writes 7 bytes (the last free block), the
// next answers ENOSPC.
ssize_t filling_disk(int fd, const void* data, std::size_t size) {
  if (!g_disk_full.load()) return ::write(fd, data, size);
  if (g_cut_next.exchange(false)) return ::write(fd, data, std::min<std::size_t>(size, 7));
  g_cut_next.store(true);
  errno = ENOSPC;
  return -1;
}

std::vector<std::string> lines_of(const fs::path& p) {
  std::ifstream in(p);
  std::vector<std::string> lines;
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

TEST(FaultLogWriter, ADiskThatFillsUpKeepsOnlyWholeLinesCountsTheRestAndResumesWhenSpaceReturns) {
  const fs::path path = fs::temp_directory_path() / ("fault_log_writer_" + std::to_string(::getpid()) + ".jsonl");
  fs::remove(path);
  {
    FaultLogWriter writer(path.string(), &filling_disk);
    writer.open();
    auto line = [](int i) { return nlohmann::json{{"event", i}, {"pad", std::string(40, 'x')}}.dump(); };
    writer.write_line(line(1));
    writer.write_line(line(2));
    ASSERT_TRUE(writer.wait_idle(2s));
    g_cut_next.store(true);
    g_disk_full.store(true);
    for (int i = 3; i <= 5; ++i) writer.write_line(line(i));
    ASSERT_TRUE(writer.wait_idle(2s));
    EXPECT_EQ(writer.counters().dropped_events, 3u);
    EXPECT_NE(writer.counters().last_error.find("No space left on device"), std::string::npos)
        << writer.counters().last_error;
    g_disk_full.store(false);  // space returns
    writer.write_line(line(6));
    ASSERT_TRUE(writer.wait_idle(2s));
    const auto c = writer.counters();
    EXPECT_EQ(c.lines_written, 3u);
    EXPECT_EQ(c.dropped_events, 3u);
    EXPECT_TRUE(c.open);
    writer.close(1s);
  }
  const std::vector<std::string> lines = lines_of(path);
  ASSERT_EQ(lines.size(), 3u);
  std::vector<int> events;
  for (const std::string& l : lines) {
    ASSERT_TRUE(nlohmann::json::accept(l)) << "a cut line: " << l;
    events.push_back(nlohmann::json::parse(l)["event"].get<int>());
  }
  EXPECT_EQ(events, (std::vector<int>{1, 2, 6}));
  fs::remove(path);
}

// A queue that is full (the log not open: a FIFO without reader) drops the
// newest lines whole and counts them; close() counts what was left.
TEST(FaultLogWriter, LinesBeyondTheQueueAndLeftAtExitAreCounted) {
  const fs::path fifo = fs::temp_directory_path() / ("fault_log_writer_" + std::to_string(::getpid()) + ".fifo");
  fs::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  FaultLogWriter writer(fifo.string(), nullptr, 4);
  const auto t0 = std::chrono::steady_clock::now();
  writer.open();  // no reader: not an error, and no wait
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 500ms);
  EXPECT_FALSE(writer.counters().open);
  for (int i = 0; i < 10; ++i) writer.write_line("{}");
  EXPECT_EQ(writer.counters().dropped_events, 6u);
  EXPECT_EQ(writer.counters().queued, 4u);
  writer.close(0ms);
  EXPECT_EQ(writer.counters().dropped_events, 10u);
  fs::remove(fifo);
}

}  // namespace
}  // namespace unity_service_test_fault_log_writer
