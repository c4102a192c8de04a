#include "io/atomic_file.hpp"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <linux/magic.h>
#include <sys/stat.h>
#include <sys/vfs.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
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

std::string file_name_of(const std::string& path) {
  const std::size_t slash = path.rfind('/');
  return slash == std::string::npos ? path : path.substr(slash + 1);
}

void fsync_directory(const std::string& path) {
  // Make a rename durable. Best effort: some file systems refuse fsync on a
  // directory, and the data is already in place.
  const int dir_fd = ::open(directory_of(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir_fd >= 0) {
    ::fsync(dir_fd);
    ::close(dir_fd);
  }
}

// This thread's open OutputTransaction (AtomicFileWriter::commit defers to it).
thread_local OutputTransaction* t_transaction = nullptr;

// Where an output goes (see "Paths that are not plain files" in the header).
struct Destination {
  bool stream = false;  // open `path` and write it directly
  int open_flags = 0;   // for a stream
  std::string path;     // the file to replace atomically, or the path to open
};

std::string read_link(const std::string& path) {
  std::string target(256, '\0');
  for (;;) {
    const ssize_t n = ::readlink(path.c_str(), target.data(), target.size());
    if (n < 0) throw_errno(errno, "cannot read the symbolic link '" + path + "'");
    if (static_cast<std::size_t>(n) < target.size()) {
      target.resize(static_cast<std::size_t>(n));
      return target;
    }
    target.resize(target.size() * 2);
  }
}

// A link in /proc/<pid>/fd (what /dev/stdout and /dev/fd/N lead to) names an
// open file description, not a path: its text ("pipe:[1234]") cannot be
// followed, but open() through it reaches the descriptor's object.
bool in_procfs(const std::string& directory) {
  struct statfs fs {};
  return ::statfs(directory.c_str(), &fs) == 0 && fs.f_type == PROC_SUPER_MAGIC;
}

// A file that is neither replaced nor streamed: why not.
[[noreturn]] void refuse(const std::string& output, const std::string& path, mode_t mode) {
  const std::string through = path == output ? "" : " (through its links: '" + path + "')";
  if (S_ISDIR(mode)) throw_errno(EISDIR, "output '" + output + "'" + through + " is a directory, not a file");
  if (S_ISBLK(mode))
    throw_errno(ENOTSUP, "output '" + output + "'" + through + " is a block device: imuemu writes files, not disks");
  if (S_ISSOCK(mode))
    throw_errno(ENXIO, "output '" + output + "'" + through +
                           " is a socket, which cannot be opened as a file (a service's journal stream?): give a "
                           "file, a FIFO or a pipe");
  throw_errno(ENOTSUP, "output '" + output + "'" + through + " is not a regular file, FIFO or character device");
}

Destination destination_of(const std::string& output) {
  constexpr int kMaxLinks = 40;  // as the kernel's path walk (ELOOP)
  std::string path = output;
  for (int links = 0;; ++links) {
    struct stat info {};
    if (::lstat(path.c_str(), &info) != 0) {
      // A new file (a missing directory is reported by mkstemp, naming it).
      if (errno == ENOENT) return {false, 0, path};
      throw_errno(errno, "cannot examine output '" + output + "'" + (path == output ? "" : " at '" + path + "'"));
    }
    if (S_ISREG(info.st_mode)) return {false, 0, path};
    if (S_ISFIFO(info.st_mode) || S_ISCHR(info.st_mode)) return {true, O_WRONLY, path};
    if (!S_ISLNK(info.st_mode)) refuse(output, path, info.st_mode);
    if (links == kMaxLinks) throw_errno(ELOOP, "output '" + output + "': more than 40 symbolic links");
    if (in_procfs(directory_of(path))) {
      struct stat object {};
      if (::stat(path.c_str(), &object) != 0) throw_errno(errno, "cannot examine output '" + output + "'");
      if (S_ISREG(object.st_mode)) return {true, O_WRONLY | O_APPEND, path};
      if (S_ISFIFO(object.st_mode) || S_ISCHR(object.st_mode)) return {true, O_WRONLY, path};
      refuse(output, path, object.st_mode);
    }
    const std::string target = read_link(path);
    path = !target.empty() && target.front() == '/' ? target : directory_of(path) + "/" + target;
  }
}

}  // namespace

