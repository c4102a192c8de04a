#include "drivers/socketcan.hpp"

#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cstring>
#include <vector>

#include "drivers/queued_writer.hpp"
#include "drivers/socketcan_wire.hpp"

namespace imuemu::drivers {
namespace {

std::string socket_error_reason(int error) {
  if (error == ENETDOWN) return "interface down";
  if (error == ENODEV || error == ENXIO) return "interface removed";
  return errno_message(error);
}

// The CAN_RAW socket of a CanTransport, as the queued writer sees it.
class CanDevice final : public WriterDevice {
 public:
  CanDevice(std::string interface, bool fd_frames, int socket, bool up, std::vector<CanReceiveFilter> filters)
      : interface_(std::move(interface)), fd_frames_(fd_frames), socket_(socket), up_at_start_(up),
        filters_(std::move(filters)) {
    if (socket_ >= 0) configure_receive();
  }
  ~CanDevice() override { close_socket(); }

  bool datagrams() const override { return true; }
  int poll_fd() const override { return socket_; }

  DeviceWrite write(std::span<const std::byte> bytes) override {
    const ssize_t n = ::send(socket_, bytes.data(), bytes.size(), MSG_DONTWAIT);
    if (n == static_cast<ssize_t>(bytes.size())) return {DeviceWrite::Outcome::written, bytes.size(), {}};
    if (n >= 0) return {DeviceWrite::Outcome::frame_rejected, 0, "short write of a CAN frame"};
    const int error = errno;
    switch (error) {
      case EAGAIN:
      case EINTR:
        return {DeviceWrite::Outcome::would_block, 0, {}};  // socket send buffer full: POLLOUT will come
      case ENOBUFS:
        return {DeviceWrite::Outcome::retry_later, 0, {}};  // device queue full: POLLOUT would not tell us
      case ENETDOWN:
      case ENODEV:
      case ENXIO:
        return {DeviceWrite::Outcome::link_lost, 0, socket_error_reason(error)};
      default:
        return {DeviceWrite::Outcome::frame_rejected, 0, errno_message(error)};
    }
  }

  std::optional<std::string> service(short revents, std::uint64_t* discarded_bytes) override {
    std::optional<std::string> lost;
    if (revents & POLLERR) {
      // CAN_RAW reports the interface going down (ENETDOWN) or away (ENODEV)
      // as a socket error (net/can/raw.c, raw_notify).
      int error = 0;
      socklen_t size = sizeof error;
      if (::getsockopt(socket_, SOL_SOCKET, SO_ERROR, &error, &size) == 0 && error != 0) {
        lost = socket_error_reason(error);
      }
    }
    if (revents & POLLIN) {
      // Error frames, and the data frames the receive filters let through
      // (requests addressed to the device): those go to the input tap.
      canfd_frame frame{};
      for (;;) {
        const ssize_t n = ::recv(socket_, &frame, sizeof frame, MSG_DONTWAIT);
        if (n <= 0) break;
        if (frame.can_id & CAN_ERR_FLAG) {
          if (frame.can_id & CAN_ERR_BUSOFF) lost = "bus-off (controller error frame)";
          continue;
        }
        deliver_input(std::span<const std::byte>(reinterpret_cast<const std::byte*>(&frame), static_cast<std::size_t>(n)),
                      discarded_bytes);
      }
    }
    if (revents & POLLNVAL) lost = "socket closed";
    return lost;
  }

  void on_link_lost() override { close_socket(); }

  bool try_restore(std::string& why) override {
    close_socket();
    try {
      const CanInterfaceState state = inspect_can_interface(interface_, fd_frames_);
      if (!state.up) {
        why = "interface is down (ip link set " + interface_ + " up)";
        return false;
      }
      if (!state.running) {
        why = "interface is up but not running (bus-off or no carrier)";
        return false;
      }
      socket_ = open_can_raw_socket(interface_, state.index, fd_frames_);
      configure_receive();
      return true;
    } catch (const TransportError& e) {
      why = e.what();
      return false;
    }
  }

  bool initially_up() const override { return up_at_start_; }

