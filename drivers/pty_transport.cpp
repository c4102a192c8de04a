#include "drivers/pty_transport.hpp"

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <sys/file.h>
#include <sys/ioctl.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <chrono>
#include <filesystem>
#include <system_error>
#include <thread>

#include "drivers/queued_writer.hpp"

namespace imuemu::drivers {
namespace {

std::string read_link(const std::string& path) {
  std::array<char, 4096> target{};
  const ssize_t n = ::readlink(path.c_str(), target.data(), target.size() - 1);
  return n > 0 ? std::string(target.data(), static_cast<std::size_t>(n)) : std::string();
}

// The master side of the pair, as the queued writer's device.
class PtyDevice final : public WriterDevice {
 public:
  PtyDevice(int master_fd, std::string slave_path) : master_(master_fd), slave_path_(std::move(slave_path)) {}
  ~PtyDevice() override {
    drain_before_close();
    ::close(master_);
  }

  bool datagrams() const override { return false; }
  int poll_fd() const override { return master_; }

  DeviceWrite write(std::span<const std::byte> bytes) override {
    const ssize_t n = ::write(master_, bytes.data(), bytes.size());
    if (n >= 0) return {DeviceWrite::Outcome::written, static_cast<std::size_t>(n), {}};
    if (errno == EAGAIN || errno == EINTR) return {DeviceWrite::Outcome::would_block, 0, {}};
    return {DeviceWrite::Outcome::link_lost, 0, "write to the pty master: " + errno_message(errno)};
  }

  std::optional<std::string> service(short revents, std::uint64_t* discarded_bytes) override {
    if (revents & POLLIN) {
      // The reader wrote to the slave (commands to the device): read all of
      // it (its writes never block on a full buffer) and hand it to the
      // device's input handler, or discard it without one.
      std::array<std::byte, 4096> sink;
      for (;;) {
        const ssize_t n = ::read(master_, sink.data(), sink.size());
        if (n <= 0) break;  // EAGAIN: drained; EIO: no slave open (POLLHUP below)
        deliver_input(std::span<const std::byte>(sink.data(), static_cast<std::size_t>(n)), discarded_bytes);
      }
    }
    // Linux reports POLLHUP on the master while no process has the slave open.
    if (revents & (POLLHUP | POLLERR | POLLNVAL)) return "the reader closed " + slave_path_;
    return std::nullopt;
  }

  void on_link_lost() override {
    // Bytes the departed reader left unread stay in the slave's input buffer
    // and would greet the next reader as stale samples. Flushing them takes a
    // slave descriptor (TCIFLUSH on the master does not reach them; checked
    // on Linux 6.1).
    const int fd = ::open(slave_path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) return;
    ::tcflush(fd, TCIFLUSH);
    ::close(fd);
  }

  bool try_restore(std::string& why) override {
    if (reader_present()) return true;
    why = "no process has " + slave_path_ + " open";
    return false;
  }

  bool initially_up() const override { return reader_present(); }

