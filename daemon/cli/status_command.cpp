#include "daemon/cli/status_command.hpp"

#include <sys/socket.h>
#include <sys/stat.h>
#include <grp.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <ostream>
#include <thread>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>
#include <boost/asio/buffers_iterator.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/local/stream_protocol.hpp>
#include <boost/asio/read.hpp>
#include <boost/asio/streambuf.hpp>
#include <boost/asio/write.hpp>

#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/service/imuemud.hpp"

namespace imuemu::cli {

namespace asio = boost::asio;
using stream_protocol = asio::local::stream_protocol;

namespace {

constexpr std::size_t kMaxReplyBytes = 4u << 20;

std::string group_name_of(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return {};
  const struct group* g = ::getgrgid(st.st_gid);
  return g ? std::string(g->gr_name) : std::to_string(st.st_gid);
}

[[noreturn]] void fail_connect(const std::string& path, const boost::system::error_code& ec) {
  // connect(2) errors arrive in the system category: compare errno values.
  const int err = ec.category() == boost::system::system_category() ? ec.value() : 0;
  if (err == ENOENT) {
    throw ControlClientError("no control socket at " + path +
                             " (is imuemud running for this scene? `systemctl status imuemud@SCENE`)");
  }
  if (err == EACCES || err == EPERM) {
    const std::string group = group_name_of(path);
    throw ControlClientError("permission denied on control socket " + path +
                             (group.empty() ? std::string() : " (ask to be added to its group '" + group + "')"));
  }
  if (err == ECONNREFUSED) {
    throw ControlClientError("nothing is listening on control socket " + path +
                             " (stale socket file: the daemon is not running)");
  }
  throw ControlClientError("cannot connect to control socket " + path + ": " + ec.message());
}

double number_or_zero(const nlohmann::json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_number() ? it->get<double>() : 0.0;
}

std::uint64_t count_of(const nlohmann::json& j, const char* key) {
  const auto it = j.find(key);
  // Counters are unsigned, but the pid and rates are written as int64.
  if (it == j.end() || !it->is_number_integer()) return 0u;
  return it->is_number_unsigned() ? it->get<std::uint64_t>()
                                  : static_cast<std::uint64_t>(std::max<std::int64_t>(0, it->get<std::int64_t>()));
}

std::string text_of(const nlohmann::json& j, const char* key) {
  const auto it = j.find(key);
  return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

std::string microseconds(double ns) { return std::to_string(std::llround(ns / 1000.0)) + " us"; }

// A bucket's upper bound as a person reads it: "850 us", "4.1 ms", "25 ms".
std::string bucket_bound_text(double upper_us) {
  char text[32];
  if (upper_us < 10.0) std::snprintf(text, sizeof text, "%.1f us", upper_us);
  else if (upper_us < 1000.0) std::snprintf(text, sizeof text, "%.0f us", upper_us);
  else if (upper_us < 10'000.0) std::snprintf(text, sizeof text, "%.1f ms", upper_us / 1e3);
  else std::snprintf(text, sizeof text, "%.0f ms", upper_us / 1e3);
  return text;
}

// status pose_latency.buckets ({upper_us, count}, non-empty, increasing) on
// one line: neighbouring buckets merged so at most kMaxGroups are shown, each
// as "<= its last bucket's bound: the count".
std::string buckets_text(const nlohmann::json& buckets) {
  constexpr std::size_t kMaxGroups = 12;
  std::vector<std::pair<double, std::uint64_t>> b;
  for (const nlohmann::json& e : buckets)
    if (e.is_object()) b.emplace_back(number_or_zero(e, "upper_us"), count_of(e, "count"));
  const std::size_t per_group = (b.size() + kMaxGroups - 1) / kMaxGroups;
  std::string out;
  for (std::size_t i = 0; i < b.size(); i += per_group) {
    const std::size_t end = std::min(b.size(), i + per_group);
    std::uint64_t n = 0;
    for (std::size_t k = i; k < end; ++k) n += b[k].second;
    out += (out.empty() ? "<= " : ", <= ") + bucket_bound_text(b[end - 1].first) + ": " + std::to_string(n);
  }
  return out;
}

}  // namespace

void print_status_summary(const nlohmann::json& status, std::ostream& out) {
  out << "scene " << text_of(status, "scene") << " (pid " << count_of(status, "pid") << ", up "
      << std::llround(number_or_zero(status, "uptime_s")) << " s): " << count_of(status, "samples_emitted")
      << " samples emitted, emitter "
      << (status.value("emitter_progressing", false) ? "progressing" : "NOT progressing") << "\n";
  const auto engine = status.find("engine");
  if (engine == status.end() || !engine->is_object()) {
    out << "  no emission engine running"
        << (status.value("waiting_for_device", false) ? " (waiting for a device to appear)" : "") << "\n";
    return;
  }
  out << "  emission delay " << number_or_zero(*engine, "emit_delay_ns") / 1e9
      << " s (trajectory time to wire time: the smoother's look-ahead plus margin for live input)\n";
  for (const nlohmann::json& d : engine->value("devices", nlohmann::json::array())) {
    const nlohmann::json samples = d.value("samples", nlohmann::json::object());
    const nlohmann::json lateness = d.value("lateness", nlohmann::json::object());
    const nlohmann::json transport = d.value("transport", nlohmann::json::object());
    out << "  " << text_of(d, "name") << " (" << text_of(d, "output") << ", " << count_of(d, "rate_hz")
        << " Hz): " << count_of(d, "emitted") << " of " << count_of(d, "ticks") << " ticks emitted ("
        << count_of(samples, "exact") << " exact, " << count_of(samples, "extrapolated") << " extrapolated, "
        << count_of(samples, "blending") << " blending back); " << count_of(d, "underruns")
        << " underruns (no sample ready at the deadline), " << count_of(d, "deadline_misses")
        << " deadline misses (woken more than one period late; " << count_of(d, "dropped_late") << " not sent)\n";
    out << "    lateness of the wake-up p50 " << microseconds(number_or_zero(lateness, "p50_ns")) << ", p99 "
        << microseconds(number_or_zero(lateness, "p99_ns")) << ", max "
        << microseconds(number_or_zero(lateness, "max_ns")) << "; smoother running "
        << number_or_zero(d, "engine_lag_ns") / 1e9 << " s ahead (newest knot minus newest sample ready)\n";
    const nlohmann::json pose_latency = d.value("pose_latency", nlohmann::json::object());
    if (count_of(pose_latency, "count") > 0)
      out << "    pose latency (arrival -> first dependent sample to the transport; " << count_of(pose_latency, "count")
          << " poses): p50 " << microseconds(number_or_zero(pose_latency, "p50_ns")) << ", p99 "
          << microseconds(number_or_zero(pose_latency, "p99_ns")) << ", max "
          << microseconds(number_or_zero(pose_latency, "max_ns")) << "\n";
    if (const auto b = pose_latency.find("buckets"); b != pose_latency.end() && b->is_array() && !b->empty())
      out << "      histogram (poses up to each bound): " << buckets_text(*b) << "\n";
    const nlohmann::json faults = d.value("faults", nlohmann::json::object());
    if (count_of(faults, "started") + count_of(faults, "injected") + count_of(faults, "active") > 0)
      out << "    faults: " << count_of(faults, "active") << " acting now, " << count_of(faults, "started")
          << " started and " << count_of(faults, "ended") << " ended (the fault log's events), "
          << count_of(faults, "injected") << " injected and " << count_of(faults, "cleared")
          << " cleared over the control socket, " << count_of(faults, "silenced")
          << " ticks silenced (device off), " << count_of(faults, "dropped_events")
          << " events lost (queue full)\n";
    out << "    transport: " << count_of(transport, "frames_sent") << " frames sent, "
        << count_of(transport, "queued") << " queued; not taken: "
        << count_of(d, "dropped_link_down") + count_of(d, "write_errors") << " packets ("
        << count_of(d, "dropped_link_down") << " dropped while the link was down: e.g. no reader on the pty; "
        << count_of(d, "write_errors") << " write errors: queue full "
        << count_of(transport, "dropped_queue_full") << ", refused by the kernel or invalid "
        << count_of(transport, "write_errors") << ")\n";
    if (count_of(transport, "input_bytes") > 0)
      out << "    input: " << count_of(transport, "input_bytes") << " bytes from the client ("
          << count_of(transport, "input_bytes_discarded") << " discarded: no device protocol reads them), "
          << count_of(transport, "replies_sent") << " replies sent, " << count_of(transport, "replies_dropped")
          << " dropped\n";
    // A device that answers its driver (issue 27): what its driver sent and
    // the settings it left.
    if (const auto c = d.find("commands"); c != d.end() && c->is_object())
      out << "    commands: " << count_of(*c, "received") << " received, " << count_of(*c, "answered")
          << " answered, " << count_of(*c, "nacked") << " NACKed, " << count_of(*c, "not_command_bytes")
          << " bytes that were not commands, " << count_of(*c, "replies_dropped") << " replies dropped; mode "
          << text_of(*c, "mode") << ", baud " << count_of(*c, "baud") << ", format " << text_of(*c, "format") << "\n";
  }
  if (const auto source = engine->find("pose_source"); source != engine->end() && source->is_object()) {
    out << "  pose source " << text_of(*source, "name") << ": " << count_of(*source, "accepted") << " accepted of "
        << count_of(*source, "received") << " received, " << count_of(*source, "lost") << " lost, "
        << count_of(*source, "out_of_order") << " out of order, " << count_of(*source, "duplicate")
        << " duplicates, " << count_of(*source, "rejected") << " rejected\n"
        << "    live time: " << count_of(*source, "resyncs")
        << " re-acquisitions (the sender's times jumped or restarted; the new stream placed on the running timeline), "
        << count_of(*source, "time_jump") << " stray poses dropped (far from the stream, never confirmed), "
        << count_of(*source, "held") << " held now (waiting for consistent poses)\n";
    // A MAVLink source takes one vehicle; the others' packets are dropped
    // (docs/pose-wire-format.md §4.5).
    if (text_of(*source, "name").rfind("mavlink", 0) == 0 && count_of(*source, "other_sender") > 0)
      out << "    other MAVLink senders: " << count_of(*source, "other_sender")
          << " packets dropped (this source takes one vehicle; the log names them)\n";
    // Connections are a TCP source's (one client at a time).
    if (text_of(*source, "name").rfind("tcp", 0) == 0)
      out << "    connections: " << count_of(*source, "connections") << " accepted, "
          << count_of(*source, "connections_refused") << " refused (slot taken), "
          << count_of(*source, "connections_idle_closed") << " closed idle (nothing within the idle timeout), "
          << count_of(*source, "connections_replaced") << " replaced (idle, taken over by a new client)\n";
  }
}

nlohmann::json query_control_socket(const std::string& socket_path, const std::string& command,
                                    std::chrono::milliseconds timeout) {
  if (command.empty() || command.size() >= service::kMaxCommandBytes || command.find('\n') != std::string::npos) {
    throw ControlClientError("control command must be one line of 1.." +
                             std::to_string(service::kMaxCommandBytes - 1) + " bytes");
  }
  asio::io_context io;
  stream_protocol::socket socket(io);
  // The timeout covers the connect too: a blocking connect() on a Unix socket
  // whose listen backlog is full (a stopped or hung daemon) waits forever.
  // Non-blocking, it fails with EAGAIN at once; retried until the deadline.
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  boost::system::error_code ec;
  socket.open();
  socket.non_blocking(true);
  for (;;) {
    socket.connect(stream_protocol::endpoint(socket_path), ec);
    if (ec != asio::error::would_block && ec != asio::error::try_again && ec != asio::error::in_progress &&
        ec != asio::error::no_buffer_space)  // ENOBUFS: the backlog is full too (Linux, non-blocking AF_UNIX)
      break;
    if (std::chrono::steady_clock::now() >= deadline)
      throw ControlClientError("cannot connect to control socket " + socket_path + " within " +
                               std::to_string(timeout.count()) +
                               " ms: its connection backlog is full (daemon stopped, hung or overloaded)");
    if (ec == asio::error::in_progress) {
      // Not for AF_UNIX on Linux, but POSIX allows it: wait until writable.
      socket.wait(stream_protocol::socket::wait_write, ec);
      int error = 0;
      socklen_t length = sizeof error;
      if (::getsockopt(socket.native_handle(), SOL_SOCKET, SO_ERROR, &error, &length) != 0) error = errno;
      ec = boost::system::error_code(error, boost::system::system_category());
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  if (ec) fail_connect(socket_path, ec);
  // Rounded up, never down: the reply gets the whole timeout, not 1 ms less.
  const auto left = std::chrono::ceil<std::chrono::milliseconds>(deadline - std::chrono::steady_clock::now());

  const std::string line = command + "\n";
  asio::streambuf reply(kMaxReplyBytes);
  boost::system::error_code read_ec;
  bool done = false;
  asio::async_write(socket, asio::buffer(line), [&](const boost::system::error_code& write_ec, std::size_t) {
    if (write_ec) {
      read_ec = write_ec;
      done = true;
      return;
    }
    // The daemon closes after its one reply: read to the end.
    asio::async_read(socket, reply, [&](const boost::system::error_code& e, std::size_t) {
      read_ec = e;
      done = true;
    });
  });
  io.run_for(std::max(left, std::chrono::milliseconds(1)));
  if (!done) {
    throw ControlClientError("imuemud did not respond on control socket " + socket_path + " within " +
                             std::to_string(timeout.count()) + " ms (daemon hung or overloaded)");
  }
  if (read_ec && read_ec != asio::error::eof) {
    throw ControlClientError("control socket " + socket_path + ": reading the reply failed: " + read_ec.message());
  }
  const std::string text{asio::buffers_begin(reply.data()), asio::buffers_end(reply.data())};
  if (text.empty()) throw ControlClientError("control socket " + socket_path + ": the daemon closed without a reply");
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::parse_error& e) {
    throw ControlClientError("control socket " + socket_path + ": the reply is not JSON (" + e.what() + ")");
  }
}

nlohmann::json query_control_socket(const std::string& socket_path, const std::string& command,
                                    const nlohmann::json& args, std::chrono::milliseconds timeout) {
  if (!args.is_object()) throw ControlClientError("control command arguments must be a JSON object");
  if (command.find_first_of(" \t") != std::string::npos)
    throw ControlClientError("control command name '" + command + "' has a blank");
  // Compact, and a newline inside a string is escaped: still one line.
  return query_control_socket(socket_path, command + " " + args.dump(-1, ' ', true), timeout);
}

int run_status(const StatusArgs& args) {
  if (!(args.timeout_s > 0.0) || !std::isfinite(args.timeout_s) || args.timeout_s > 3600.0) {
    std::cerr << "imuemu status: --timeout-s must be in (0, 3600]\n";
    return kUsageError;
  }
  const std::string path = args.socket_path.empty() ? service::find_control_socket(args.scene) : args.socket_path;
  const auto timeout = std::chrono::milliseconds(static_cast<std::int64_t>(std::llround(args.timeout_s * 1000.0)));
  try {
    const nlohmann::json reply = query_control_socket(path, args.command, timeout);
    if (args.summary && reply.is_object() && !reply.contains("error")) print_status_summary(reply, std::cout);
    else std::cout << reply.dump(args.compact ? -1 : 2) << '\n';
    if (reply.is_object() && reply.contains("error")) {
      std::cerr << "imuemu status: the daemon at " << path << " answered with an error: "
                << reply["error"].dump() << '\n';
      return kCannotProcess;
    }
    return kOk;
  } catch (const std::exception& e) {
    std::cerr << "imuemu status: " << e.what()
              << (args.socket_path.empty() ? " (looked at " + service::control_socket_places_text(args.scene) + ")" : "")
              << '\n';
    return kCannotProcess;
  }
}

void add_status_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<StatusArgs>();
  auto* cmd = app.add_subcommand("status", "Ask a running imuemud for its status (JSON) over its control socket");
  auto* socket_option = cmd->add_option("--socket", args->socket_path, "Control socket path (default /run/imuemu/SCENE.sock, else /tmp/imuemu/SCENE.sock: the first that exists)");
  cmd->add_option("--scene", args->scene, "Scene name, for the default socket path")->capture_default_str()->excludes(socket_option);
  cmd->add_option("--command", args->command,
                  "Command to send: status, help (lists what the daemon offers)")->capture_default_str();
  cmd->add_option("--timeout-s", args->timeout_s, "Give up when no reply comes within this")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS, true));
  auto* compact = cmd->add_flag("--compact", args->compact, "One-line JSON");
  cmd->add_flag("--summary", args->summary, "A few lines for a person (each counter explained) instead of the JSON")
      ->excludes(compact);
  cmd->callback([args, &exit_code] { exit_code = run_status(*args); });
}

}  // namespace imuemu::cli
