// All-or-nothing output files, and whole-file input.
//
// A run that fails half way (bad sample, full disk, exception) must not leave
// half a file behind, nor a temporary file: readers see either the complete
// new file or whatever was there before (standard atomic replace).
// AtomicFileWriter writes into "<target>.tmp.XXXXXX" (mkstemp, same directory
// so rename() stays within one file system), buffered; commit() flushes,
// fsyncs, and renames it over the target. An uncommitted writer's destructor
// deletes the temporary file, and the target is never touched before commit().
#pragma once

#include <cstddef>
#include <string>
#include <string_view>

namespace imuemu::io {

class AtomicFileWriter {
 public:
  static constexpr std::size_t kDefaultBufferBytes = std::size_t{1} << 20;

  // Creates the temporary file next to target_path. Throws std::system_error
  // (naming the path) if it cannot (missing directory, no permission, ...).
  explicit AtomicFileWriter(std::string target_path,
                            std::size_t buffer_bytes = kDefaultBufferBytes);
  // Uncommitted: closes and deletes the temporary file. Never throws.
  ~AtomicFileWriter();

  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;
  AtomicFileWriter(AtomicFileWriter&&) = delete;
  AtomicFileWriter& operator=(AtomicFileWriter&&) = delete;

  // Appends bytes (buffered; a write(2) only when the buffer is full).
  // Throws std::system_error on a write error, std::logic_error after commit.
  void write(std::string_view bytes);

  // Flush, set the mode (the old target's mode, or 0666 & ~umask for a new
  // file), fsync, close, rename over the target, fsync the directory.
  // Throws std::system_error; on failure the temporary file is still removed
  // by the destructor and the old target (if any) is left as it was.
  void commit();

  // Deletes the temporary file now (idempotent; no-op after commit).
  void discard() noexcept;

  bool committed() const noexcept { return committed_; }
  const std::string& target_path() const noexcept { return target_path_; }
  const std::string& temp_path() const noexcept { return temp_path_; }

 private:
  void flush();
  void write_all(const char* data, std::size_t size);

  std::string target_path_;
  std::string temp_path_;
  std::string buffer_;
  std::size_t buffer_bytes_;
  int fd_ = -1;
  bool committed_ = false;
};

// Writes the whole content atomically (AtomicFileWriter + commit).
void write_file_atomically(const std::string& path, std::string_view content);

// Reads a whole file into `out`. Returns 0 on success, else the errno value
// (ENOENT, EACCES, EISDIR, ...); `out` is then unspecified. Works for regular
// files (one read of the known size) and for pipes/devices.
int read_whole_file(const std::string& path, std::string& out);

}  // namespace imuemu::io
