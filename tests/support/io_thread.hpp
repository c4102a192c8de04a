// Test fixtures shared by the daemon's service tests (control socket, sd_notify,
// signals): a Boost.Asio io_context on its own thread, and a scratch directory.
#pragma once

#include <stdlib.h>

#include <atomic>
#include <chrono>
#include <filesystem>
#include <string>
#include <thread>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>

namespace imuemu::test {

// A directory /tmp/<prefix>XXXXXX removed with everything in it.
class TempDir {
 public:
  explicit TempDir(const std::string& prefix = "imuemu_test_") {
    std::string dir_template = "/tmp/" + prefix + "XXXXXX";
    path = ::mkdtemp(dir_template.data());
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  TempDir(const TempDir&) = delete;
  TempDir& operator=(const TempDir&) = delete;
  std::string path;
};

// io.run() on a thread of its own until destruction.
class IoThread {
 public:
  IoThread() : work_(io.get_executor()), thread_([this] { io.run(); }) {}
  ~IoThread() {
    work_.reset();
    io.stop();
    thread_.join();
  }
  IoThread(const IoThread&) = delete;
  IoThread& operator=(const IoThread&) = delete;
  // Runs f on the io thread and waits for it.
  template <class F>
  void run(F f) {
    std::atomic<bool> done{false};
    boost::asio::post(io, [&] {
      f();
      done = true;
    });
    while (!done) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  boost::asio::io_context io;

 private:
  boost::asio::executor_work_guard<boost::asio::io_context::executor_type> work_;
  std::thread thread_;
};

}  // namespace imuemu::test
