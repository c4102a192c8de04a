#include "daemon/service/control_socket.hpp"

#include <grp.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <mutex>
#include <utility>
#include <vector>

#include <boost/asio/buffers_iterator.hpp>
#include <boost/asio/read_until.hpp>
#include <boost/asio/steady_timer.hpp>
#include <boost/asio/streambuf.hpp>
#include <boost/asio/write.hpp>

#include "log/log.hpp"

namespace imuemu::service {

namespace asio = boost::asio;
using stream_protocol = asio::local::stream_protocol;

struct ControlServer::Shared {
  struct Command {
    std::string help;
    ControlCommandHandler handler;   // either this (no arguments)...
    ControlArgsHandler with_args;    // ...or this
  };
  std::mutex mutex;  // guards commands against add_command from another thread
  std::map<std::string, Command> commands;
  std::chrono::milliseconds client_timeout{2000};
  bool closed = false;  // set on the io thread (or after it stopped) by close()
  std::unique_ptr<asio::steady_timer> accept_retry;

  nlohmann::json run(const std::string& line) {
    ControlRequest request;
    try {
      request = parse_control_request(line);
    } catch (const std::exception& e) {
      return {{"error", e.what()}};
    }
    const std::string& command = request.name;
    Command found_command;
    {
      const std::lock_guard lock(mutex);
      if (command == "help") {
        nlohmann::json list = nlohmann::json::object();
        for (const auto& [name, c] : commands) list[name] = c.help;
        list["help"] = "this list";
        return {{"commands", list}};
      }
      const auto found = commands.find(command);
      if (found == commands.end()) {
        std::vector<std::string> names{"help"};
        for (const auto& [name, c] : commands) names.push_back(name);
        return {{"error", "unknown command '" + command + "'"}, {"commands", names}};
      }
      found_command = found->second;
    }
    if (request.has_args && !found_command.with_args) return {{"error", command + ": takes no arguments"}};
    try {
      return found_command.with_args ? found_command.with_args(request.args) : found_command.handler();
    } catch (const std::exception& e) {
      return {{"error", command + ": " + e.what()}};
    }
  }
};

namespace {

std::string errno_text(int err) { return std::strerror(err); }

// What the client sent, without the line end and surrounding blanks.
std::string trimmed_command(std::string line) {
  const auto not_blank = [](char c) { return c != ' ' && c != '\t' && c != '\r' && c != '\n'; };
  std::size_t begin = 0;
  while (begin < line.size() && !not_blank(line[begin])) ++begin;
  std::size_t end = line.size();
  while (end > begin && !not_blank(line[end - 1])) --end;
  return line.substr(begin, end - begin);
}

class Session : public std::enable_shared_from_this<Session> {
 public:
  Session(stream_protocol::socket socket, std::shared_ptr<ControlServer::Shared> shared)
      : socket_(std::move(socket)),
        // One byte more than a command may have, so an over-long line is
        // detected (read_until fails with not_found) instead of truncated.
        buffer_(kMaxCommandBytes + 1),
        deadline_(socket_.get_executor()),
        shared_(std::move(shared)) {}

  void start() {
    deadline_.expires_after(shared_->client_timeout);
    deadline_.async_wait([self = shared_from_this()](const boost::system::error_code& ec) {
      if (ec) return;  // cancelled: the reply went out
      boost::system::error_code ignored;
      self->socket_.close(ignored);  // aborts the pending read or write
    });
    asio::async_read_until(socket_, buffer_, '\n',
                           [self = shared_from_this()](const boost::system::error_code& ec, std::size_t) {
                             self->on_line(ec);
                           });
  }

 private:
  void on_line(const boost::system::error_code& ec) {
    if (ec == asio::error::operation_aborted || ec == asio::error::bad_descriptor) return;  // timed out
    if (ec == asio::error::not_found) {
      reply({{"error", "command longer than " + std::to_string(kMaxCommandBytes) + " bytes"}});
      return;
    }
    std::string line{asio::buffers_begin(buffer_.data()), asio::buffers_end(buffer_.data())};
    if (ec && !(ec == asio::error::eof && !line.empty())) {
      // Closed without a command (a probe such as the stale-socket check): nothing to answer.
      deadline_.cancel();
      return;
    }
    const std::size_t newline = line.find('\n');
    if (newline != std::string::npos) line.resize(newline);
    reply(shared_->run(line));
  }

