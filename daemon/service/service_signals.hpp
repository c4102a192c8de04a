// imuemud's signals, handled on the service io_context (boost::asio::signal_set),
// never in an async-signal context:
//   SIGTERM, SIGINT: stop (systemctl stop; Ctrl-C in a terminal). The daemon
//     sends STOPPING=1, stops the emission thread, closes devices and the
//     control socket and exits 0 (a clean stop is not a failure, so
//     Restart=on-failure leaves it stopped).
//   SIGHUP: reload (systemctl reload = ExecReload=kill -HUP $MAINPID). The
//     daemon sends RELOADING=1, re-reads and checks the scene file on a worker
//     thread while the running scene goes on, then restarts the scene
//     in-process (devices re-opened), then READY=1. A scene file that no longer
//     parses (or whose trajectory does not load) is logged and the running
//     scene is kept. The io thread is never blocked by a build, so these
//     signals are handled at once whatever is being built.
// A second SIGTERM while stopping is ignored: systemd escalates to SIGKILL
// after TimeoutStopSec.
#pragma once

#include <functional>

#include <boost/asio/io_context.hpp>
#include <boost/asio/signal_set.hpp>

namespace imuemu::service {

class ServiceSignals {
 public:
  ServiceSignals(boost::asio::io_context& io, std::function<void(int signal_number)> on_stop,
                 std::function<void()> on_reload);
  ~ServiceSignals();  // on the io thread or after it stopped; restores default dispositions
  ServiceSignals(const ServiceSignals&) = delete;
  ServiceSignals& operator=(const ServiceSignals&) = delete;

  bool stop_requested() const { return stop_requested_; }

 private:
  void wait();

  boost::asio::signal_set signals_;
  std::function<void(int)> on_stop_;
  std::function<void()> on_reload_;
  bool stop_requested_ = false;
};

}  // namespace imuemu::service
