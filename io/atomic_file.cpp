#include "io/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <stdexcept>
#include <system_error>
#include <utility>
#include <vector>

namespace imuemu::io {
namespace {

[[noreturn]] void throw_errno(int error, const std::string& what) {
  throw std::system_error(error, std::generic_category(), what);
}

// The process umask without changing it: umask(2) can only be read by setting
// it, which would race with other threads creating files; Linux reports it in
// /proc/self/status (since 4.7). Falls back to the common 022.
mode_t current_umask() {
  mode_t mask = 022;
  if (std::FILE* f = std::fopen("/proc/self/status", "re")) {
    char line[256];
    while (std::fgets(line, sizeof line, f) != nullptr) {
      if (std::strncmp(line, "Umask:", 6) == 0) {
        mask = static_cast<mode_t>(std::strtoul(line + 6, nullptr, 8)) & 0777;
        break;
      }
    }
    std::fclose(f);
  }
  return mask;
}

std::string directory_of(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

}  // namespace

AtomicFileWriter::AtomicFileWriter(std::string target_path, std::size_t buffer_bytes)
    : target_path_(std::move(target_path)), buffer_bytes_(buffer_bytes == 0 ? 1 : buffer_bytes) {
  if (target_path_.empty()) throw std::invalid_argument("AtomicFileWriter: empty output path");
  std::vector<char> name(target_path_.begin(), target_path_.end());
  static constexpr char kSuffix[] = ".tmp.XXXXXX";
  name.insert(name.end(), kSuffix, kSuffix + sizeof kSuffix);  // includes the NUL
  fd_ = ::mkostemp(name.data(), O_CLOEXEC);
  if (fd_ < 0) {
    throw_errno(errno, "cannot create a temporary file next to '" + target_path_ + "'");
  }
  temp_path_.assign(name.data());
  buffer_.reserve(buffer_bytes_);
}

AtomicFileWriter::~AtomicFileWriter() { discard(); }

void AtomicFileWriter::discard() noexcept {
  if (committed_) return;
  if (fd_ >= 0) {
    ::close(fd_);
    fd_ = -1;
  }
  if (!temp_path_.empty()) {
    ::unlink(temp_path_.c_str());
    temp_path_.clear();
  }
  buffer_.clear();
}

void AtomicFileWriter::write_all(const char* data, std::size_t size) {
  while (size > 0) {
    const ssize_t written = ::write(fd_, data, size);
    if (written < 0) {
      if (errno == EINTR) continue;
      throw_errno(errno, "cannot write '" + temp_path_ + "'");
    }
    data += written;
    size -= static_cast<std::size_t>(written);
  }
}

void AtomicFileWriter::flush() {
  write_all(buffer_.data(), buffer_.size());
  buffer_.clear();
}

void AtomicFileWriter::write(std::string_view bytes) {
  if (committed_) throw std::logic_error("AtomicFileWriter::write after commit: " + target_path_);
  if (fd_ < 0) throw std::logic_error("AtomicFileWriter::write after discard: " + target_path_);
  if (buffer_.size() + bytes.size() > buffer_bytes_) {
    flush();
    if (bytes.size() >= buffer_bytes_) {  // too big to be worth copying
      write_all(bytes.data(), bytes.size());
      return;
    }
  }
  buffer_.append(bytes);
}

void AtomicFileWriter::commit() {
  if (committed_) return;
  if (fd_ < 0) throw std::logic_error("AtomicFileWriter::commit after discard: " + target_path_);
  flush();
  // mkstemp creates 0600; give the file the mode an ordinary open() would have
  // produced, or keep the replaced file's mode.
  struct stat old_target {};
  const mode_t mode = ::stat(target_path_.c_str(), &old_target) == 0
                          ? static_cast<mode_t>(old_target.st_mode & 07777)
                          : static_cast<mode_t>(0666 & ~current_umask());
  if (::fchmod(fd_, mode) != 0) throw_errno(errno, "cannot set the mode of '" + temp_path_ + "'");
  if (::fsync(fd_) != 0) throw_errno(errno, "cannot fsync '" + temp_path_ + "'");
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) throw_errno(errno, "cannot close '" + temp_path_ + "'");
  if (::rename(temp_path_.c_str(), target_path_.c_str()) != 0) {
    throw_errno(errno, "cannot rename '" + temp_path_ + "' to '" + target_path_ + "'");
  }
  committed_ = true;
  temp_path_.clear();
  // Make the rename itself durable. Best effort: some file systems refuse
  // fsync on a directory, and the data is already in place.
  const int dir_fd = ::open(directory_of(target_path_).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd >= 0) {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
}

void write_file_atomically(const std::string& path, std::string_view content) {
  AtomicFileWriter writer(path);
  writer.write(content);
  writer.commit();
}

int read_whole_file(const std::string& path, std::string& out) {
  out.clear();
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return errno;
  struct stat info {};
  if (::fstat(fd, &info) != 0) {
    const int error = errno;
    ::close(fd);
    return error;
  }
  if (S_ISDIR(info.st_mode)) {
    ::close(fd);
    return EISDIR;
  }
  // Regular files: one allocation of the known size; anything else (pipes,
  // /dev/stdin) grows as it goes. The loop also copes with a file that grows
  // while being read.
  std::size_t capacity = S_ISREG(info.st_mode) && info.st_size > 0
                             ? static_cast<std::size_t>(info.st_size) + 1
                             : std::size_t{1} << 16;
  std::size_t size = 0;
  out.resize(capacity);
  for (;;) {
    if (size == out.size()) out.resize(out.size() * 2);
    const ssize_t got = ::read(fd, out.data() + size, out.size() - size);
    if (got < 0) {
      if (errno == EINTR) continue;
      const int error = errno;
      ::close(fd);
      return error;
    }
    if (got == 0) break;
    size += static_cast<std::size_t>(got);
  }
  ::close(fd);
  out.resize(size);
  return 0;
}

}  // namespace imuemu::io
