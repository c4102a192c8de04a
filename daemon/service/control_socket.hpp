// imuemud's control socket: a Unix stream socket served from Boost.Asio on
// the daemon's service io_context (never the emission thread). A client
// connects, sends ONE line ("\n"-terminated, at most kMaxCommandBytes): a
// command name, optionally followed by blanks and ONE JSON object with the
// command's arguments (`fault-inject {"imu": "imu0", "type": "dead"}`), and
// receives ONE JSON document followed by "\n", then the daemon closes the
// connection. Protocol documented in docs/daemon.md.
//
// Commands are registered by the daemon (status, fault-*, test hooks);
// an unknown command gets {"error": "...", "commands": [...]}, arguments
// that are not one JSON object, or arguments to a command that takes none,
// get {"error": "<command>: ..."} and the handler is not called; a handler
// that throws gets {"error": "<command>: <what>"} (a handler that refuses
// its arguments throws before changing anything). A client that sends
// nothing, too much or no newline within the client timeout is dropped; it
// never blocks other clients (every connection is asynchronous).
//
// The socket file is created with mode 0660 (owner and group only) and, when
// a group is named, chowned to that group before listen(), so no one can
// connect before the permissions are final. A stale socket file (nothing
// listening on it) is removed at start; a live one is an error (another
// daemon serves that path). The file is removed when the server closes.
#pragma once

#include <chrono>
#include <cstddef>
#include <functional>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>

#include <boost/asio/io_context.hpp>
#include <boost/asio/local/stream_protocol.hpp>
#include <nlohmann/json.hpp>

#include "daemon/service/imuemud.hpp"

namespace imuemu::service {

// kMaxCommandBytes and default_control_socket_path(): daemon/service/imuemud.hpp
// (the room's public header, what the command-line tool uses).

// Setting up the socket failed; the message names the path or the group.
class ControlSocketError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct ControlSocketOptions {
  std::string path;
  std::string group;  // empty: the daemon's own group
  std::chrono::milliseconds client_timeout{2000};  // to send the command line and take the reply
};

// Runs on the io_context's thread; must not block (read atomics, copy a
// snapshot under a short lock).
using ControlCommandHandler = std::function<nlohmann::json()>;
// A command with arguments: the JSON object after the name ({} when the line
// has only the name). Throw std::invalid_argument (or any std::exception) to
// refuse them; the client gets {"error": "<command>: <what>"}.
using ControlArgsHandler = std::function<nlohmann::json(const nlohmann::json& args)>;

// One request line split: the command name and its arguments (an object, {}
// when none). Throws std::invalid_argument when the text after the name is
// not one JSON object. Leading/trailing blanks and CR are ignored.
struct ControlRequest {
  std::string name;
  nlohmann::json args = nlohmann::json::object();
  bool has_args = false;  // the line had text after the name
};
ControlRequest parse_control_request(const std::string& line);

class ControlServer {
 public:
  // Creates, secures and listens on the socket, and starts accepting; throws
  // ControlSocketError. Connections are served while `io` runs.
  ControlServer(boost::asio::io_context& io, ControlSocketOptions options);
  // Closes and removes the socket file. Call on the io_context's thread or
  // after it stopped (the usual order: io.stop(), join, destroy).
  ~ControlServer();
  ControlServer(const ControlServer&) = delete;
  ControlServer& operator=(const ControlServer&) = delete;

  // Registers (or replaces) a command. `help` is listed in "help"'s reply.
  // Register before clients may call it, or from the io_context's thread.
  // A command registered this way takes no arguments: a line with arguments
  // is refused with an error (nothing is called).
  void add_command(const std::string& name, const std::string& help, ControlCommandHandler handler);
  void add_command_with_args(const std::string& name, const std::string& help, ControlArgsHandler handler);

  const std::string& path() const { return options_.path; }
  void close();  // stop accepting, remove the socket file; idempotent

  struct Shared;  // state the connections share (outlives `this` if they do)

 private:
  void accept_next();

  ControlSocketOptions options_;
  boost::asio::local::stream_protocol::acceptor acceptor_;
  std::shared_ptr<Shared> shared_;
  bool open_ = false;
};

}  // namespace imuemu::service
