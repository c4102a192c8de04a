// Test support: run a program as a child with stdout and stderr in a log file,
// for tests that signal it (SIGTERM) or read its device while it runs.
#pragma once

#include <fcntl.h>
#include <sys/types.h>
#include <unistd.h>

#include <string>
#include <vector>

namespace imuemu::test {

// fork + execv(program, {program, args...}); returns the child's pid (-1 if
// fork failed). Everything is allocated before fork: the child only calls
// async-signal-safe functions, and exits 127 if exec fails.
inline pid_t spawn_logged(const char* program, const std::vector<std::string>& args, const std::string& log_path) {
  std::vector<char*> argv;
  argv.push_back(const_cast<char*>(program));
  for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const pid_t pid = ::fork();
  if (pid == 0) {
    const int log = ::open(log_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    ::dup2(log, 1);
    ::dup2(log, 2);
    ::execv(program, argv.data());
    ::_exit(127);
  }
  return pid;
}

}  // namespace imuemu::test