 private:
  // Closing the master hangs the slave up, and Linux discards what the reader
  // has not read yet: the last frames of an orderly stop would be lost. While
  // a reader is connected, wait (bounded) until it has read everything.
  // The unread count is the slave's input queue (FIONREAD on a slave
  // descriptor; the master's own queue does not report it).
  void drain_before_close() const {
    constexpr auto kLimit = std::chrono::milliseconds(500);
    if (!reader_present()) return;  // nobody to read it: nothing to wait for
    const auto until = std::chrono::steady_clock::now() + kLimit;
    // Our own slave descriptor keeps POLLHUP off the master from here on, so
    // a reader that leaves meanwhile costs the bounded wait, no more.
    const int fd = ::open(slave_path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) return;
    // Empty for 20 ms in a row (checked every 2 ms): written bytes reach the
    // slave's queue through the kernel's flip buffer, moved by a kworker
    // thread, which other SCHED_FIFO emitters on a busy host can hold off for
    // milliseconds. Two empty looks 2 ms apart let a close discard the last
    // frames (loopback_pty_emit_listen: 2 of 12000 MIP frames lost, uncounted).
    constexpr int kQuietChecks = 10;
    int quiet_checks = 0;
    while (std::chrono::steady_clock::now() < until) {
      int unread = 0;
      if (::ioctl(fd, FIONREAD, &unread) != 0) break;
      quiet_checks = unread == 0 ? quiet_checks + 1 : 0;
      if (quiet_checks >= kQuietChecks) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    ::close(fd);
  }
  bool reader_present() const {
    pollfd p{master_, POLLOUT, 0};
    return ::poll(&p, 1, 0) >= 0 && (p.revents & POLLHUP) == 0;
  }

  int master_;
  std::string slave_path_;
};

}  // namespace

// The symlink and the lock that tells a live owner from a stale link.
class PtyTransport::PublishedLink {
 public:
  PublishedLink(std::string link_path, std::string target) : link_path_(std::move(link_path)), target_(std::move(target)) {
    lock_path_ = link_path_ + ".lock";
    const std::filesystem::path parent = std::filesystem::path(link_path_).parent_path();
    if (!parent.empty()) {
      std::error_code ec;
      std::filesystem::create_directories(parent, ec);
      if (ec) fail("cannot create its directory " + parent.string() + ": " + ec.message());
    }
    lock();
    struct stat st {};
    if (::lstat(link_path_.c_str(), &st) == 0 && !S_ISLNK(st.st_mode)) {
      release_lock();
      fail("exists and is not a symbolic link; refusing to replace it");
    }
    // Atomic replacement of a stale link: readers never see the path missing.
    const std::string temporary = link_path_ + ".tmp-" + std::to_string(::getpid());
    ::unlink(temporary.c_str());
    if (::symlink(target_.c_str(), temporary.c_str()) != 0 || ::rename(temporary.c_str(), link_path_.c_str()) != 0) {
      const int error = errno;
      ::unlink(temporary.c_str());
      release_lock();
      fail("cannot create the symlink: " + errno_message(error));
    }
  }

  ~PublishedLink() {
    // Only our own link: if someone replaced it meanwhile, it is theirs.
    if (read_link(link_path_) == target_) ::unlink(link_path_.c_str());
    release_lock();
  }

  PublishedLink(const PublishedLink&) = delete;
  PublishedLink& operator=(const PublishedLink&) = delete;

 private:
  [[noreturn]] void fail(const std::string& what) const { throw TransportError("pty link " + link_path_ + ": " + what); }

  void lock() {
    // flock on "<link>.lock": held while we live, released by the kernel if
    // we crash, so a link whose lock is free is stale. The lock file is
    // removed on close; the inode check catches a file removed between our
    // open and flock (the previous owner closing at that moment).
    for (int attempt = 0; attempt < 8; ++attempt) {
      lock_fd_ = ::open(lock_path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC | O_NOFOLLOW, 0644);
      if (lock_fd_ < 0) fail("cannot open its lock file " + lock_path_ + ": " + errno_message(errno));
      if (::flock(lock_fd_, LOCK_EX | LOCK_NB) != 0) {
        const int error = errno;
        ::close(lock_fd_);
        lock_fd_ = -1;
        if (error == EWOULDBLOCK) fail("in use by another running imuemu (it holds " + lock_path_ + ")");
        fail("cannot lock " + lock_path_ + ": " + errno_message(error));
      }
      struct stat held {}, named {};
      if (::fstat(lock_fd_, &held) == 0 && ::stat(lock_path_.c_str(), &named) == 0 && held.st_ino == named.st_ino &&
          held.st_dev == named.st_dev) {
        return;
      }
      ::close(lock_fd_);
      lock_fd_ = -1;
    }
    fail("its lock file " + lock_path_ + " keeps changing; is another imuemu starting and stopping on it?");
  }