pid_t temp_file_owner(std::string_view name, std::string_view target_name) {
  constexpr std::string_view kMark = ".tmp.";
  if (name.size() <= target_name.size() + kMark.size() || name.substr(0, target_name.size()) != target_name ||
      name.substr(target_name.size(), kMark.size()) != kMark)
    return -1;
  const std::string_view rest = name.substr(target_name.size() + kMark.size());
  const std::size_t dot = rest.find('.');
  if (dot == std::string_view::npos || dot == 0 || dot + 1 == rest.size()) return -1;
  pid_t pid = 0;
  const auto [end, ec] = std::from_chars(rest.data(), rest.data() + dot, pid);
  if (ec != std::errc() || end != rest.data() + dot || pid <= 0) return -1;
  return pid;
}

std::size_t remove_stale_temp_files(const std::string& target_path) noexcept {
  std::size_t removed = 0;
  try {
    const std::string dir = directory_of(target_path), target_name = file_name_of(target_path);
    DIR* d = ::opendir(dir.c_str());
    if (d == nullptr) return 0;
    std::vector<std::string> stale;
    while (const dirent* e = ::readdir(d)) {
      const pid_t pid = temp_file_owner(e->d_name, target_name);
      if (pid <= 0 || pid == ::getpid()) continue;
      if (::kill(pid, 0) == 0 || errno != ESRCH) continue;  // running (or not ours to signal: EPERM)
      stale.emplace_back(dir + "/" + e->d_name);
    }
    ::closedir(d);
    for (const std::string& path : stale) {
      struct stat info {};
      // Regular files of this user only (never follow a symlink planted there).
      if (::lstat(path.c_str(), &info) != 0 || !S_ISREG(info.st_mode) || info.st_uid != ::geteuid()) continue;
      if (::unlink(path.c_str()) == 0) ++removed;
    }
  } catch (...) {
  }
  return removed;
}

OutputTransaction::OutputTransaction() {
  if (t_transaction != nullptr) throw std::logic_error("OutputTransaction: one is already open on this thread");
  t_transaction = this;
}

OutputTransaction::~OutputTransaction() {
  end();
  for (const Prepared& p : prepared_) ::unlink(p.temp_path.c_str());
}

void OutputTransaction::end() noexcept {
  if (t_transaction == this) t_transaction = nullptr;
  open_ = false;
}

void OutputTransaction::adopt(std::string temp_path, std::string target_path) {
  prepared_.push_back({std::move(temp_path), std::move(target_path)});
}

void OutputTransaction::commit() {
  if (!open_) throw std::logic_error("OutputTransaction::commit: already ended");
  end();
  // The old targets as hard links, so a failed rename can put them back.
  std::vector<std::string> backups(prepared_.size());
  for (std::size_t i = 0; i < prepared_.size(); ++i) {
    const std::string& target = prepared_[i].target_path;
    for (int attempt = 0; attempt < 100; ++attempt) {
      const std::string name = target + ".tmp." + std::to_string(::getpid()) + ".old" + std::to_string(i) + "_" +
                               std::to_string(attempt);
      if (::link(target.c_str(), name.c_str()) == 0) {
        backups[i] = name;
        break;
      }
      if (errno != EEXIST) break;  // no old target (ENOENT), or no hard links here: nothing to restore
    }
  }
  auto remove_all = [&] {
    for (const Prepared& p : prepared_) ::unlink(p.temp_path.c_str());
    for (const std::string& b : backups)
      if (!b.empty()) ::unlink(b.c_str());
    prepared_.clear();
  };
  for (std::size_t i = 0; i < prepared_.size(); ++i) {
    if (::rename(prepared_[i].temp_path.c_str(), prepared_[i].target_path.c_str()) == 0) continue;
    const int error = errno;
    const std::string what = "cannot rename '" + prepared_[i].temp_path + "' to '" + prepared_[i].target_path + "'";
    for (std::size_t j = 0; j < i; ++j) {  // undo the renames made
      if (!backups[j].empty()) {
        if (::rename(backups[j].c_str(), prepared_[j].target_path.c_str()) == 0) backups[j].clear();
      } else {
        ::unlink(prepared_[j].target_path.c_str());
      }
    }
    remove_all();
    throw_errno(error, what);
  }
  for (const Prepared& p : prepared_) fsync_directory(p.target_path);
  prepared_.clear();
  remove_all();
}

