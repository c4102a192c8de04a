#include "drivers/byte_stream_reader.hpp"

#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <termios.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <utility>

#include "drivers/queued_writer.hpp"
#include "drivers/serial_port.hpp"

namespace imuemu::drivers {
namespace {

// termios knows a fixed set of rates (termios(3), Linux additions up to 4 Mbaud).
speed_t termios_speed(int baud) {
  static constexpr std::pair<int, speed_t> kRates[] = {
      {1200, B1200},       {2400, B2400},       {4800, B4800},       {9600, B9600},       {19200, B19200},
      {38400, B38400},     {57600, B57600},     {115200, B115200},   {230400, B230400},   {460800, B460800},
      {500000, B500000},   {576000, B576000},   {921600, B921600},   {1000000, B1000000}, {1152000, B1152000},
      {1500000, B1500000}, {2000000, B2000000}, {2500000, B2500000}, {3000000, B3000000}, {3500000, B3500000},
      {4000000, B4000000}};
  for (const auto& [rate, speed] : kRates) {
    if (rate == baud) return speed;
  }
  return B0;
}

// Raw mode (no editing, echo or signals) plus, for a real tty, the line settings.
void make_raw(int fd, const std::string& where, const SerialSettings* settings) {
  termios tio{};
  if (::tcgetattr(fd, &tio) != 0) throw TransportError(where + ": tcgetattr: " + errno_message(errno));
  ::cfmakeraw(&tio);
  tio.c_cc[VMIN] = 1;
  tio.c_cc[VTIME] = 0;
  if (settings != nullptr) {
    const speed_t speed = termios_speed(settings->baud);
    if (speed == B0) {
      throw TransportError(where + ": " + std::to_string(settings->baud) +
                           " baud is not a standard termios rate (libserialport could not open this port, "
                           "and the termios fallback has standard rates only)");
    }
    ::cfsetispeed(&tio, speed);
    ::cfsetospeed(&tio, speed);
    tio.c_cflag |= CLOCAL | CREAD;
    tio.c_cflag &= ~(CSIZE | PARENB | PARODD | CMSPAR | CSTOPB | CRTSCTS);
    static constexpr tcflag_t kSizes[] = {CS5, CS6, CS7, CS8};
    tio.c_cflag |= kSizes[settings->data_bits - 5];
    switch (settings->parity) {
      case Parity::none: break;
      case Parity::odd: tio.c_cflag |= PARENB | PARODD; break;
      case Parity::even: tio.c_cflag |= PARENB; break;
      case Parity::mark: tio.c_cflag |= PARENB | CMSPAR | PARODD; break;
      case Parity::space: tio.c_cflag |= PARENB | CMSPAR; break;
    }
    if (settings->stop_bits == 2) tio.c_cflag |= CSTOPB;
    if (settings->flow_control == FlowControl::rts_cts) tio.c_cflag |= CRTSCTS;
    if (settings->flow_control == FlowControl::xon_xoff) tio.c_iflag |= IXON | IXOFF;
  }
  if (::tcsetattr(fd, TCSANOW, &tio) != 0) throw TransportError(where + ": tcsetattr: " + errno_message(errno));
}

int open_for_reading(const std::string& path, const std::string& where, bool writable = false) {
  const int fd = ::open(path.c_str(), (writable ? O_RDWR : O_RDONLY) | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) throw TransportError(where + ": cannot open: " + errno_message(errno));
  return fd;
}

}  // namespace

ByteStreamReader::ByteStreamReader(const std::string& path, const SerialSettings& settings, Access access)
    : path_(path), writable_(access == Access::read_write) {
  const std::string where = "byte stream " + path;
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) throw TransportError(where + ": not found (" + errno_message(errno) + ")");
  if (is_pty_slave(path)) {
    fd_ = open_for_reading(path, where, writable_);
    try {
      make_raw(fd_, where, nullptr);
    } catch (...) {
      ::close(fd_);
      throw;
    }
    kind_ = Kind::pty;
    description_ = "pty " + path + " (termios raw)";
    return;
  }
  validate(settings);
  if (S_ISCHR(st.st_mode)) {
    const int probe = open_for_reading(path, where);
    const bool tty = ::isatty(probe) != 0;
    ::close(probe);
    if (tty) {
      try {
        SerialPortHandle port = open_serial_port(path, settings, writable_ ? SP_MODE_READ_WRITE : SP_MODE_READ);
        fd_ = serial_port_fd(port.get());
        port_ = port.release();
        kind_ = Kind::serial_libserialport;
        description_ = "serial " + path + " " + to_string(settings) + " (libserialport)";
        return;
      } catch (const TransportError& libserialport_failure) {
        fd_ = open_for_reading(path, where, writable_);
        try {
          make_raw(fd_, where, &settings);
        } catch (...) {
          ::close(fd_);
          throw;
        }
        kind_ = Kind::tty_termios;
        description_ = "tty " + path + " " + to_string(settings) + " (termios; libserialport: " +
                       libserialport_failure.what() + ")";
        return;
      }
    }
  }
  if (writable_) throw TransportError(where + ": not a tty: nothing to write requests to");
  fd_ = open_for_reading(path, where);
  kind_ = Kind::other;
  description_ = "file " + path;
}

ByteStreamReader::~ByteStreamReader() {
  if (port_ != nullptr) {
    SerialPortCloser{}(port_);
  } else if (fd_ >= 0) {
    ::close(fd_);
  }
}

ReadResult ByteStreamReader::read_some(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) {
  pollfd p{fd_, POLLIN, 0};
  const int ready = ::poll(&p, 1, static_cast<int>(timeout.count()));
  if (ready < 0) {
    if (errno == EINTR) return {};
    throw TransportError("byte stream " + path_ + ": poll: " + errno_message(errno));
  }
  if (ready == 0) return {};
  if (p.revents & POLLIN) {
    const ssize_t n = ::read(fd_, buffer.data(), buffer.size());
    if (n > 0) return {static_cast<std::size_t>(n), false};
    if (n == 0) return {0, true};  // end of file / FIFO without writer
    if (errno == EAGAIN || errno == EINTR) return {};
    // A pty slave reads EIO once the master is closed; a removed USB adapter too.
    if (errno == EIO || errno == ENXIO || errno == ENODEV) return {0, true};
    throw TransportError("byte stream " + path_ + ": read: " + errno_message(errno));
  }
  if (p.revents & (POLLHUP | POLLERR | POLLNVAL)) return {0, true};
  return {};
}

void ByteStreamReader::write_all(std::span<const std::uint8_t> bytes, std::chrono::milliseconds timeout) {
  if (!writable_) throw TransportError("byte stream " + path_ + ": opened for reading only");
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd_, bytes.data() + done, bytes.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno != EAGAIN && errno != EINTR)
      throw TransportError("byte stream " + path_ + ": write: " + errno_message(errno));
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    if (left.count() <= 0) throw TransportError("byte stream " + path_ + ": the port took no bytes for the timeout");
    pollfd p{fd_, POLLOUT, 0};
    ::poll(&p, 1, static_cast<int>(left.count()));
  }
}

}  // namespace imuemu::drivers