  void release_lock() {
    if (lock_fd_ < 0) return;
    ::unlink(lock_path_.c_str());
    ::close(lock_fd_);
    lock_fd_ = -1;
  }

  std::string link_path_;
  std::string target_;
  std::string lock_path_;
  int lock_fd_ = -1;
};

PtyTransport::PtyTransport(PtyTransportOptions options) : link_path_(options.link_path) {
  termios raw{};
  ::cfmakeraw(&raw);
  raw.c_cc[VMIN] = 1;
  raw.c_cc[VTIME] = 0;
  int master = -1, slave = -1;
  if (::openpty(&master, &slave, nullptr, &raw, nullptr) != 0) {
    throw TransportError("pty: openpty failed: " + errno_message(errno));
  }
  std::array<char, 256> name{};
  if (::ttyname_r(slave, name.data(), name.size()) != 0) {
    const int error = errno;
    ::close(master);
    ::close(slave);
    throw TransportError("pty: ttyname of the new slave: " + errno_message(error));
  }
  slave_path_ = name.data();
  if (options.slave_mode != 0 && ::fchmod(slave, static_cast<mode_t>(options.slave_mode & 07777)) != 0) {
    const int error = errno;
    ::close(master);
    ::close(slave);
    throw TransportError("pty " + slave_path_ + ": cannot set mode " + std::to_string(options.slave_mode) + ": " +
                         errno_message(error));
  }
  // The termios set above stay with the pair while the master is open, so
  // our slave descriptor is not needed; closing it makes "no reader" visible
  // (POLLHUP on the master).
  ::close(slave);
  ::fcntl(master, F_SETFD, FD_CLOEXEC);
  if (::fcntl(master, F_SETFL, ::fcntl(master, F_GETFL) | O_NONBLOCK) != 0) {
    const int error = errno;
    ::close(master);
    throw TransportError("pty " + slave_path_ + ": cannot make the master non-blocking: " + errno_message(error));
  }
  auto device = std::make_unique<PtyDevice>(master, slave_path_);  // owns `master` from here on
  if (!link_path_.empty()) link_ = std::make_unique<PublishedLink>(link_path_, slave_path_);

  QueuedWriterOptions writer;
  writer.name = describe();
  writer.queue_bytes = options.queue_bytes;
  // Probing for a reader is one poll(): a constant short interval (no need
  // to back off) keeps the frames lost after a reader connects few.
  writer.restore_initial = options.reader_probe_interval;
  writer.restore_max = options.reader_probe_interval;
  writer.link_lost_verb = "reader gone";
  writer.link_restored_verb = "reader connected";
  writer.log = std::move(options.log);
  // A pty has no line rate; it records the one its peer's device was last
  // told (a baud-rate command), starting from the usual 115200.
  writer.baud = 115200;
  writer_ = std::make_unique<QueuedWriter>(std::move(device), std::move(writer));
}

PtyTransport::~PtyTransport() {
  writer_.reset();  // stops the writer thread and closes the master
  link_.reset();
}

bool PtyTransport::write_frame(std::span<const std::byte> frame) { return writer_->offer(frame); }
bool PtyTransport::set_input_handler(InputHandler* handler) {
  writer_->set_input_handler(handler);
  return true;
}
std::uint32_t PtyTransport::baud() const { return writer_->baud(); }

std::string PtyTransport::describe() const {
  return link_path_.empty() ? "pty " + slave_path_ : "pty " + slave_path_ + " (" + link_path_ + ")";
}

TransportCounters PtyTransport::counters() const { return writer_->counters(); }
bool PtyTransport::link_up() const { return writer_->link_up(); }
bool PtyTransport::flush(std::chrono::milliseconds timeout) { return writer_->flush(timeout); }
void PtyTransport::stop(std::chrono::milliseconds drain_timeout) { writer_->stop(drain_timeout); }

}  // namespace imuemu::drivers