AtomicFileWriter::AtomicFileWriter(std::string target_path, std::size_t buffer_bytes)
    : target_path_(std::move(target_path)), buffer_bytes_(buffer_bytes == 0 ? 1 : buffer_bytes) {
  if (target_path_.empty()) throw std::invalid_argument("AtomicFileWriter: empty output path");
  const Destination destination = destination_of(target_path_);
  file_path_ = destination.path;
  if (destination.stream) {
    do {
      fd_ = ::open(file_path_.c_str(), destination.open_flags | O_CLOEXEC);  // a FIFO waits here for its reader
    } while (fd_ < 0 && errno == EINTR);
    if (fd_ < 0) throw_errno(errno, "cannot open output '" + target_path_ + "' for writing");
    streaming_ = true;
    buffer_.reserve(buffer_bytes_);
    return;
  }
  std::vector<char> name(file_path_.begin(), file_path_.end());
  remove_stale_temp_files(file_path_);
  const std::string suffix = ".tmp." + std::to_string(::getpid()) + ".XXXXXX";
  name.insert(name.end(), suffix.c_str(), suffix.c_str() + suffix.size() + 1);  // includes the NUL
  fd_ = ::mkostemp(name.data(), O_CLOEXEC);
  if (fd_ < 0) {
    throw_errno(errno, "cannot create a temporary file next to '" + file_path_ + "'" +
                           (file_path_ == target_path_ ? "" : " (where the link '" + target_path_ + "' leads)"));
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
      throw_errno(errno, "cannot write '" + (streaming_ ? target_path_ : temp_path_) + "'");
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
  if (streaming_) {  // nothing to rename (and a transaction has nothing to take back)
    const int fd = fd_;
    fd_ = -1;
    committed_ = true;
    if (::close(fd) != 0 && errno != EINTR) throw_errno(errno, "cannot close '" + target_path_ + "'");
    return;
  }
  // mkstemp creates 0600; give the file the mode an ordinary open() would have
  // produced, or keep the replaced file's mode.
  struct stat old_target {};
  const mode_t mode = ::stat(file_path_.c_str(), &old_target) == 0
                          ? static_cast<mode_t>(old_target.st_mode & 07777)
                          : static_cast<mode_t>(0666 & ~current_umask());
  if (::fchmod(fd_, mode) != 0) throw_errno(errno, "cannot set the mode of '" + temp_path_ + "'");
  if (::fsync(fd_) != 0) throw_errno(errno, "cannot fsync '" + temp_path_ + "'");
  const int fd = fd_;
  fd_ = -1;
  if (::close(fd) != 0) throw_errno(errno, "cannot close '" + temp_path_ + "'");
  if (t_transaction != nullptr) {  // the transaction renames it with the others
    t_transaction->adopt(temp_path_, file_path_);
    committed_ = true;
    temp_path_.clear();
    return;
  }
  if (::rename(temp_path_.c_str(), file_path_.c_str()) != 0) {
    throw_errno(errno, "cannot rename '" + temp_path_ + "' to '" + file_path_ + "'");
  }
  committed_ = true;
  temp_path_.clear();
  fsync_directory(file_path_);
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