  void reply(const nlohmann::json& document) {
    // dump() with replace: a handler's text with invalid UTF-8 must not throw here.
    reply_ = document.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace) + "\n";
    asio::async_write(socket_, asio::buffer(reply_),
                      [self = shared_from_this()](const boost::system::error_code&, std::size_t) {
                        self->deadline_.cancel();
                        boost::system::error_code ignored;
                        self->socket_.shutdown(stream_protocol::socket::shutdown_both, ignored);
                        self->socket_.close(ignored);
                      });
  }

  stream_protocol::socket socket_;
  asio::streambuf buffer_;
  asio::steady_timer deadline_;
  std::shared_ptr<ControlServer::Shared> shared_;
  std::string reply_;
};

gid_t resolve_group(const std::string& group, const std::string& path) {
  std::vector<char> storage(16384);
  struct group entry {};
  struct group* found = nullptr;
  int r = 0;
  while ((r = ::getgrnam_r(group.c_str(), &entry, storage.data(), storage.size(), &found)) == ERANGE &&
         storage.size() < (1u << 20)) {
    storage.resize(storage.size() * 4);  // a group with very many members
  }
  if (r != 0) {
    throw ControlSocketError("control socket " + path + ": cannot look up group '" + group + "': " + errno_text(r));
  }
  if (found == nullptr) {
    throw ControlSocketError("control socket " + path + ": group '" + group +
                             "' does not exist (create it, e.g. with systemd-sysusers and "
                             "imuemu.sysusers.conf, or leave control_group empty)");
  }
  return found->gr_gid;
}

// Is a daemon answering on `path`? true: yes; false: nothing listens (stale).
bool someone_listens_on(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (fd < 0) throw ControlSocketError("control socket " + path + ": socket(): " + errno_text(errno));
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::memcpy(address.sun_path, path.c_str(), path.size() + 1);
  const int r = ::connect(fd, reinterpret_cast<const sockaddr*>(&address), sizeof address);
  const int err = errno;
  ::close(fd);
  if (r == 0) return true;
  if (err == ECONNREFUSED || err == ENOENT) return false;
  throw ControlSocketError("control socket " + path + ": cannot check whether the existing socket is in use: " +
                           errno_text(err));
}

}  // namespace

ControlRequest parse_control_request(const std::string& line) {
  const std::string text = trimmed_command(line);
  ControlRequest request;
  const std::size_t blank = text.find_first_of(" \t");
  request.name = text.substr(0, blank);
  if (blank == std::string::npos) return request;
  const std::string rest = trimmed_command(text.substr(blank));
  if (rest.empty()) return request;
  request.has_args = true;
  nlohmann::json args;
  try {
    args = nlohmann::json::parse(rest);
  } catch (const nlohmann::json::parse_error& e) {
    throw std::invalid_argument(request.name + ": the arguments are not JSON (" + e.what() + ")");
  } catch (const nlohmann::json::exception& e) {
    // A number beyond a double (1e400) is an out_of_range, not a parse
    // error (issue 26 N17: it reached the client as a raw json exception).
    std::string what = e.what();
    if (const auto end = what.find("] "); what.rfind("[json.exception", 0) == 0 && end != std::string::npos)
      what.erase(0, end + 2);
    throw std::invalid_argument(request.name + ": a number in the arguments is beyond the range of a double (" + what +
                                "); times are seconds, at most 9e9");
  }
  if (!args.is_object())
    throw std::invalid_argument(request.name + ": the arguments must be one JSON object, got " + std::string(args.type_name()));
  request.args = std::move(args);
  return request;
}

std::string default_control_socket_path(const std::string& scene_name) {
  return "/run/imuemu/" + scene_name + ".sock";
}

std::vector<std::string> default_control_socket_paths(const std::string& scene_name) {
  // The second is the built-in scene's [daemon] control_socket
  // (daemon/scene/default_scene.cpp, config/default.toml) for its name.
  return {default_control_socket_path(scene_name), "/tmp/imuemu/" + scene_name + ".sock"};
}

std::string find_control_socket(const std::string& scene_name) {
  const std::vector<std::string> paths = default_control_socket_paths(scene_name);
  for (const std::string& p : paths) {
    struct stat st {};
    if (::stat(p.c_str(), &st) == 0 && S_ISSOCK(st.st_mode)) return p;
  }
  return paths.front();
}

std::string control_socket_places_text(const std::string& scene_name) {
  const std::vector<std::string> paths = default_control_socket_paths(scene_name);
  std::string text;
  for (std::size_t i = 0; i < paths.size(); ++i) text += (i == 0 ? "" : " or ") + paths[i];
  return text;
}

