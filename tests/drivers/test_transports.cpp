// Transports (GitHub issue "Drivers and wire protocols", transport part).
//
// What runs where: the pty transport runs end to end on any Linux host. The
// queued writer's link-loss, reconnect and ENOBUFS back-off logic is driven
// here through fake devices. UART I/O, SocketCAN I/O and GPIO edges need a
// real UART, a CAN-capable kernel and a gpiochip: this file checks their
// error paths on this host (no CAN, no GPIO, libserialport cannot open ptys)
// and the wire conversion against linux/can.h; their I/O belongs to the
// user-mode Linux / QEMU fixtures.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <linux/can.h>
#include <pthread.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "drivers/byte_stream_reader.hpp"
#include "drivers/gpio_sync.hpp"
#include "drivers/pty_transport.hpp"
#include "drivers/queued_writer.hpp"
#include "drivers/serial_transport.hpp"
#include "drivers/socketcan.hpp"
#include "drivers/socketcan_wire.hpp"
#include "drivers/transport.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_drivers_test_transports {
namespace imuemu { using namespace ::imuemu; }

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using imuemu::drivers::ByteStreamReader;
using imuemu::drivers::TransportCounters;
using imuemu::drivers::TransportError;

namespace {

// ---------------------------------------------------------------------------
// Test frames: 0x7E, u32 sequence (little endian), u8 payload length L (1..60,
// varying with the sequence), L payload bytes, u8 XOR of all previous bytes.
// A stream of them can be checked strictly: every frame whole, in order.

std::vector<std::byte> make_frame(std::uint32_t sequence) {
  const std::size_t length = 1 + (sequence * 7u) % 60u;
  std::vector<std::byte> f;
  f.push_back(std::byte{0x7E});
  for (int i = 0; i < 4; ++i) f.push_back(static_cast<std::byte>((sequence >> (8 * i)) & 0xFFu));
  f.push_back(static_cast<std::byte>(length));
  for (std::size_t i = 0; i < length; ++i) f.push_back(static_cast<std::byte>((sequence * 31u + i) & 0xFFu));
  std::byte x{0};
  for (auto b : f) x ^= b;
  f.push_back(x);
  return f;
}

std::vector<std::byte> make_fixed_frame(std::uint32_t sequence, std::size_t total_size) {
  // Same layout with the payload length chosen so the frame has total_size bytes.
  const std::size_t length = total_size - 7;
  std::vector<std::byte> f;
  f.push_back(std::byte{0x7E});
  for (int i = 0; i < 4; ++i) f.push_back(static_cast<std::byte>((sequence >> (8 * i)) & 0xFFu));
  f.push_back(static_cast<std::byte>(length));
  for (std::size_t i = 0; i < length; ++i) f.push_back(static_cast<std::byte>((sequence * 31u + i) & 0xFFu));
  std::byte x{0};
  for (auto b : f) x ^= b;
  f.push_back(x);
  return f;
}

struct ParsedStream {
  std::vector<std::uint32_t> sequences;
  std::string error;  // empty: the bytes are whole frames back to back
};

ParsedStream parse_frames(const std::vector<std::uint8_t>& bytes) {
  ParsedStream out;
  std::size_t at = 0;
  while (at < bytes.size()) {
    if (bytes.size() - at < 7) {
      out.error = "truncated frame at byte " + std::to_string(at);
      return out;
    }
    if (bytes[at] != 0x7E) {
      out.error = "no frame start at byte " + std::to_string(at);
      return out;
    }
    const std::size_t length = bytes[at + 5];
    if (bytes.size() - at < 7 + length) {
      out.error = "truncated frame at byte " + std::to_string(at);
      return out;
    }
    std::uint8_t x = 0;
    for (std::size_t i = 0; i < 6 + length; ++i) x ^= bytes[at + i];
    if (x != bytes[at + 6 + length]) {
      out.error = "checksum mismatch at byte " + std::to_string(at);
      return out;
    }
    std::uint32_t sequence = 0;
    for (int i = 0; i < 4; ++i) sequence |= static_cast<std::uint32_t>(bytes[at + 1 + i]) << (8 * i);
    out.sequences.push_back(sequence);
    at += 7 + length;
  }
  return out;
}

bool wait_until(const std::function<bool()>& condition, std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!condition()) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    std::this_thread::sleep_for(1ms);
  }
  return true;
}

// Reads until `want` bytes arrived or nothing came for `quiet`.
std::vector<std::uint8_t> read_stream(ByteStreamReader& reader, std::size_t want, std::chrono::milliseconds quiet) {
  std::vector<std::uint8_t> got;
  std::array<std::uint8_t, 8192> buffer{};
  while (got.size() < want) {
    const auto r = reader.read_some(buffer, quiet);
    if (r.bytes == 0) break;
    got.insert(got.end(), buffer.begin(), buffer.begin() + static_cast<std::ptrdiff_t>(r.bytes));
  }
  return got;
}

std::uint64_t accounted(const TransportCounters& c) {
  return c.frames_sent + c.dropped_queue_full + c.dropped_link_down + c.write_errors + c.queued;
}

std::string error_of(const std::function<void()>& action) {
  try {
    action();
  } catch (const TransportError& e) {
    return e.what();
  }
  return "(no TransportError thrown)";
}

class TempDir {
 public:
  TempDir() {
    char name[] = "/tmp/imuemu-transports-XXXXXX";
    const char* made = ::mkdtemp(name);
    if (made == nullptr) throw std::runtime_error("mkdtemp failed");
    path_ = made;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path_, ec);
  }
  const fs::path& path() const { return path_; }

 private:
  fs::path path_;
};

// Collects a transport's log lines (they come from its writer thread).
struct LogCapture {
  std::mutex mutex;
  std::vector<std::string> lines;
  std::function<void(std::string_view)> sink() {
    return [this](std::string_view line) {
      std::lock_guard lock(mutex);
      lines.emplace_back(line);
    };
  }
  bool contains(const std::string& text) {
    std::lock_guard lock(mutex);
    return std::any_of(lines.begin(), lines.end(), [&](const std::string& l) { return l.find(text) != std::string::npos; });
  }
};

// ---------------------------------------------------------------------------
// pty transport, end to end on this host

TEST(PtyTransport, FramesArriveWholeAndInOrderThroughTheSymlink) {
  TempDir dir;
  const fs::path link = dir.path() / "run" / "imuemu" / "ttyIMU0";  // parents do not exist yet
  LogCapture log;
  std::vector<std::uint8_t> expected;
  std::string slave;
  {
    imuemu::drivers::PtyTransportOptions options;
    options.link_path = link.string();
    options.queue_bytes = 1 << 20;  // large enough that nothing is dropped while the reader keeps up
    options.log = log.sink();
    imuemu::drivers::PtyTransport pty(options);
    slave = pty.slave_path();
    ASSERT_EQ(slave.rfind("/dev/pts/", 0), 0u) << slave;
    ASSERT_TRUE(fs::is_symlink(link));
    EXPECT_EQ(fs::read_symlink(link).string(), slave);
    EXPECT_TRUE(fs::exists(link.string() + ".lock"));
    EXPECT_FALSE(pty.link_up()) << "nobody has the slave open yet";

    ByteStreamReader reader(link.string());  // through the symlink, as a driver under test would
    EXPECT_EQ(reader.kind(), ByteStreamReader::Kind::pty);
    ASSERT_TRUE(wait_until([&] { return pty.link_up(); }, 2s));

    constexpr std::uint32_t kFrames = 2000;  // ~70 KB: several times the kernel's pty buffer
    std::vector<std::uint8_t> received;
    std::thread consumer([&] { received = read_stream(reader, SIZE_MAX, 500ms); });
    for (std::uint32_t s = 0; s < kFrames; ++s) {
      const auto frame = make_frame(s);
      for (auto b : frame) expected.push_back(static_cast<std::uint8_t>(b));
      ASSERT_TRUE(pty.write_frame(frame)) << "frame " << s;
    }
    EXPECT_TRUE(pty.flush(5s));
    consumer.join();

    EXPECT_EQ(received.size(), expected.size());
    EXPECT_TRUE(received == expected) << "the reader must see exactly the bytes written, in order";
    const ParsedStream parsed = parse_frames(received);
    EXPECT_EQ(parsed.error, "");
    EXPECT_EQ(parsed.sequences.size(), kFrames);
    const TransportCounters c = pty.counters();
    EXPECT_EQ(c.frames, kFrames);
    EXPECT_EQ(c.frames_sent, kFrames);
    EXPECT_EQ(c.bytes, expected.size());
    EXPECT_EQ(c.bytes_sent, expected.size());
    EXPECT_EQ(c.dropped_queue_full + c.dropped_link_down + c.write_errors + c.queued, 0u);
    EXPECT_EQ(c.link_restored, 1u);
    EXPECT_TRUE(log.contains("reader connected"));
    std::printf("pty end to end: %u frames, %zu bytes through %s\n", kFrames, received.size(), slave.c_str());
  }
  // Closed: the symlink and its lock file are gone.
  EXPECT_FALSE(fs::exists(fs::symlink_status(link)));
  EXPECT_FALSE(fs::exists(link.string() + ".lock"));
}

