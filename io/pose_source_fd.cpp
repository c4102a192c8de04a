// Pose lines from a file descriptor (stdin). poll() + read() rather than
// Asio: poll works on every kind of stdin (pipe, tty, regular file), epoll
// (Asio's reactor) refuses regular files.
#include <poll.h>
#include <sys/eventfd.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>
#include <utility>
#include <vector>

#include "io/pose_admission.hpp"
#include "io/pose_source.hpp"

namespace imuemu::io {
namespace {

class FdPoseSource final : public PoseSource {
 public:
  FdPoseSource(int fd, PoseSourceOptions options)
      : PoseSource(std::move(options)), fd_(fd), wake_fd_(::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK)) {
    if (wake_fd_ < 0) throw std::system_error(errno, std::generic_category(), name_ + ": eventfd");
  }
  ~FdPoseSource() override {
    stop();
    ::close(wake_fd_);
  }

 private:
  static constexpr std::size_t kReadBytes = 16384;

  void run() override {
    PoseLineStream stream(*admission_, name_);
    std::vector<char> buffer(kReadBytes);
    while (!stop_requested()) {
      pollfd fds[2] = {{fd_, POLLIN, 0}, {wake_fd_, POLLIN, 0}};
      if (::poll(fds, 2, -1) < 0) {
        if (errno == EINTR) continue;
        admission_->log("read_error", std::string("poll failed: ") + std::strerror(errno));
        mark_finished();
        return;
      }
      if (fds[1].revents != 0) return;  // stop requested
      const ssize_t n = ::read(fd_, buffer.data(), buffer.size());
      if (n < 0) {
        if (errno == EINTR || errno == EAGAIN) continue;
        // Nothing more will come (e.g. a closed descriptor): end the input.
        admission_->log("read_error", std::string("read failed: ") + std::strerror(errno));
        stream.finish();
        mark_finished();
        return;
      }
      if (n == 0) {
        stream.finish();
        admission_->log("end", "end of input");
        mark_finished();
        return;
      }
      stream.append(buffer.data(), static_cast<std::size_t>(n), monotonic_now_ns());
      // Reading stops while the queue is full (push_with_backpressure
      // blocks): the writer's pipe fills and it waits.
      SourcedPose pose;
      while (stream.next(pose)) {
        if (!push_with_backpressure(pose)) return;
      }
    }
  }

  void wake() override {
    const std::uint64_t one = 1;
    [[maybe_unused]] const ssize_t written = ::write(wake_fd_, &one, sizeof one);
  }

  int fd_;
  int wake_fd_;
};

}  // namespace

std::unique_ptr<PoseSource> make_fd_pose_source(int fd, PoseSourceOptions options) {
  if (options.name.empty()) options.name = fd == 0 ? "stdin" : "fd " + std::to_string(fd);
  return std::make_unique<FdPoseSource>(fd, std::move(options));
}

}  // namespace imuemu::io
