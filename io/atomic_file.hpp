// All-or-nothing output files, and whole-file input.
//
// A run that fails half way (bad sample, full disk, exception) must not leave
// half a file behind, nor a temporary file: readers see either the complete
// new file or whatever was there before (standard atomic replace).
// AtomicFileWriter writes into "<target>.tmp.<pid>.XXXXXX" (mkstemp, same
// directory so rename() stays within one file system), buffered; commit()
// flushes, fsyncs, and renames it over the target. An uncommitted writer's
// destructor deletes the temporary file, and the target is never touched
// before commit().
//
// Stale temporary files (a writer killed by SIGKILL or a power cut cannot
// delete its own): the pid in the name says whose a temporary file is. Each
// new AtomicFileWriter removes the temporary files of its own target whose
// pid no longer runs (kill(pid, 0) fails with ESRCH) and which belong to the
// same user; those of a running process (this one included) are left alone.
// A pid reused by an unrelated process only keeps a stale file a little
// longer. Processes of other pid namespaces writing the same directory are
// not told apart (the files of a dead writer there may stay).
//
// Paths that are not plain files (issue 26 N16: as root, `--out /dev/stdout`
// once replaced the system's /dev/stdout symlink with a regular file). The
// writer never replaces anything but a regular file:
//  - a symbolic link is followed (up to 40 links, relative ones from the
//    link's directory) and the file it names is written atomically, beside
//    that file; the link stays. A dangling link creates the file it names.
//  - a FIFO or character device (a pipe, a tty, /dev/null), or a descriptor
//    link of /proc (/dev/stdout, /dev/fd/N, /proc/self/fd/N) to one of them
//    or to a regular file, is opened and written as a stream: not atomic
//    (a failure leaves what was written; a transaction cannot take it back),
//    the file behind a descriptor link is appended to as the descriptor's
//    owner left it (`> file` truncated it, `>> file` keeps it). Opening a
//    FIFO waits for its reader, as a shell's `> fifo` does.
//  - a directory, block device or socket is refused (std::system_error
//    naming the path and what it is) before anything is created or written.
//
// Several outputs of one command (an IMU file and a trajectory file) are
// committed together with an OutputTransaction: while one is open on a
// thread, AtomicFileWriter::commit() on that thread only prepares its file
// (flushed, fsynced, closed) and hands it over; OutputTransaction::commit()
// then renames them all. If any output fails before that, none is replaced.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <sys/types.h>
#include <vector>

namespace imuemu::io {

class AtomicFileWriter {
 public:
  static constexpr std::size_t kDefaultBufferBytes = std::size_t{1} << 20;

  // Creates the temporary file next to target_path (or next to the file a
  // link names), or opens a stream (see the top of this file). Throws
  // std::system_error (naming the path) if it cannot (missing directory, no
  // permission, a directory or other file that cannot be written, ...).
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
  // file), fsync, close, rename over the target, fsync the directory. A
  // stream: flush and close.
  // Throws std::system_error; on failure the temporary file is still removed
  // by the destructor and the old target (if any) is left as it was.
  // Inside an OutputTransaction (same thread): everything but the rename;
  // the transaction then owns the temporary file.
  void commit();

  // Deletes the temporary file now (idempotent; no-op after commit).
  void discard() noexcept;

  bool committed() const noexcept { return committed_; }
  const std::string& target_path() const noexcept { return target_path_; }
  const std::string& temp_path() const noexcept { return temp_path_; }  // empty for a stream
  // Written directly (FIFO, character device, descriptor link): not atomic.
  bool streaming() const noexcept { return streaming_; }

 private:
  void flush();
  void write_all(const char* data, std::size_t size);

  std::string target_path_;
  std::string file_path_;  // the file replaced: target_path_ with its symbolic links followed
  std::string temp_path_;
  std::string buffer_;
  std::size_t buffer_bytes_;
  int fd_ = -1;
  bool committed_ = false;
  bool streaming_ = false;
};

// The outputs of one command, replaced together (see the top of this file).
// Open one before the first output is written; commit() after the last.
// Destroyed without commit() (an exception, a failed output): every prepared
// temporary file is removed and no target changes. Not nestable.
class OutputTransaction {
 public:
  OutputTransaction();
  ~OutputTransaction();
  OutputTransaction(const OutputTransaction&) = delete;
  OutputTransaction& operator=(const OutputTransaction&) = delete;

  // Renames every prepared file over its target, in the order prepared. If
  // a rename fails, the targets already replaced get their old content back
  // (kept as a hard link until then; a target that did not exist is
  // removed), every temporary file is removed, and std::system_error is
  // thrown. Ends the transaction either way.
  void commit();

  // AtomicFileWriter::commit() inside the transaction.
  void adopt(std::string temp_path, std::string target_path);

 private:
  struct Prepared {
    std::string temp_path, target_path;
  };
  void end() noexcept;
  std::vector<Prepared> prepared_;
  bool open_ = true;
};

// Whose temporary file `name` (a file name, no directory) is, if it is one
// of AtomicFileWriter's for the target file name `target_name`:
// "<target_name>.tmp.<pid>.<suffix>" -> pid; else -1.
pid_t temp_file_owner(std::string_view name, std::string_view target_name);

// Removes the stale temporary files of target_path (see the top of this
// file); returns how many. Never throws.
std::size_t remove_stale_temp_files(const std::string& target_path) noexcept;

// Writes the whole content atomically (AtomicFileWriter + commit).
void write_file_atomically(const std::string& path, std::string_view content);

// Reads a whole file into `out`. Returns 0 on success, else the errno value
// (ENOENT, EACCES, EISDIR, ...); `out` is then unspecified. Works for regular
// files (one read of the known size) and for pipes/devices.
int read_whole_file(const std::string& path, std::string& out);

}  // namespace imuemu::io