TEST(PtyTransport, ReaderSeesEndOfStreamWhenTheTransportCloses) {
  TempDir dir;
  imuemu::drivers::PtyTransportOptions options;
  options.link_path = (dir.path() / "tty").string();
  options.log = [](std::string_view) {};
  auto pty = std::make_unique<imuemu::drivers::PtyTransport>(options);
  ByteStreamReader reader(options.link_path);
  ASSERT_TRUE(wait_until([&] { return pty->link_up(); }, 2s));
  pty.reset();
  std::array<std::uint8_t, 64> buffer{};
  const auto r = reader.read_some(buffer, 1000ms);
  EXPECT_TRUE(r.end_of_stream);
  EXPECT_EQ(r.bytes, 0u);
}

// Closing the master hangs the slave up, and Linux then discards what the
// reader has not read: an orderly stop must wait (bounded) until a connected
// reader has everything, or the last frames of every run are lost. The reader
// here starts reading only after the transport has been told to close.
TEST(PtyTransport, FramesWrittenBeforeCloseReachAReaderThatReadsLate) {
  TempDir dir;
  imuemu::drivers::PtyTransportOptions options;
  options.link_path = (dir.path() / "tty").string();
  options.log = [](std::string_view) {};
  auto pty = std::make_unique<imuemu::drivers::PtyTransport>(options);
  ByteStreamReader reader(options.link_path);
  ASSERT_TRUE(wait_until([&] { return pty->link_up(); }, 2s));
  constexpr std::uint32_t kFrames = 40;  // ~1.4 KB: fits the kernel's buffer, so nothing blocks
  std::size_t expected_bytes = 0;
  for (std::uint32_t s = 0; s < kFrames; ++s) {
    const auto frame = make_frame(s);
    expected_bytes += frame.size();
    ASSERT_TRUE(pty->write_frame(frame));
  }
  ASSERT_TRUE(pty->flush(2s));
  std::vector<std::uint8_t> received;
  std::thread closer([&] { pty.reset(); });
  std::this_thread::sleep_for(100ms);  // the transport is closing; the reader has read nothing yet
  received = read_stream(reader, SIZE_MAX, 1000ms);
  closer.join();
  EXPECT_EQ(received.size(), expected_bytes);
  EXPECT_EQ(parse_frames(received).sequences.size(), kFrames);
}

TEST(PtyTransport, WithoutAReaderFramesAreDroppedAndCountedAndNothingGoesStale) {
  TempDir dir;
  imuemu::drivers::PtyTransportOptions options;
  options.link_path = (dir.path() / "ttyIMU0").string();
  options.log = [](std::string_view) {};
  imuemu::drivers::PtyTransport pty(options);

  constexpr std::uint32_t kFrames = 500;
  std::chrono::nanoseconds longest{0};
  for (std::uint32_t s = 0; s < kFrames; ++s) {
    const auto frame = make_frame(s);
    const auto start = std::chrono::steady_clock::now();
    EXPECT_FALSE(pty.write_frame(frame));
    longest = std::max(longest, std::chrono::steady_clock::now() - start);
  }
  TransportCounters c = pty.counters();
  EXPECT_EQ(c.frames, kFrames);
  EXPECT_EQ(c.dropped_link_down, kFrames);
  EXPECT_EQ(c.frames_sent, 0u);
  EXPECT_EQ(accounted(c), c.frames);

  // A reader arriving now gets nothing from before it came, then new frames.
  ByteStreamReader reader(options.link_path);
  ASSERT_TRUE(wait_until([&] { return pty.link_up(); }, 2s));
  std::array<std::uint8_t, 4096> buffer{};
  EXPECT_EQ(reader.read_some(buffer, 200ms).bytes, 0u) << "dropped frames must not reach a later reader";
  ASSERT_TRUE(pty.write_frame(make_frame(kFrames)));
  const auto got = read_stream(reader, make_frame(kFrames).size(), 1000ms);
  const ParsedStream parsed = parse_frames(got);
  EXPECT_EQ(parsed.error, "");
  EXPECT_EQ(parsed.sequences, std::vector<std::uint32_t>{kFrames});
  std::printf("no reader: %u frames dropped and counted, longest write_frame %.1f us\n", kFrames,
              static_cast<double>(longest.count()) / 1e3);
}

