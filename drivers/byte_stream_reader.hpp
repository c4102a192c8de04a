// Reads a byte stream raw for `imuemu listen` and the tests: a pty (such as
// the one a PtyTransport publishes), a real serial port, or a FIFO / file.
//  - pty slave: opened with termios, switched to raw (no line discipline
//    editing, no echo); libserialport 0.1.1 cannot open ptys.
//  - other ttys: libserialport when it can open them (real UARTs, USB
//    adapters), configured with `settings`; otherwise termios with the same
//    settings (standard rates only), e.g. UML's /dev/ttyS*.
//  - FIFOs and files: read as they are.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

#include "drivers/serial_transport.hpp"

struct sp_port;

namespace imuemu::drivers {

struct ReadResult {
  std::size_t bytes = 0;       // bytes placed at the start of the buffer
  bool end_of_stream = false;  // the writer side is gone (pty master closed, device removed, end of file)
};

class ByteStreamReader {
 public:
  enum class Kind { pty, serial_libserialport, tty_termios, other };

  // read_write: a tty (pty or serial port) the caller also writes to, as a
  // driver writes its requests (`imuemu listen --handshake`); a file or FIFO
  // is refused then.
  enum class Access { read_only, read_write };

  // Throws TransportError naming the path: missing, cannot open, settings refused.
  explicit ByteStreamReader(const std::string& path, const SerialSettings& settings = {},
                            Access access = Access::read_only);
  ~ByteStreamReader();
  ByteStreamReader(const ByteStreamReader&) = delete;
  ByteStreamReader& operator=(const ByteStreamReader&) = delete;

  // Waits up to `timeout` for bytes; returns what one read gave (0 bytes on
  // timeout). Throws TransportError on a read error other than the end of
  // the stream.
  ReadResult read_some(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout);

  // Writes all of `bytes`, waiting at most `timeout` for the port to take
  // them. Throws TransportError (opened read-only, write error, timeout).
  void write_all(std::span<const std::uint8_t> bytes, std::chrono::milliseconds timeout);

  Kind kind() const noexcept { return kind_; }
  std::string describe() const { return description_; }

 private:
  std::string path_;
  std::string description_;
  Kind kind_ = Kind::other;
  bool writable_ = false;
  int fd_ = -1;
  sp_port* port_ = nullptr;  // set when libserialport opened the port (it owns fd_ then)
};

}  // namespace imuemu::drivers
