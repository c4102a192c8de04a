#include "daemon/service/service_signals.hpp"

#include <csignal>
#include <string>

#include "log/log.hpp"

namespace imuemu::service {

ServiceSignals::ServiceSignals(boost::asio::io_context& io, std::function<void(int)> on_stop,
                               std::function<void()> on_reload)
    : signals_(io, SIGTERM, SIGINT, SIGHUP), on_stop_(std::move(on_stop)), on_reload_(std::move(on_reload)) {
  wait();
}

ServiceSignals::~ServiceSignals() {
  boost::system::error_code ignored;
  signals_.cancel(ignored);
  signals_.clear(ignored);
}

void ServiceSignals::wait() {
  signals_.async_wait([this](const boost::system::error_code& ec, int signal_number) {
    if (ec) return;  // cancelled: `this` is going away
    if (signal_number == SIGHUP) {
      if (stop_requested_) {
        log_info("SIGHUP while stopping: ignored");
      } else {
        log_info("SIGHUP: reloading the scene");
        if (on_reload_) on_reload_();
      }
    } else if (!stop_requested_) {
      stop_requested_ = true;
      log_info(std::string(signal_number == SIGTERM ? "SIGTERM" : "SIGINT") + ": stopping");
      if (on_stop_) on_stop_(signal_number);
    }
    wait();
  });
}

}  // namespace imuemu::service