// The emission budget with a reader that opened the pty and stopped reading:
// the kernel's pty buffer fills, then the queue, then frames are refused. No
// write_frame call may take longer than 1 ms (the period of a 1 kHz IMU),
// and the reader, once it resumes, must see whole frames: exactly those
// write_frame accepted, in order.
TEST(PtyTransport, StalledReaderNeverBlocksTheCallerAndOverflowIsCountedWhole) {
  TempDir dir;
  imuemu::drivers::PtyTransportOptions options;
  options.link_path = (dir.path() / "ttyIMU0").string();
  options.log = [](std::string_view) {};
  imuemu::drivers::PtyTransport pty(options);  // default queue: 32 KiB
  ByteStreamReader reader(options.link_path);
  ASSERT_TRUE(wait_until([&] { return pty.link_up(); }, 2s));

  constexpr std::uint32_t kCalls = 10'000;
  constexpr auto kPeriod = 100us;  // a 10 kHz schedule: 1 s of calls, 640 KB offered
  constexpr std::size_t kFrameBytes = 64;
  std::vector<std::vector<std::byte>> frames;
  frames.reserve(kCalls);
  for (std::uint32_t s = 0; s < kCalls; ++s) frames.push_back(make_fixed_frame(s, kFrameBytes));
  std::vector<bool> accepted(kCalls, false);
  std::vector<std::int64_t> call_ns(kCalls, 0);
  // Context switches of the calling thread during each call: a call that
  // blocks (sleeps in the kernel) makes a voluntary switch; a call the
  // scheduler interrupts for another job makes an involuntary one.
  std::vector<bool> preempted(kCalls, false);
  long voluntary_switches_in_calls = 0;

  // The measuring thread runs like the emission thread would: SCHED_FIFO
  // when the system allows it (then other jobs cannot preempt it), on an
  // absolute-time schedule.
  bool realtime = false;
  std::thread emitter([&] {
    sched_param param{};
    param.sched_priority = 50;
    realtime = ::pthread_setschedparam(::pthread_self(), SCHED_FIFO, &param) == 0;
    timespec next{};
    ::clock_gettime(CLOCK_MONOTONIC, &next);
    rusage before{}, after{};
    for (std::uint32_t s = 0; s < kCalls; ++s) {
      next.tv_nsec += std::chrono::nanoseconds(kPeriod).count();
      if (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
      ::getrusage(RUSAGE_THREAD, &before);
      const auto start = std::chrono::steady_clock::now();
      accepted[s] = pty.write_frame(frames[s]);
      call_ns[s] = (std::chrono::steady_clock::now() - start).count();
      ::getrusage(RUSAGE_THREAD, &after);
      voluntary_switches_in_calls += after.ru_nvcsw - before.ru_nvcsw;
      preempted[s] = after.ru_nivcsw != before.ru_nivcsw;
    }
  });
  emitter.join();

  std::vector<std::int64_t> sorted = call_ns;
  std::sort(sorted.begin(), sorted.end());
  const std::int64_t max_ns = sorted.back();
  const std::int64_t p99_ns = sorted[sorted.size() * 99 / 100];
  const std::int64_t median_ns = sorted[sorted.size() / 2];
  std::int64_t max_unpreempted_ns = 0;
  std::size_t preempted_calls = 0;
  for (std::uint32_t s = 0; s < kCalls; ++s) {
    if (preempted[s]) {
      ++preempted_calls;
    } else {
      max_unpreempted_ns = std::max(max_unpreempted_ns, call_ns[s]);
    }
  }
  const TransportCounters stalled = pty.counters();
  std::printf("stalled reader (%s): %u write_frame calls, max %.1f us (%.1f us not counting %zu calls preempted by "
              "other jobs), p99 %.2f us, median %.2f us; voluntary context switches inside calls: %ld; "
              "accepted %llu (sent %llu + queued %llu), dropped_queue_full %llu\n",
              realtime ? "SCHED_FIFO" : "SCHED_OTHER: no permission for SCHED_FIFO", kCalls,
              static_cast<double>(max_ns) / 1e3, static_cast<double>(max_unpreempted_ns) / 1e3, preempted_calls,
              static_cast<double>(p99_ns) / 1e3, static_cast<double>(median_ns) / 1e3, voluntary_switches_in_calls,
              static_cast<unsigned long long>(stalled.frames_sent + stalled.queued),
              static_cast<unsigned long long>(stalled.frames_sent), static_cast<unsigned long long>(stalled.queued),
              static_cast<unsigned long long>(stalled.dropped_queue_full));
  ::testing::Test::RecordProperty("max_write_frame_ns", std::to_string(max_ns));
  ::testing::Test::RecordProperty("scheduling", realtime ? "SCHED_FIFO" : "SCHED_OTHER");
  // "Never blocks" is asserted as what it is: no call slept in the kernel, and
  // 99 % of calls end well inside the 1 ms budget. The single slowest call is
  // printed, not asserted: in a VM, time the hypervisor takes from a vCPU lands
  // in whatever call is running, even under SCHED_FIFO (this test, with a bound
  // on the maximum, failed once on a loaded 2-core CI host).
  EXPECT_LT(p99_ns, 1'000'000) << "1 % of write_frame calls took longer than the 1 ms budget";
  EXPECT_EQ(voluntary_switches_in_calls, 0) << "write_frame slept in the kernel: it blocked the emission thread";

  // Overflow: 640 KB offered against ~18 KB of pty buffer + 32 KiB of queue.
  EXPECT_GT(stalled.dropped_queue_full, 0u);
  EXPECT_EQ(stalled.dropped_link_down + stalled.write_errors, 0u);
  EXPECT_EQ(accounted(stalled), kCalls);
  const auto accepted_count = static_cast<std::uint64_t>(std::count(accepted.begin(), accepted.end(), true));
  EXPECT_EQ(accepted_count, stalled.frames_sent + stalled.queued);
  EXPECT_EQ(kCalls - accepted_count, stalled.dropped_queue_full);

  // The reader resumes: it must get exactly the accepted frames, whole, in order.
  std::vector<std::uint8_t> received;
  std::thread consumer([&] { received = read_stream(reader, accepted_count * kFrameBytes, 1000ms); });
  EXPECT_TRUE(pty.flush(5s));
  consumer.join();
  const ParsedStream parsed = parse_frames(received);
  EXPECT_EQ(parsed.error, "") << "a frame was cut";
  std::vector<std::uint32_t> want;
  for (std::uint32_t s = 0; s < kCalls; ++s) {
    if (accepted[s]) want.push_back(s);
  }
  EXPECT_EQ(parsed.sequences, want);
  const TransportCounters done = pty.counters();
  EXPECT_EQ(done.frames_sent, accepted_count);
  EXPECT_EQ(done.queued, 0u);
}

TEST(PtyTransport, AReaderThatLeftLeavesNoStaleBytesForTheNext) {
  TempDir dir;
  imuemu::drivers::PtyTransportOptions options;
  options.link_path = (dir.path() / "ttyIMU0").string();
  LogCapture log;
  options.log = log.sink();
  imuemu::drivers::PtyTransport pty(options);
  {
    ByteStreamReader first(options.link_path);
    ASSERT_TRUE(wait_until([&] { return pty.link_up(); }, 2s));
    for (std::uint32_t s = 0; s < 100; ++s) ASSERT_TRUE(pty.write_frame(make_frame(s)));
    ASSERT_TRUE(pty.flush(2s));  // in the kernel's buffer, unread
  }  // the first reader leaves without reading
  ASSERT_TRUE(wait_until([&] { return !pty.link_up(); }, 2s));
  EXPECT_TRUE(wait_until([&] { return log.contains("reader gone"); }, 2s));

  ByteStreamReader second(options.link_path);
  ASSERT_TRUE(wait_until([&] { return pty.link_up(); }, 2s));
  std::size_t bytes = 0;
  for (std::uint32_t s = 100; s < 110; ++s) {
    bytes += make_frame(s).size();
    ASSERT_TRUE(pty.write_frame(make_frame(s)));
  }
  const auto got = read_stream(second, bytes, 1000ms);
  const ParsedStream parsed = parse_frames(got);
  EXPECT_EQ(parsed.error, "");
  std::vector<std::uint32_t> want;
  for (std::uint32_t s = 100; s < 110; ++s) want.push_back(s);
  EXPECT_EQ(parsed.sequences, want) << "the second reader must start with fresh frames";
  const TransportCounters c = pty.counters();
  EXPECT_EQ(c.link_down_events, 1u);
  EXPECT_EQ(c.link_restored, 2u);
}

TEST(PtyTransport, ReplacesAStaleSymlinkButNeverALiveOneOrAFile) {
  TempDir dir;
  const fs::path link = dir.path() / "ttyIMU0";
  // Left behind by a crashed run: a dangling symlink and an unlocked lock file.
  fs::create_symlink("/dev/pts/does-not-exist", link);
  std::ofstream(link.string() + ".lock") << "";
  imuemu::drivers::PtyTransportOptions options;
  options.link_path = link.string();
  options.log = [](std::string_view) {};
  {
    imuemu::drivers::PtyTransport pty(options);
    EXPECT_EQ(fs::read_symlink(link).string(), pty.slave_path());

    // A second instance on the same path while the first lives: refused.
    const std::string live = error_of([&] { imuemu::drivers::PtyTransport second(options); });
    EXPECT_NE(live.find(link.string()), std::string::npos) << live;
    EXPECT_NE(live.find("in use by another running imuemu"), std::string::npos) << live;
    EXPECT_EQ(fs::read_symlink(link).string(), pty.slave_path()) << "the live link must be untouched";
  }
  EXPECT_FALSE(fs::exists(fs::symlink_status(link)));

  // A regular file at the link path is never replaced.
  std::ofstream(link) << "precious";
  const std::string file = error_of([&] { imuemu::drivers::PtyTransport pty(options); });
  EXPECT_NE(file.find(link.string()), std::string::npos) << file;
  EXPECT_NE(file.find("not a symbolic link"), std::string::npos) << file;
  std::ifstream in(link);
  std::string content;
  in >> content;
  EXPECT_EQ(content, "precious");

  // A directory that cannot be created.
  options.link_path = (link / "sub" / "tty").string();  // `link` is a regular file
  const std::string parent = error_of([&] { imuemu::drivers::PtyTransport pty(options); });
  EXPECT_NE(parent.find(options.link_path), std::string::npos) << parent;
  EXPECT_NE(parent.find("cannot create its directory"), std::string::npos) << parent;
}

TEST(PtyTransport, CommandsTheReaderSendsAreDiscardedNotBlocking) {
  TempDir dir;
  imuemu::drivers::PtyTransportOptions options;
  options.link_path = (dir.path() / "ttyIMU0").string();
  options.log = [](std::string_view) {};
  imuemu::drivers::PtyTransport pty(options);
  const int fd = ::open(options.link_path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK);
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(wait_until([&] { return pty.link_up(); }, 2s));
  // 200 KB of "commands": far more than the pty buffers hold, so the writes
  // only all complete if the transport keeps draining them.
  std::vector<char> command(1000, 'c');
  std::size_t written = 0;
  const auto deadline = std::chrono::steady_clock::now() + 5s;
  while (written < 200'000 && std::chrono::steady_clock::now() < deadline) {
    const ssize_t n = ::write(fd, command.data(), std::min(command.size(), 200'000 - written));
    if (n > 0) written += static_cast<std::size_t>(n);
    else std::this_thread::sleep_for(1ms);
  }
  ::close(fd);
  EXPECT_EQ(written, 200'000u);
  EXPECT_TRUE(wait_until([&] { return pty.counters().input_bytes_discarded == 200'000u; }, 2s))
      << pty.counters().input_bytes_discarded;
}

TEST(PtyTransport, SlaveModeLetsOtherUsersOpenIt) {
  imuemu::drivers::PtyTransportOptions options;
  options.log = [](std::string_view) {};
  {
    imuemu::drivers::PtyTransport pty(options);
    EXPECT_EQ(fs::status(pty.slave_path()).permissions() & fs::perms::others_read, fs::perms::none)
        << "openpty's default keeps other users out";
  }
  options.slave_mode = 0666;
  imuemu::drivers::PtyTransport pty(options);
  EXPECT_EQ(fs::status(pty.slave_path()).permissions() & fs::perms::mask, static_cast<fs::perms>(0666));
  EXPECT_EQ(pty.describe(), "pty " + pty.slave_path());
}

TEST(ByteStreamReader, MissingPathIsAClearError) {
  const std::string e = error_of([] { ByteStreamReader r("/dev/imuemu-no-such-tty"); });
  EXPECT_NE(e.find("/dev/imuemu-no-such-tty"), std::string::npos) << e;
  EXPECT_NE(e.find("not found"), std::string::npos) << e;
}

// ---------------------------------------------------------------------------
// The queued writer's link handling, through fake devices (the pty cannot
// be unplugged, and this host has no CAN to fill).

// Records what it is given; fails on command. Called from the writer thread.
class FakeDevice final : public imuemu::drivers::WriterDevice {
 public:
  using Outcome = imuemu::drivers::DeviceWrite::Outcome;
  struct Shared {
    std::mutex mutex;
    std::vector<std::uint8_t> bytes;                        // accepted bytes
    std::vector<std::chrono::steady_clock::time_point> restore_attempts, write_attempts;
    int lose_link_after_bytes = -1;                        // accept this many more bytes, then link_lost
    int restore_failures_left = 0;
    int retry_later_left = 0;
    int reject_next = 0;
    bool closed = false;
  };
  FakeDevice(std::shared_ptr<Shared> shared, bool datagrams) : shared_(std::move(shared)), datagrams_(datagrams) {}
  bool datagrams() const override { return datagrams_; }
  int poll_fd() const override { return -1; }
  imuemu::drivers::DeviceWrite write(std::span<const std::byte> bytes) override {
    std::lock_guard lock(shared_->mutex);
    shared_->write_attempts.push_back(std::chrono::steady_clock::now());
    if (shared_->retry_later_left > 0) {
      --shared_->retry_later_left;
      return {Outcome::retry_later, 0, {}};
    }
    if (shared_->reject_next > 0) {
      --shared_->reject_next;
      return {Outcome::frame_rejected, 0, "EINVAL (fake)"};
    }
    std::size_t take = bytes.size();
    if (shared_->lose_link_after_bytes >= 0) {
      take = std::min<std::size_t>(take, static_cast<std::size_t>(shared_->lose_link_after_bytes));
      shared_->lose_link_after_bytes -= static_cast<int>(take);
      if (take == 0) {
        shared_->lose_link_after_bytes = -1;
        return {Outcome::link_lost, 0, "EIO (fake unplug)"};
      }
    }
    for (std::size_t i = 0; i < take; ++i) shared_->bytes.push_back(static_cast<std::uint8_t>(bytes[i]));
    return {Outcome::written, take, {}};
  }
  std::optional<std::string> service(short, std::uint64_t*) override { return std::nullopt; }
  void on_link_lost() override {
    std::lock_guard lock(shared_->mutex);
    shared_->closed = true;
  }
  bool try_restore(std::string& why) override {
    std::lock_guard lock(shared_->mutex);
    shared_->restore_attempts.push_back(std::chrono::steady_clock::now());
    if (shared_->restore_failures_left > 0) {
      --shared_->restore_failures_left;
      why = "ENOENT (fake: still unplugged)";
      return false;
    }
    shared_->closed = false;
    return true;
  }
  bool initially_up() const override { return true; }

 private:
  std::shared_ptr<Shared> shared_;
  bool datagrams_;
};

TEST(QueuedWriter, DeviceLossDropsAndCountsThenReopensWithExponentialBackoff) {
  auto shared = std::make_shared<FakeDevice::Shared>();
  LogCapture log;
  imuemu::drivers::QueuedWriterOptions options;
  options.name = "fake uart";
  options.restore_initial = 10ms;
  options.restore_max = 40ms;
  options.link_lost_verb = "device lost";
  options.link_restored_verb = "device reopened";
  options.log = log.sink();
  imuemu::drivers::QueuedWriter writer(std::make_unique<FakeDevice>(shared, false), options);

  // Ten whole frames go through.
  for (std::uint32_t s = 0; s < 10; ++s) ASSERT_TRUE(writer.offer(make_frame(s)));
  ASSERT_TRUE(writer.flush(2s));
  // Unplug in the middle of frame 10: 5 of its bytes get out.
  {
    std::lock_guard lock(shared->mutex);
    shared->lose_link_after_bytes = 5;
    shared->restore_failures_left = 4;  // stays unplugged for four attempts
  }
  const auto lost_at = std::chrono::steady_clock::now();
  ASSERT_TRUE(writer.offer(make_frame(10)));
  ASSERT_TRUE(wait_until([&] { return !writer.link_up(); }, 2s));
  // The schedule continues meanwhile: every offer while the link is down is
  // refused at once and counted. The device comes back after at least 150 ms
  // of back-off; on a loaded host these 50 offers can outlast that, and the
  // ones made after the reopen are taken and sent in order, so the test keeps
  // which were taken rather than assuming the host's speed.
  std::uint32_t refused = 0;
  std::vector<std::uint32_t> taken_while_probing;
  for (std::uint32_t s = 11; s < 61; ++s) {
    if (writer.offer(make_frame(s))) taken_while_probing.push_back(s);
    else ++refused;
    std::this_thread::sleep_for(1ms);
  }
  ASSERT_TRUE(wait_until([&] { return writer.link_up(); }, 3s));
  for (std::uint32_t s = 1000; s < 1005; ++s) ASSERT_TRUE(writer.offer(make_frame(s)));
  ASSERT_TRUE(writer.flush(2s));

  const TransportCounters c = writer.counters();
  EXPECT_EQ(c.link_down_events, 1u);
  EXPECT_EQ(c.link_restored, 1u);
  EXPECT_EQ(c.frames_sent, 15u + taken_while_probing.size());
  EXPECT_EQ(c.dropped_link_down, 1u + refused) << "the cut frame 10 plus every refused one";
  EXPECT_EQ(accounted(c), c.frames);
  EXPECT_TRUE(log.contains("device lost (EIO (fake unplug))"));
  EXPECT_TRUE(log.contains("still down: ENOENT (fake: still unplugged)"));
  EXPECT_TRUE(log.contains("device reopened"));

  std::lock_guard lock(shared->mutex);
  // The byte stream: frames 0-9, 5 bytes of the cut frame 10, any frame taken
  // after the reopen, then 1000-1004.
  std::vector<std::uint8_t> want;
  for (std::uint32_t s = 0; s < 10; ++s)
    for (auto b : make_frame(s)) want.push_back(static_cast<std::uint8_t>(b));
  for (int i = 0; i < 5; ++i) want.push_back(static_cast<std::uint8_t>(make_frame(10)[static_cast<std::size_t>(i)]));
  for (std::uint32_t s : taken_while_probing)
    for (auto b : make_frame(s)) want.push_back(static_cast<std::uint8_t>(b));
  for (std::uint32_t s = 1000; s < 1005; ++s)
    for (auto b : make_frame(s)) want.push_back(static_cast<std::uint8_t>(b));
  EXPECT_EQ(shared->bytes, want);

  // Back-off: attempts 10 ms after the loss, then 20, 40, 40 (capped), 40 ms apart.
  ASSERT_EQ(shared->restore_attempts.size(), 5u);
  const std::array<std::chrono::milliseconds, 5> minimum_gap = {10ms, 20ms, 40ms, 40ms, 40ms};
  auto previous = lost_at;
  std::string gaps;
  for (std::size_t i = 0; i < 5; ++i) {
    const auto gap = shared->restore_attempts[i] - previous;
    gaps += std::to_string(std::chrono::duration<double, std::milli>(gap).count()) + " ";
    EXPECT_GE(gap, minimum_gap[i]) << "attempt " << i;
    EXPECT_LT(gap, minimum_gap[i] + 100ms) << "attempt " << i;
    previous = shared->restore_attempts[i];
  }
  std::printf("reconnect attempts, ms apart: %s\n", gaps.c_str());
}

TEST(QueuedWriter, KernelOutOfBuffersRetriesTheSameFrameWithBackoffNeverBusyLooping) {
  auto shared = std::make_shared<FakeDevice::Shared>();
  shared->retry_later_left = 6;
  LogCapture log;
  imuemu::drivers::QueuedWriterOptions options;
  options.name = "fake can";
  options.retry_initial = 1ms;
  options.retry_max = 8ms;
  options.log = log.sink();
  imuemu::drivers::QueuedWriter writer(std::make_unique<FakeDevice>(shared, true), options);
  for (std::uint32_t s = 0; s < 20; ++s) ASSERT_TRUE(writer.offer(make_fixed_frame(s, 16)));
  ASSERT_TRUE(writer.flush(2s));
  const TransportCounters c = writer.counters();
  EXPECT_EQ(c.retries, 6u);
  EXPECT_EQ(c.frames_sent, 20u);
  EXPECT_EQ(accounted(c), c.frames);

  std::lock_guard lock(shared->mutex);
  // Datagrams: one frame per write, all 20 in order.
  const ParsedStream parsed = parse_frames(shared->bytes);
  EXPECT_EQ(parsed.error, "");
  ASSERT_EQ(parsed.sequences.size(), 20u);
  for (std::uint32_t s = 0; s < 20; ++s) EXPECT_EQ(parsed.sequences[s], s);
  // 6 refused attempts then success: gaps of at least 1, 2, 4, 8, 8, 8 ms.
  ASSERT_GE(shared->write_attempts.size(), 7u);
  const std::array<std::chrono::milliseconds, 6> minimum_gap = {1ms, 2ms, 4ms, 8ms, 8ms, 8ms};
  std::string gaps;
  for (std::size_t i = 0; i < 6; ++i) {
    const auto gap = shared->write_attempts[i + 1] - shared->write_attempts[i];
    gaps += std::to_string(std::chrono::duration<double, std::milli>(gap).count()) + " ";
    EXPECT_GE(gap, minimum_gap[i]) << "retry " << i;
  }
  std::printf("ENOBUFS retries, ms apart: %s\n", gaps.c_str());
}

TEST(QueuedWriter, AFrameTheKernelRefusesIsCountedAndTheNextOnesGoOn) {
  auto shared = std::make_shared<FakeDevice::Shared>();
  shared->reject_next = 1;
  imuemu::drivers::QueuedWriterOptions options;
  options.name = "fake can";
  options.log = [](std::string_view) {};
  imuemu::drivers::QueuedWriter writer(std::make_unique<FakeDevice>(shared, true), options);
  for (std::uint32_t s = 0; s < 3; ++s) ASSERT_TRUE(writer.offer(make_fixed_frame(s, 16)));
  ASSERT_TRUE(writer.flush(2s));
  const TransportCounters c = writer.counters();
  EXPECT_EQ(c.write_errors, 1u);
  EXPECT_EQ(c.frames_sent, 2u);
  std::lock_guard lock(shared->mutex);
  EXPECT_EQ(parse_frames(shared->bytes).sequences, (std::vector<std::uint32_t>{1, 2}));
}

TEST(QueuedWriter, RefusesEmptyAndOversizedFramesAndBadOptions) {
  auto shared = std::make_shared<FakeDevice::Shared>();
  imuemu::drivers::QueuedWriterOptions options;
  options.name = "fake";
  options.queue_bytes = 256;
  imuemu::drivers::QueuedWriter writer(std::make_unique<FakeDevice>(shared, false), options);
  EXPECT_FALSE(writer.offer({}));
  std::vector<std::byte> big(253);  // 256 - 4 bytes of length prefix = 252 at most
  EXPECT_FALSE(writer.offer(big));
  big.resize(252);
  EXPECT_TRUE(writer.offer(big));
  ASSERT_TRUE(writer.flush(2s));
  EXPECT_EQ(writer.counters().write_errors, 2u);
  EXPECT_EQ(writer.counters().frames_sent, 1u);

  options.queue_bytes = 10;
  const std::string e = error_of(
      [&] { imuemu::drivers::QueuedWriter w(std::make_unique<FakeDevice>(shared, false), options); });
  EXPECT_NE(e.find("queue size 10 bytes is out of range"), std::string::npos) << e;
}

// ---------------------------------------------------------------------------
// UART (libserialport): error paths and port listing on this host

TEST(SerialTransport, MissingPortIsAClearError) {
  imuemu::drivers::SerialTransportOptions options;
  options.port = "/dev/ttyIMUEMU-missing0";
  options.settings.baud = 921600;
  const std::string e = error_of([&] { imuemu::drivers::SerialTransport t(options); });
  EXPECT_NE(e.find("/dev/ttyIMUEMU-missing0"), std::string::npos) << e;
  EXPECT_NE(e.find("not found"), std::string::npos) << e;
}

TEST(SerialTransport, APtyIsRefusedNamingLibserialportsLimitation) {
  TempDir dir;
  imuemu::drivers::PtyTransportOptions pty_options;
  pty_options.log = [](std::string_view) {};
  imuemu::drivers::PtyTransport pty(pty_options);
  imuemu::drivers::SerialTransportOptions options;
  options.port = pty.slave_path();
  const std::string e = error_of([&] { imuemu::drivers::SerialTransport t(options); });
  EXPECT_NE(e.find(pty.slave_path()), std::string::npos) << e;
  EXPECT_NE(e.find("pseudo-terminal"), std::string::npos) << e;
}

TEST(SerialTransport, SettingsOutOfRangeAreNamed) {
  using imuemu::drivers::SerialSettings;
  SerialSettings s;
  s.data_bits = 9;
  EXPECT_NE(error_of([&] { imuemu::drivers::validate(s); }).find("9 data bits; expected 5, 6, 7 or 8"), std::string::npos);
  s = SerialSettings{};
  s.stop_bits = 3;
  EXPECT_NE(error_of([&] { imuemu::drivers::validate(s); }).find("3 stop bits"), std::string::npos);
  s = SerialSettings{};
  s.baud = 0;
  EXPECT_NE(error_of([&] { imuemu::drivers::validate(s); }).find("baud rate 0"), std::string::npos);
  EXPECT_NE(error_of([] { imuemu::drivers::parse_parity("evn"); }).find("expected none, odd, even, mark or space"),
            std::string::npos);
  EXPECT_NE(error_of([] { imuemu::drivers::parse_flow_control("hw"); }).find("expected none, rtscts or xonxoff"),
            std::string::npos);
  EXPECT_EQ(imuemu::drivers::parse_flow_control("rtscts"), imuemu::drivers::FlowControl::rts_cts);
  s = SerialSettings{};
  s.baud = 4'000'000;
  s.parity = imuemu::drivers::Parity::even;
  s.stop_bits = 2;
  EXPECT_EQ(imuemu::drivers::to_string(s), "4000000 8E2, flow none");
}

TEST(SerialPorts, ListingWorksAndTheCommandAgreesWithIt) {
  const auto ports = imuemu::drivers::list_serial_ports();
  for (const auto& p : ports) {
    EXPECT_EQ(p.name.rfind("/dev/", 0), 0u) << p.name;
    EXPECT_TRUE(fs::exists(p.name)) << p.name;
    EXPECT_TRUE(p.transport == "native" || p.transport == "usb" || p.transport == "bluetooth") << p.transport;
  }
  std::printf("libserialport lists %zu serial port(s) on this machine\n", ports.size());

  FILE* pipe = ::popen((std::string(IMUEMU_CLI_PATH) + " ports 2>&1").c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  std::array<char, 4096> chunk{};
  while (std::fgets(chunk.data(), static_cast<int>(chunk.size()), pipe) != nullptr) output += chunk.data();
  const int status = ::pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << output;
  if (ports.empty()) {
    EXPECT_NE(output.find("no serial ports found"), std::string::npos) << output;
  } else {
    EXPECT_EQ(static_cast<std::size_t>(std::count(output.begin(), output.end(), '\n')), ports.size() + 1) << output;
    for (const auto& p : ports) EXPECT_NE(output.find(p.name), std::string::npos) << output;
  }
}

// ---------------------------------------------------------------------------
// SocketCAN: errors on this host (no CAN in its kernel), wire format vs linux/can.h

TEST(SocketCan, MissingInterfaceIsAClearErrorNamingIt) {
  imuemu::drivers::CanTransportOptions options;
  options.interface = "imuemu-nocan0";
  const std::string send = error_of([&] { imuemu::drivers::CanTransport t(options); });
  EXPECT_NE(send.find("'imuemu-nocan0'"), std::string::npos) << send;
  EXPECT_NE(send.find("no such network interface"), std::string::npos) << send;
  const std::string receive = error_of([] { imuemu::drivers::CanReader r("imuemu-nocan0"); });
  EXPECT_NE(receive.find("'imuemu-nocan0'"), std::string::npos) << receive;
  EXPECT_NE(receive.find("no such network interface"), std::string::npos) << receive;
}

TEST(SocketCan, ANonCanInterfaceAndABadNameAreRefused) {
  imuemu::drivers::CanTransportOptions options;
  options.interface = "lo";  // every Linux network namespace has it
  const std::string e = error_of([&] { imuemu::drivers::CanTransport t(options); });
  EXPECT_NE(e.find("'lo' is not a CAN interface (link type 772"), std::string::npos) << e;
  options.interface = "a-name-longer-than-15";
  const std::string n = error_of([&] { imuemu::drivers::CanTransport t(options); });
  EXPECT_NE(n.find("'a-name-longer-than-15'"), std::string::npos) << n;
  EXPECT_NE(n.find("1 to 15 characters"), std::string::npos) << n;
}

TEST(SocketCan, FramesMatchTheKernelStructures) {
  using imuemu::drivers::CanFrame;
  std::array<std::byte, imuemu::drivers::kCanFdMtu> wire{};
  std::string error;

  CanFrame classic;
  classic.id = 0x123;
  classic.len = 8;
  for (std::uint8_t i = 0; i < 8; ++i) classic.data[i] = static_cast<std::uint8_t>(0xA0 + i);
  ASSERT_EQ(imuemu::drivers::to_socketcan(classic, false, true, wire, error), CAN_MTU) << error;
  can_frame k{};
  std::memcpy(&k, wire.data(), sizeof k);
  EXPECT_EQ(k.can_id, 0x123u);
  EXPECT_EQ(k.len, 8u);
  EXPECT_EQ(k.data[7], 0xA7u);

  CanFrame extended = classic;
  extended.id = 0x18FF5080;  // a J1939-style 29-bit id
  extended.extended = true;
  ASSERT_EQ(imuemu::drivers::to_socketcan(extended, false, true, wire, error), CAN_MTU) << error;
  std::memcpy(&k, wire.data(), sizeof k);
  EXPECT_EQ(k.can_id, 0x18FF5080u | CAN_EFF_FLAG);

  CanFrame fd;
  fd.id = 0x1ABCDE;
  fd.extended = true;
  fd.fd = true;
  fd.len = 64;
  for (std::uint8_t i = 0; i < 64; ++i) fd.data[i] = i;
  ASSERT_EQ(imuemu::drivers::to_socketcan(fd, true, true, wire, error), CANFD_MTU) << error;
  canfd_frame f{};
  std::memcpy(&f, wire.data(), sizeof f);
  EXPECT_EQ(f.can_id, 0x1ABCDEu | CAN_EFF_FLAG);
  EXPECT_EQ(f.len, 64u);
  EXPECT_EQ(f.flags, CANFD_BRS | CANFD_FDF);
  EXPECT_EQ(f.data[63], 63u);

  // Back again, as CanReader decodes what it receives.
  std::string what;
  const auto back = imuemu::drivers::from_socketcan(std::span<const std::byte>(wire.data(), CANFD_MTU), what);
  ASSERT_TRUE(back.has_value()) << what;
  EXPECT_EQ(back->id, fd.id);
  EXPECT_TRUE(back->extended && back->fd);
  EXPECT_EQ(back->len, 64u);
  EXPECT_EQ(back->data, fd.data);
  can_frame rtr{};
  rtr.can_id = 0x55 | CAN_RTR_FLAG;
  std::memcpy(wire.data(), &rtr, sizeof rtr);
  EXPECT_FALSE(imuemu::drivers::from_socketcan(std::span<const std::byte>(wire.data(), CAN_MTU), what));
  EXPECT_EQ(what, "a remote-request frame");

  // Invalid frames are refused with the reason.
  CanFrame bad = classic;
  bad.id = 0x800;  // 12 bits in an 11-bit frame
  EXPECT_EQ(imuemu::drivers::to_socketcan(bad, false, true, wire, error), 0u);
  EXPECT_EQ(error, "CAN id 0x800 does not fit 11 bits");
  bad = classic;
  bad.len = 9;
  EXPECT_EQ(imuemu::drivers::to_socketcan(bad, true, true, wire, error), 0u);
  EXPECT_NE(error.find("9 data bytes (at most 8)"), std::string::npos) << error;
  bad = fd;
  bad.len = 9;
  EXPECT_EQ(imuemu::drivers::to_socketcan(bad, true, true, wire, error), 0u);
  EXPECT_NE(error.find("expected 0-8, 12, 16, 20, 24, 32, 48 or 64"), std::string::npos) << error;
  EXPECT_EQ(imuemu::drivers::to_socketcan(fd, false, true, wire, error), 0u);
  EXPECT_NE(error.find("enable fd_frames"), std::string::npos) << error;
  // Every length a DLC can encode, and only those (ISO 11898-1 table 5).
  int valid = 0;
  for (unsigned len = 0; len <= 64; ++len) valid += imuemu::drivers::valid_can_fd_length(len) ? 1 : 0;
  EXPECT_EQ(valid, 16);
}

// ---------------------------------------------------------------------------
// GPIO: errors on this host (no gpiochip)

TEST(GpioSync, MissingChipIsAClearError) {
  imuemu::drivers::GpioSyncOptions options;
  options.chip = "gpiochip0";
  options.line = 3;
  const std::string e = error_of([&] { imuemu::drivers::GpioSyncOutput g(options); });
  bool any_chip = false;
  for (const auto& entry : fs::directory_iterator("/dev")) {
    if (entry.path().filename().string().rfind("gpiochip", 0) == 0) any_chip = true;
  }
  if (!any_chip) {
    EXPECT_NE(e.find("GPIO chip 'gpiochip0': not found"), std::string::npos) << e;
    EXPECT_NE(e.find("this machine has no GPIO chips"), std::string::npos) << e;
  } else {
    ADD_FAILURE() << "this machine has a gpiochip: run the GPIO tests in the QEMU fixture instead; got: " << e;
  }
  options.chip = "imuemu-no-such-chip";
  const std::string label = error_of([&] { imuemu::drivers::GpioSyncOutput g(options); });
  EXPECT_NE(label.find("GPIO chip 'imuemu-no-such-chip': not found"), std::string::npos) << label;
}

TEST(GpioSync, BadOptionsAreNamedBeforeAnyHardwareIsTouched) {
  imuemu::drivers::GpioSyncOptions options;
  options.chip = "gpiochip0";
  options.every_n_samples = 0;
  EXPECT_NE(error_of([&] { imuemu::drivers::GpioSyncOutput g(options); }).find("every_n_samples must be at least 1"),
            std::string::npos);
  options.every_n_samples = 4;
  options.sample_period_ns = 2'500'000;  // 400 Hz
  options.pulse_width_ns = 10'000'000;   // 10 ms = the whole 4-sample interval
  EXPECT_NE(error_of([&] { imuemu::drivers::GpioSyncOutput g(options); }).find("does not end before the next one"),
            std::string::npos);
  options.pulse_width_ns = 100'000;
  options.pps_line = 1;
  options.pps_width_ns = 1'000'000'000;
  EXPECT_NE(error_of([&] { imuemu::drivers::GpioSyncOutput g(options); }).find("1PPS pulse width must be between 0 and 1 s"),
            std::string::npos);
}


// The pulse timing itself, on recording lines (this host has no gpiochip):
// edges as the kernel would see line writes, stamped with CLOCK_MONOTONIC.
std::int64_t monotonic_now_ns() {
  timespec t{};
  ::clock_gettime(CLOCK_MONOTONIC, &t);
  return static_cast<std::int64_t>(t.tv_sec) * 1'000'000'000 + t.tv_nsec;
}

struct RecordingLine {
  struct Pulse {
    std::int64_t rise_ns, fall_ns;
  };
  std::mutex mutex;
  std::vector<std::pair<std::int64_t, bool>> writes;
  imuemu::drivers::GpioSyncOutput::LineWriter writer() {
    return [this](bool active) {
      std::lock_guard lock(mutex);
      writes.emplace_back(monotonic_now_ns(), active);
      return true;
    };
  }
  bool active() {
    std::lock_guard lock(mutex);
    return !writes.empty() && writes.back().second;
  }
  std::size_t rising_edges() {
    std::lock_guard lock(mutex);
    std::size_t n = 0;
    bool level = false;
    for (const auto& [t, active] : writes) {
      if (active && !level) ++n;
      level = active;
    }
    return n;
  }
  // Pulses from the level changes; `error` if the writes are not strictly
  // alternating inactive/active (a pulse started while one was going on).
  std::vector<Pulse> pulses(std::string& error) {
    std::lock_guard lock(mutex);
    std::vector<Pulse> out;
    bool level = false;
    for (const auto& [t, active] : writes) {
      if (active && level) error = "a pulse started while the line was active";
      if (active && !level) out.push_back({t, -1});
      if (!active && level) out.back().fall_ns = t;
      level = active;
    }
    return out;
  }
};

TEST(GpioSync, PulseOnEveryNthSampleLeadingEdgeInTheCallTrailingEdgeAfterTheWidth) {
  RecordingLine line;
  imuemu::drivers::GpioSyncOptions options;
  options.every_n_samples = 4;
  options.pulse_width_ns = 200'000;
  options.sample_period_ns = 1'000'000;
  options.trailing_edge_priority = 60;  // as a daemon would run it; tested both ways below
  options.log = [](std::string_view) {};
  bool realtime = false;
  constexpr std::uint64_t kSamples = 400;  // 0.4 s at 1 kHz
  std::vector<std::pair<std::int64_t, std::int64_t>> call_window;  // around each pulse() of a pulsing sample
  long voluntary_switches_in_calls = 0;
  {
    imuemu::drivers::GpioSyncOutput gpio(options, line.writer(), nullptr);
    realtime = gpio.trailing_edges_realtime();
    timespec next{};
    ::clock_gettime(CLOCK_MONOTONIC, &next);
    rusage before{}, after{};
    for (std::uint64_t k = 0; k < kSamples; ++k) {
      next.tv_nsec += 1'000'000;
      if (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      ::clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
      ::getrusage(RUSAGE_THREAD, &before);
      const std::int64_t start = monotonic_now_ns();
      gpio.pulse(k, static_cast<std::int64_t>(k) * 1'000'000);
      const std::int64_t end = monotonic_now_ns();
      ::getrusage(RUSAGE_THREAD, &after);
      voluntary_switches_in_calls += after.ru_nvcsw - before.ru_nvcsw;
      if (k % 4 == 0) call_window.emplace_back(start, end);
    }
    std::this_thread::sleep_for(20ms);  // the last trailing edge
    const auto c = gpio.counters();
    // Every 4th sample pulses, or (a trailing edge so late that it had not
    // happened 4 ms on: only without SCHED_FIFO on a loaded machine) is
    // skipped and counted.
    // (Even a SCHED_FIFO thread sees wake-ups milliseconds late on a shared
    // virtual machine, so no single edge's timing is asserted.)
    EXPECT_EQ(c.pulses + c.skipped_pulses, kSamples / 4);
    EXPECT_EQ(c.set_errors, 0u);
    std::printf("gpio sync (trailing edges %s): %llu pulses, %llu skipped, worst trailing edge %.1f us late\n",
                realtime ? "SCHED_FIFO" : "SCHED_OTHER", static_cast<unsigned long long>(c.pulses),
                static_cast<unsigned long long>(c.skipped_pulses), static_cast<double>(c.max_trailing_edge_delay_ns) / 1e3);
  }
  EXPECT_EQ(voluntary_switches_in_calls, 0) << "pulse() slept: it blocked the emission thread";
  std::string error;
  const auto pulses = line.pulses(error);
  EXPECT_EQ(error, "");
  ASSERT_LE(pulses.size(), kSamples / 4);
  std::int64_t widest = 0;
  std::vector<std::int64_t> widths;
  std::size_t call = 0;
  for (std::size_t i = 0; i < pulses.size(); ++i) {
    // The leading edge falls inside the pulse() call of its sample.
    while (call < call_window.size() && call_window[call].second < pulses[i].rise_ns) ++call;
    ASSERT_LT(call, call_window.size()) << "pulse " << i << " after the last pulsing sample";
    EXPECT_GE(pulses[i].rise_ns, call_window[call].first) << "pulse " << i << ": leading edge outside any pulse() call";
    ASSERT_GT(pulses[i].fall_ns, 0) << "pulse " << i << " never ended";
    const std::int64_t width = pulses[i].fall_ns - pulses[i].rise_ns;
    EXPECT_GE(width, 200'000) << "pulse " << i << " ended early";
    if (i + 1 < pulses.size()) {
      EXPECT_LT(pulses[i].fall_ns, pulses[i + 1].rise_ns) << "pulse " << i << " overlaps the next";
    }
    widest = std::max(widest, width);
    widths.push_back(width);
  }
  std::sort(widths.begin(), widths.end());
  const std::int64_t median_width = widths[widths.size() / 2];
  std::printf("gpio sync: widths 200 us asked, median %.1f us, widest %.1f us\n", static_cast<double>(median_width) / 1e3,
              static_cast<double>(widest) / 1e3);
  // The trailing edge comes from the timer, not from the next pulse() call
  // (which would make every pulse about 4 ms wide).
  EXPECT_LT(median_width, 1'200'000);
}

TEST(GpioSync, OnePpsOnTheFirstSampleAtOrAfterEachWholeTrajectorySecond) {
  // (trajectory times of successive samples, those that must carry a 1PPS edge)
  struct Case {
    std::vector<std::int64_t> t_ms;
    std::vector<std::int64_t> pps_at_ms;
  };
  const std::vector<Case> cases = {
      {{0, 250, 500, 750, 1000, 1250, 1500, 1750, 2000, 2250, 2500, 2750, 3000}, {0, 1000, 2000, 3000}},
      {{300, 600, 900, 1200, 1500, 1800, 2100, 2400}, {1200, 2100}},  // grid does not hit whole seconds
      {{-1500, -1000, -500, 0, 500}, {-1000, 0}},                     // negative trajectory time
  };
  for (const auto& c : cases) {
    RecordingLine sync, pps;
    imuemu::drivers::GpioSyncOptions options;
    options.every_n_samples = 1'000'000;  // no sync pulse for counters 1..n
    options.pulse_width_ns = 10'000;
    options.pps_width_ns = 100'000;
    imuemu::drivers::GpioSyncOutput gpio(options, sync.writer(), pps.writer());
    std::vector<std::int64_t> got;
    for (std::size_t k = 0; k < c.t_ms.size(); ++k) {
      const std::size_t before = pps.rising_edges();
      gpio.pulse(k + 1, c.t_ms[k] * 1'000'000);
      if (pps.rising_edges() > before) got.push_back(c.t_ms[k]);
      // Each edge a separate pulse, however loaded the machine: wait until the
      // output is free again, not only until the line is low (the helper
      // lowers the line a moment before it frees the output).
      ASSERT_TRUE(wait_until([&] { return !pps.active() && gpio.counters().pulses_in_progress == 0; }, 2s));
    }
    EXPECT_EQ(got, c.pps_at_ms);
    EXPECT_EQ(gpio.counters().pps_pulses, c.pps_at_ms.size());
    EXPECT_EQ(sync.rising_edges(), 0u);
  }
}

TEST(GpioSync, APulseDueWhileTheLastIsStillOnIsSkippedNotMerged) {
  RecordingLine line;
  imuemu::drivers::GpioSyncOptions options;
  options.every_n_samples = 1;
  options.pulse_width_ns = 200'000'000;  // far longer than the samples below are apart
  {
    imuemu::drivers::GpioSyncOutput gpio(options, line.writer(), nullptr);
    for (std::uint64_t k = 0; k < 6; ++k) gpio.pulse(k, static_cast<std::int64_t>(k) * 1'000'000);  // 1 starts, 5 skipped
    EXPECT_TRUE(line.active());
    ASSERT_TRUE(wait_until([&] { return !line.active() && gpio.counters().pulses_in_progress == 0; }, 2s));
    gpio.pulse(6, 6'000'000);  // the line is free again: a new pulse
    ASSERT_TRUE(wait_until([&] { return !line.active() && gpio.counters().pulses_in_progress == 0; }, 2s));
    const auto c = gpio.counters();
    EXPECT_EQ(c.pulses, 2u);
    EXPECT_EQ(c.skipped_pulses, 5u);
  }
  std::string error;
  const auto pulses = line.pulses(error);
  EXPECT_EQ(error, "") << "a skipped pulse must not touch the line";
  ASSERT_EQ(pulses.size(), 2u);
  for (const auto& p : pulses) EXPECT_GE(p.fall_ns - p.rise_ns, 200'000'000);
}

// Issue 29: a device personality's own sync-out setting (VectorNav register
// 32) drives the sync line: its pulses, widths and polarity, not the
// scene's every_n_samples. A polarity change moves the idle level at once
// when the line is idle, and waits for a pulse in progress to end.
TEST(GpioSync, TheDevicesSyncOutSettingDrivesPulseWidthAndPolarity) {
  using imuemu::drivers::DeviceSyncPulse;
  RecordingLine line;
  imuemu::drivers::GpioSyncOptions options;
  options.every_n_samples = 1;  // the scene's: a pulse per sample, 100 us, active high
  options.pulse_width_ns = 100'000;
  {
    imuemu::drivers::GpioSyncOutput gpio(options, line.writer(), nullptr);
    auto idle = [&] { return wait_until([&] { return gpio.counters().pulses_in_progress == 0; }, 2s); };
    auto level_writes = [&] {
      std::lock_guard lock(line.mutex);
      std::vector<bool> levels;
      for (const auto& w : line.writes) levels.push_back(w.second);
      return levels;
    };
    gpio.pulse(0, 0, DeviceSyncPulse{false, 300'000, false});  // the device says no pulse here
    EXPECT_EQ(level_writes(), std::vector<bool>({false})) << "only the constructor's idle level";
    gpio.pulse(1, 1'000'000, DeviceSyncPulse{true, 300'000, false});
    ASSERT_TRUE(idle());
    gpio.pulse(2, 2'000'000, DeviceSyncPulse{false, 300'000, true});  // negative polarity: idle high at once
    EXPECT_EQ(level_writes(), std::vector<bool>({false, true, false, true}));
    gpio.pulse(3, 3'000'000, DeviceSyncPulse{true, 300'000, true});  // a low pulse
    ASSERT_TRUE(idle());
    EXPECT_EQ(level_writes(), std::vector<bool>({false, true, false, true, false, true}));
    {
      std::lock_guard lock(line.mutex);
      const auto& w = line.writes;
      EXPECT_GE(w[2].first - w[1].first, 300'000) << "the device's width, not the scene's 100 us";
      EXPECT_GE(w[5].first - w[4].first, 300'000);
    }
    // A long pulse in progress: the polarity change waits for its end.
    gpio.pulse(4, 4'000'000, DeviceSyncPulse{true, 50'000'000, true});
    gpio.pulse(5, 5'000'000, DeviceSyncPulse{false, 300'000, false});
    EXPECT_EQ(level_writes().size(), 7u) << "no write while the pulse is on";
    ASSERT_TRUE(idle());
    gpio.pulse(6, 6'000'000, DeviceSyncPulse{false, 300'000, false});
    EXPECT_EQ(level_writes(), std::vector<bool>({false, true, false, true, false, true, false, true, false}));
    const auto c = gpio.counters();
    EXPECT_EQ(c.pulses, 3u);
    EXPECT_EQ(c.skipped_pulses, 0u);
    EXPECT_EQ(c.set_errors, 0u);
  }
}

// Issue 13: no exception leaves the trailing-edge thread. A line writer that
// throws there (the line gone, a bad writer) ended the process through
// std::terminate; now the thread records it, counts it, logs it and marks the
// sync output down: later pulses are skipped and touch no line.
TEST(GpioSync, AnExceptionOnTheTrailingEdgeThreadMarksTheSyncDown) {
  imuemu::drivers::GpioSyncOptions options;
  std::mutex log_mutex;
  std::string log;
  options.log = [&](std::string_view line) {
    std::lock_guard lock(log_mutex);
    log += std::string(line) + "\n";
  };
  std::atomic<int> writes{0};
  // The initial "inactive" and the leading edge work; every later write
  // (the trailing edge, on the helper thread) throws.
  imuemu::drivers::GpioSyncOutput gpio(options, [&](bool) {
    if (++writes > 2) throw std::runtime_error("line gone");
    return true;
  }, nullptr);
  gpio.pulse(0, 0);
  // helper_faults is counted when the helper has recorded, logged and cleaned
  // up (down is set before all that: waiting for it raced with the log).
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (gpio.counters().helper_faults == 0 && std::chrono::steady_clock::now() < until)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  auto c = gpio.counters();
  ASSERT_TRUE(c.down);
  EXPECT_EQ(c.helper_faults, 1u);
  EXPECT_EQ(c.pulses, 1u);
  EXPECT_EQ(gpio.failure(), "line gone");
  {
    std::lock_guard lock(log_mutex);
    EXPECT_NE(log.find("GPIO sync: the trailing-edge thread failed: line gone; sync output down"), std::string::npos)
        << log;
  }
  const int writes_when_down = writes.load();
  gpio.pulse(1, 1'000'000);
  c = gpio.counters();
  EXPECT_EQ(writes.load(), writes_when_down);  // no leading edge nobody would end
  EXPECT_EQ(c.pulses, 1u);
  EXPECT_EQ(c.skipped_pulses, 1u);
}

TEST(GpioSync, AFailedLineWriteIsCounted) {
  imuemu::drivers::GpioSyncOptions options;
  std::atomic<int> writes{0};
  imuemu::drivers::GpioSyncOutput gpio(options, [&](bool) { return ++writes == 1; }, nullptr);  // the initial "inactive" works
  gpio.pulse(0, 0);
  gpio.pulse(1, 1'000'000);
  const auto c = gpio.counters();
  EXPECT_EQ(c.pulses, 0u);
  EXPECT_EQ(c.set_errors, 2u);
}

}  // namespace
}  // namespace unity_drivers_test_transports