 private:
  void configure_receive() {
    // Receive exactly the requests the device answers (none: an empty
    // filter list), and the error frames that tell a bus-off and a restart.
    std::vector<can_filter> filters;
    for (const CanReceiveFilter& f : filters_) {
      can_filter k{};
      k.can_id = f.extended ? ((f.id & CAN_EFF_MASK) | CAN_EFF_FLAG) : (f.id & CAN_SFF_MASK);
      // The frame format and "not a remote request" are part of the match.
      k.can_mask = (f.extended ? (f.mask & CAN_EFF_MASK) : (f.mask & CAN_SFF_MASK)) | CAN_EFF_FLAG | CAN_RTR_FLAG;
      filters.push_back(k);
    }
    ::setsockopt(socket_, SOL_CAN_RAW, CAN_RAW_FILTER, filters.empty() ? nullptr : filters.data(),
                 static_cast<socklen_t>(filters.size() * sizeof(can_filter)));
    const can_err_mask_t errors = CAN_ERR_BUSOFF | CAN_ERR_RESTARTED;
    ::setsockopt(socket_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &errors, sizeof errors);
  }

  void close_socket() {
    if (socket_ >= 0) ::close(socket_);
    socket_ = -1;
  }

  std::string interface_;
  bool fd_frames_;
  int socket_;
  bool up_at_start_;
  std::vector<CanReceiveFilter> filters_;
};

}  // namespace

// Between the queued writer's byte input and a CanCommandResponder: the
// kernel structure -> CanFrame, and reply frames -> the kernel structure
// into the writer's reply queue (written between the device's frames).
class CanTransport::FrameInput final : public InputHandler {
 public:
  FrameInput(bool fd_frames, bool bitrate_switch) : fd_frames_(fd_frames), bitrate_switch_(bitrate_switch) {}
  CanCommandResponder* responder = nullptr;

  void on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) override {
    if (responder == nullptr) return;
    std::string what;
    const std::optional<CanFrame> frame =
        from_socketcan(std::span<const std::byte>(reinterpret_cast<const std::byte*>(bytes.data()), bytes.size()), what);
    if (!frame) return;
    Sink sink(*this, replies);
    responder->on_frame(*frame, sink);
  }

 private:
  class Sink final : public CanReplySink {
   public:
    Sink(FrameInput& input, ReplySink& replies) : input_(input), replies_(replies) {}
    bool reply(const CanFrame& frame) override {
      std::array<std::byte, kCanFdMtu> wire;
      std::string error;
      const std::size_t size = to_socketcan(frame, input_.fd_frames_, input_.bitrate_switch_, wire, error);
      if (size == 0) return false;
      return replies_.reply(std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(wire.data()), size));
    }

   private:
    FrameInput& input_;
    ReplySink& replies_;
  };
  bool fd_frames_;
  bool bitrate_switch_;
};

CanTransport::CanTransport(CanTransportOptions options) : options_(std::move(options)) {
  const CanInterfaceState state = inspect_can_interface(options_.interface, options_.fd_frames);
  const int socket = open_can_raw_socket(options_.interface, state.index, options_.fd_frames);
  description_ = "socketcan " + options_.interface + (options_.fd_frames ? " (CAN FD)" : " (classic CAN)");
  const bool up = state.up && state.running;
  if (!up) emit_log(options_.log, description_ + ": interface is not up and running yet; frames are dropped until it is");
  QueuedWriterOptions writer;
  writer.name = description_;
  writer.queue_bytes = options_.queue_frames * (kCanFdMtu + sizeof(std::uint32_t));
  writer.retry_initial = options_.retry_initial;
  writer.retry_max = options_.retry_max;
  writer.restore_initial = options_.restore_initial;
  writer.restore_max = options_.restore_max;
  writer.link_lost_verb = "link down";
  writer.link_restored_verb = "link up again";
  writer.log = options_.log;
  writer_ = std::make_unique<QueuedWriter>(std::make_unique<CanDevice>(options_.interface, options_.fd_frames, socket, up, options_.receive_filters),
                                           std::move(writer));
}

CanTransport::~CanTransport() {
  if (writer_) writer_->set_input_handler(nullptr);
}

void CanTransport::set_command_responder(CanCommandResponder* responder) {
  writer_->set_input_handler(nullptr);  // waits until the io thread is out of the previous one
  if (!input_) input_ = std::make_unique<FrameInput>(options_.fd_frames, options_.fd_bitrate_switch);
  input_->responder = responder;
  if (responder != nullptr) writer_->set_input_handler(input_.get());
}

bool CanTransport::send(const CanFrame& frame) {
  std::array<std::byte, kCanFdMtu> wire;
  std::string error;
  const std::size_t size = to_socketcan(frame, options_.fd_frames, options_.fd_bitrate_switch, wire, error);
  if (size == 0) {
    writer_->count_invalid_frame();
    return false;
  }
  return writer_->offer(std::span<const std::byte>(wire.data(), size));
}