ControlServer::ControlServer(asio::io_context& io, ControlSocketOptions options)
    : options_(std::move(options)), acceptor_(io), shared_(std::make_shared<Shared>()) {
  const std::string& path = options_.path;
  if (path.empty()) throw ControlSocketError("control socket: empty path");
  if (path.size() >= sizeof(sockaddr_un::sun_path)) {
    throw ControlSocketError("control socket " + path + ": path longer than " +
                             std::to_string(sizeof(sockaddr_un::sun_path) - 1) + " bytes (AF_UNIX limit)");
  }
  if (options_.client_timeout.count() <= 0) throw ControlSocketError("control socket " + path + ": client timeout must be > 0");
  shared_->client_timeout = options_.client_timeout;

  const std::filesystem::path parent = std::filesystem::path(path).parent_path();
  std::error_code fs_error;
  if (!parent.empty() && !std::filesystem::is_directory(parent, fs_error)) {
    throw ControlSocketError("control socket " + path + ": directory " + parent.string() + " does not exist");
  }
  // The group first: a typo must not leave a socket file behind.
  const bool chown_to_group = !options_.group.empty();
  const gid_t gid = chown_to_group ? resolve_group(options_.group, path) : gid_t{0};

  struct stat existing {};
  if (::lstat(path.c_str(), &existing) == 0) {
    if (!S_ISSOCK(existing.st_mode)) {
      throw ControlSocketError("control socket " + path + ": exists and is not a socket; refusing to replace it");
    }
    if (someone_listens_on(path)) {
      throw ControlSocketError("control socket " + path + ": another process is serving it (a second imuemud for the same scene?)");
    }
    if (::unlink(path.c_str()) != 0 && errno != ENOENT) {
      throw ControlSocketError("control socket " + path + ": cannot remove the stale socket file: " + errno_text(errno));
    }
    log_info("control socket " + path + ": removed a stale socket file");
  }

  boost::system::error_code ec;
  acceptor_.open(stream_protocol(), ec);
  if (!ec) acceptor_.bind(stream_protocol::endpoint(path), ec);
  if (ec) throw ControlSocketError("control socket " + path + ": cannot create it: " + ec.message());
  // Permissions before listen(): until then a connect() is refused, so no
  // client ever reaches the socket with the wider mode bind() left.
  const auto fail_and_remove = [&](const std::string& what) {
    ::unlink(path.c_str());
    throw ControlSocketError("control socket " + path + ": " + what);
  };
  if (chown_to_group && ::chown(path.c_str(), static_cast<uid_t>(-1), gid) != 0) {
    fail_and_remove("cannot give it to group '" + options_.group + "': " + errno_text(errno) +
                    " (the daemon's user must be a member of that group)");
  }
  if (::chmod(path.c_str(), 0660) != 0) fail_and_remove("cannot set mode 0660: " + errno_text(errno));
  acceptor_.listen(asio::socket_base::max_listen_connections, ec);
  if (ec) fail_and_remove("listen(): " + ec.message());
  open_ = true;
  accept_next();
}

ControlServer::~ControlServer() { close(); }

void ControlServer::add_command(const std::string& name, const std::string& help, ControlCommandHandler handler) {
  const std::lock_guard lock(shared_->mutex);
  shared_->commands[name] = Shared::Command{help, std::move(handler), {}};
}

void ControlServer::add_command_with_args(const std::string& name, const std::string& help, ControlArgsHandler handler) {
  const std::lock_guard lock(shared_->mutex);
  shared_->commands[name] = Shared::Command{help, {}, std::move(handler)};
}

void ControlServer::close() {
  if (!open_) return;
  open_ = false;
  shared_->closed = true;
  if (shared_->accept_retry) shared_->accept_retry->cancel();
  boost::system::error_code ignored;
  acceptor_.close(ignored);
  ::unlink(options_.path.c_str());
}

void ControlServer::accept_next() {
  acceptor_.async_accept([this, shared = shared_](const boost::system::error_code& ec, stream_protocol::socket socket) {
    // `closed` first: after close() (and perhaps destruction) `this` is not touched.
    if (shared->closed) return;
    if (!ec) {
      std::make_shared<Session>(std::move(socket), shared)->start();
      accept_next();
      return;
    }
    // Out of file descriptors and the like: wait a little instead of spinning.
    log_warning("control socket " + options_.path + ": accept failed: " + ec.message());
    if (!shared->accept_retry) shared->accept_retry = std::make_unique<asio::steady_timer>(acceptor_.get_executor());
    shared->accept_retry->expires_after(std::chrono::milliseconds(100));
    shared->accept_retry->async_wait([this, shared](const boost::system::error_code& wait_ec) {
      if (wait_ec || shared->closed) return;
      accept_next();
    });
  });
}

}  // namespace imuemu::service