std::string CanTransport::describe() const { return description_; }
TransportCounters CanTransport::counters() const { return writer_->counters(); }
bool CanTransport::link_up() const { return writer_->link_up(); }
bool CanTransport::flush(std::chrono::milliseconds timeout) { return writer_->flush(timeout); }
void CanTransport::stop(std::chrono::milliseconds drain_timeout) { writer_->stop(drain_timeout); }

CanReader::CanReader(const std::string& interface, bool fd_frames) : interface_(interface) {
  const CanInterfaceState state = inspect_can_interface(interface_, false);
  socket_ = open_can_raw_socket(interface_, state.index, fd_frames);
  const int on = 1;
  if (::setsockopt(socket_, SOL_SOCKET, SO_TIMESTAMPNS, &on, sizeof on) != 0 ||
      ::setsockopt(socket_, SOL_SOCKET, SO_RXQ_OVFL, &on, sizeof on) != 0) {
    const int error = errno;
    ::close(socket_);
    throw TransportError("CAN interface '" + interface_ + "': cannot enable receive timestamps: " + errno_message(error));
  }
}

CanReader::~CanReader() { ::close(socket_); }

std::string CanReader::describe() const { return "socketcan " + interface_; }

std::optional<ReceivedCanFrame> CanReader::receive(std::chrono::milliseconds timeout) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  for (;;) {
    const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());
    pollfd p{socket_, POLLIN, 0};
    const int ready = ::poll(&p, 1, left.count() > 0 ? static_cast<int>(left.count()) : 0);
    if (ready < 0 && errno != EINTR) {
      throw TransportError("CAN interface '" + interface_ + "': poll: " + errno_message(errno));
    }
    if (ready <= 0) {
      if (left.count() <= 0) return std::nullopt;
      continue;
    }
    if (p.revents & POLLERR) {
      int error = 0;
      socklen_t size = sizeof error;
      ::getsockopt(socket_, SOL_SOCKET, SO_ERROR, &error, &size);  // reading it clears it
      if (error == ENETDOWN) {
        ++counters_.interface_down;  // still bound: frames arrive again once it is up
      } else if (error != 0) {
        throw TransportError("CAN interface '" + interface_ + "': " + socket_error_reason(error));
      }
    }
    if (!(p.revents & POLLIN)) continue;

    std::array<std::byte, kCanFdMtu> wire;
    iovec io{wire.data(), wire.size()};
    alignas(cmsghdr) std::array<char, CMSG_SPACE(sizeof(timespec)) + CMSG_SPACE(sizeof(std::uint32_t))> control;
    msghdr message{};
    message.msg_iov = &io;
    message.msg_iovlen = 1;
    message.msg_control = control.data();
    message.msg_controllen = control.size();
    const ssize_t n = ::recvmsg(socket_, &message, MSG_DONTWAIT);
    if (n < 0) {
      if (errno == EAGAIN || errno == EINTR) continue;
      if (errno == ENETDOWN) {
        ++counters_.interface_down;
        continue;
      }
      throw TransportError("CAN interface '" + interface_ + "': " + socket_error_reason(errno));
    }
    ReceivedCanFrame received;
    for (cmsghdr* c = CMSG_FIRSTHDR(&message); c != nullptr; c = CMSG_NXTHDR(&message, c)) {
      if (c->cmsg_level != SOL_SOCKET) continue;
      if (c->cmsg_type == SO_TIMESTAMPNS) {
        timespec stamp{};
        std::memcpy(&stamp, CMSG_DATA(c), sizeof stamp);
        received.kernel_receive_realtime_ns = static_cast<TimeNs>(stamp.tv_sec) * kNsPerSecond + stamp.tv_nsec;
      } else if (c->cmsg_type == SO_RXQ_OVFL) {
        std::uint32_t dropped = 0;
        std::memcpy(&dropped, CMSG_DATA(c), sizeof dropped);
        counters_.kernel_drops = dropped;  // the socket's running total
      }
    }
    std::string what;
    const std::optional<CanFrame> frame =
        from_socketcan(std::span<const std::byte>(wire.data(), static_cast<std::size_t>(n)), what);
    if (!frame) {
      ++counters_.ignored_frames;
      continue;
    }
    received.frame = *frame;
    ++counters_.frames;
    return received;
  }
}

}  // namespace imuemu::drivers
