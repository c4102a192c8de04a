// daemon/control_socket (server) and daemon/status_command (client and
// `imuemu status`): one line in, one JSON document out; 0660 permissions and
// group; stale/live/foreign files at the path; slow and garbage clients do
// not block others; every client error names the socket path.
#include <gtest/gtest.h>

#include <grp.h>
#include <stdlib.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>
#include <vector>

#include <boost/asio/executor_work_guard.hpp>
#include <boost/asio/io_context.hpp>
#include <boost/asio/post.hpp>
#include <nlohmann/json.hpp>

#include "daemon/scene/default_scene.hpp"
#include "daemon/scene/scene_config.hpp"
#include "daemon/service/control_socket.hpp"
#include "daemon/service/imuemud.hpp"
#include "daemon/engine/emission.hpp"
#include "log/log.hpp"
#include "tests/support/io_thread.hpp"
#include "daemon/cli/status_command.hpp"

// This file's own namespace: tests compile as unity batches (tests/CMakeLists.txt).
namespace imuemu {}
namespace unity_service_test_control_socket {
namespace imuemu { using namespace ::imuemu; }

namespace svc = imuemu::service;
using imuemu::test::IoThread;
using imuemu::test::TempDir;
using imuemu::cli::ControlClientError;
using imuemu::cli::query_control_socket;
using nlohmann::json;
using namespace std::chrono_literals;

namespace {



// A daemon with a status counter, served on its own io thread.
struct Daemon {
  explicit Daemon(const std::string& path, const std::string& group = "", std::chrono::milliseconds timeout = 2000ms) {
    svc::set_log_threshold(svc::LogLevel::warning);
    io.run([&] {
      server.emplace(io.io, svc::ControlSocketOptions{path, group, timeout});
      server->add_command("status", "counters", [this] {
        return json{{"samples_emitted", samples.load()}, {"scene", "bench"}};
      });
      server->add_command("stats-reset", "zero the counters", [this] {
        samples = 0;
        return json{{"reset", true}};
      });
      server->add_command("explode", "throws", []() -> json { throw std::runtime_error("boom"); });
      // Takes {"add": n}: refuses anything else before changing the counter.
      server->add_command_with_args("add", "adds to the counter", [this](const json& args) {
        const auto add = args.find("add");
        if (add == args.end() || !add->is_number_unsigned())
          throw std::invalid_argument("expected {\"add\": unsigned}, got " + args.dump());
        samples += add->get<std::uint64_t>();
        return json{{"samples_emitted", samples.load()}, {"args", args}};
      });
    });
  }
  ~Daemon() { io.run([&] { server.reset(); }); }
  IoThread io;
  std::optional<svc::ControlServer> server;
  std::atomic<std::uint64_t> samples{12345};
};

int connect_raw(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::strncpy(address.sun_path, path.c_str(), sizeof address.sun_path - 1);
  if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// A socket file nothing listens on: what a killed daemon leaves behind.
void make_stale_socket(const std::string& path) {
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::strncpy(address.sun_path, path.c_str(), sizeof address.sun_path - 1);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  ::close(fd);
}

std::string read_all(int fd) {
  std::string out;
  char buffer[4096];
  ssize_t n;
  while ((n = ::read(fd, buffer, sizeof buffer)) > 0) out.append(buffer, static_cast<std::size_t>(n));
  return out;
}

std::string error_of(const std::string& path, const std::string& command, std::chrono::milliseconds timeout) {
  try {
    query_control_socket(path, command, timeout);
  } catch (const ControlClientError& e) {
    return e.what();
  }
  return "(no error)";
}

struct ShellRun {
  int exit_code;
  std::string out;
};
ShellRun run_shell(const std::string& command) {
  FILE* p = ::popen(command.c_str(), "r");
  std::string out;
  std::array<char, 4096> buffer{};
  std::size_t n;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), p)) > 0) out.append(buffer.data(), n);
  const int status = ::pclose(p);
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, out};
}

}  // namespace

TEST(ControlSocket, StatusReplyIsTheProvidersJson) {
  TempDir dir;
  const std::string path = dir.path + "/bench.sock";
  Daemon daemon(path);
  const json reply = query_control_socket(path, "status", 2000ms);
  EXPECT_EQ(reply, (json{{"samples_emitted", 12345}, {"scene", "bench"}}));
  daemon.samples = 7;
  EXPECT_EQ(query_control_socket(path, "status", 2000ms)["samples_emitted"], 7);
  EXPECT_EQ(query_control_socket(path, "stats-reset", 2000ms), (json{{"reset", true}}));
  EXPECT_EQ(daemon.samples.load(), 0u);
  const json help = query_control_socket(path, "help", 2000ms);
  EXPECT_EQ(help["commands"]["status"], "counters");
}

TEST(ControlSocket, UnknownCommandAndThrowingHandlerAnswerWithErrors) {
  TempDir dir;
  const std::string path = dir.path + "/s.sock";
  Daemon daemon(path);
  const json unknown = query_control_socket(path, "self-destruct", 2000ms);
  EXPECT_EQ(unknown["error"], "unknown command 'self-destruct'");
  EXPECT_EQ(unknown["commands"], (json{"help", "add", "explode", "stats-reset", "status"}));
  EXPECT_EQ(query_control_socket(path, "explode", 2000ms), (json{{"error", "explode: boom"}}));
  // Blanks and CRLF around the command are not part of it.
  const int fd = connect_raw(path);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::write(fd, "  status\r\n", 10), 10);
  EXPECT_EQ(json::parse(read_all(fd))["scene"], "bench");
  ::close(fd);
}

TEST(ControlSocket, ArgumentsAreOneJsonObjectAfterTheName) {
  TempDir dir;
  const std::string path = dir.path + "/args.sock";
  Daemon daemon(path);
  daemon.samples = 10;
  const json reply = query_control_socket(path, "add", json{{"add", 5}}, 2000ms);
  EXPECT_EQ(reply["samples_emitted"], 15);
  EXPECT_EQ(reply["args"], (json{{"add", 5}}));
  // Raw line with blanks around the name and the object, CRLF.
  const int fd = connect_raw(path);
  ASSERT_GE(fd, 0);
  const std::string line = "  add \t {\"add\": 2}  \r\n";
  ASSERT_EQ(::write(fd, line.data(), line.size()), static_cast<ssize_t>(line.size()));
  EXPECT_EQ(json::parse(read_all(fd))["samples_emitted"], 17);
  ::close(fd);
  // The name alone: the handler gets {} (and refuses it here).
  EXPECT_EQ(query_control_socket(path, "add", 2000ms)["error"], "add: expected {\"add\": unsigned}, got {}");
  // Refused arguments change nothing.
  EXPECT_EQ(query_control_socket(path, "add {\"add\": -3}", 2000ms)["error"],
            "add: expected {\"add\": unsigned}, got {\"add\":-3}");
  const json not_json = query_control_socket(path, "add {add: 1}", 2000ms);
  EXPECT_NE(not_json["error"].get<std::string>().find("add: the arguments are not JSON"), std::string::npos) << not_json;
  EXPECT_EQ(query_control_socket(path, "add [1, 2]", 2000ms)["error"],
            "add: the arguments must be one JSON object, got array");
  EXPECT_EQ(query_control_socket(path, "add {\"add\": 1} {\"add\": 1}", 2000ms).count("error"), 1u);
  // A command without arguments refuses them (it is not called).
  EXPECT_EQ(query_control_socket(path, "stats-reset {}", 2000ms)["error"], "stats-reset: takes no arguments");
  EXPECT_EQ(query_control_socket(path, "stats-reset now", 2000ms)["error"].get<std::string>().find("stats-reset: "), 0u);
  EXPECT_EQ(daemon.samples.load(), 17u);
  // A line up to kMaxCommandBytes (newline excluded) is taken whole.
  json big{{"add", 1}, {"pad", ""}};
  const std::size_t base = std::string("add ").size() + big.dump().size();
  big["pad"] = std::string(svc::kMaxCommandBytes - 1 - base, 'x');
  EXPECT_EQ(query_control_socket(path, "add", big, 2000ms)["samples_emitted"], 18);
  // The client refuses a line that does not fit, sending nothing.
  big["pad"] = std::string(svc::kMaxCommandBytes, 'x');
  EXPECT_THROW(query_control_socket(path, "add", big, 2000ms), ControlClientError);
  EXPECT_THROW(query_control_socket(path, "two words", json::object(), 2000ms), ControlClientError);
  EXPECT_EQ(daemon.samples.load(), 18u);
}

TEST(ControlSocket, ParseControlRequestSplitsNameAndArguments) {
  EXPECT_EQ(svc::parse_control_request("status").name, "status");
  EXPECT_FALSE(svc::parse_control_request(" status \r\n").has_args);
  EXPECT_EQ(svc::parse_control_request(" status \r\n").args, json::object());
  const svc::ControlRequest r = svc::parse_control_request("fault-inject {\"imu\": \"imu0\", \"type\": \"dead\"}");
  EXPECT_EQ(r.name, "fault-inject");
  EXPECT_TRUE(r.has_args);
  EXPECT_EQ(r.args, (json{{"imu", "imu0"}, {"type", "dead"}}));
  EXPECT_THROW(svc::parse_control_request("x 1"), std::invalid_argument);
  EXPECT_THROW(svc::parse_control_request("x \"s\""), std::invalid_argument);
  EXPECT_THROW(svc::parse_control_request("x {"), std::invalid_argument);
}

// Issue 18: the socket's 0660 mode is what keeps fault injection to its
// group. A process that is neither the owner nor in the group gets EACCES
// from connect(2) itself (path permission check, Linux unix(7)). Needs root
// to become another user; as a normal user the test cannot switch identity.
TEST(ControlSocket, AClientOutsideTheGroupIsRefusedByTheKernel) {
  if (::geteuid() != 0) GTEST_SKIP() << "needs root to switch to uid/gid 65534";
  TempDir dir;
  ::chmod(dir.path.c_str(), 0755);  // the directory is searchable: only the socket's mode decides
  const std::string path = dir.path + "/perm.sock";
  Daemon daemon(path);
  struct stat st {};
  ASSERT_EQ(::stat(path.c_str(), &st), 0);
  ASSERT_NE(st.st_gid, 65534u) << "the socket's group must not be nogroup for this test";
  ASSERT_EQ(st.st_mode & 0777, 0660u);
  // The child reports connect()'s errno (0: connected) through a pipe.
  const auto connect_as = [&](uid_t uid, gid_t gid) -> int {
    int fds[2];
    if (::pipe(fds) != 0) return -1;
    const pid_t child = ::fork();
    if (child == 0) {
      ::close(fds[0]);
      int result = 0;
      const gid_t none[1] = {gid};
      if (::setgroups(1, none) != 0 || ::setgid(gid) != 0 || ::setuid(uid) != 0) {
        result = -2;
      } else {
        const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
        sockaddr_un address{};
        address.sun_family = AF_UNIX;
        std::strncpy(address.sun_path, path.c_str(), sizeof address.sun_path - 1);
        result = ::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0 ? 0 : errno;
      }
      (void)!::write(fds[1], &result, sizeof result);
      ::_exit(0);
    }
    ::close(fds[1]);
    int result = -1;
    if (::read(fds[0], &result, sizeof result) != static_cast<ssize_t>(sizeof result)) result = -3;
    ::close(fds[0]);
    int status = 0;
    ::waitpid(child, &status, 0);
    return result;
  };
  EXPECT_EQ(connect_as(65534, 65534), EACCES);
  // The same identity in the socket's group is let in: the refusal is the
  // group's, not something else about the child.
  EXPECT_EQ(connect_as(65534, st.st_gid), 0);
  EXPECT_EQ(query_control_socket(path, "status", 2000ms)["scene"], "bench");  // the daemon is unaffected
}

TEST(ControlSocket, Mode0660AndGroupAndRemovedAtExit) {
  TempDir dir;
  const std::string path = dir.path + "/p.sock";
  const struct group* own = ::getgrgid(::getegid());
  ASSERT_NE(own, nullptr);
  {
    ::umask(0);  // bind() would leave 0777: the server must narrow it itself
    Daemon daemon(path, own->gr_name);
    ::umask(022);
    struct stat st {};
    ASSERT_EQ(::stat(path.c_str(), &st), 0);
    EXPECT_TRUE(S_ISSOCK(st.st_mode));
    EXPECT_EQ(st.st_mode & 07777, 0660u);
    EXPECT_EQ(st.st_gid, ::getegid());
  }
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(ControlSocket, MissingGroupIsAClearErrorAndLeavesNoFile) {
  TempDir dir;
  const std::string path = dir.path + "/g.sock";
  boost::asio::io_context io;
  try {
    svc::ControlServer server(io, {path, "imuemu-no-such-group", 1000ms});
    FAIL() << "expected ControlSocketError";
  } catch (const svc::ControlSocketError& e) {
    EXPECT_NE(std::string(e.what()).find("group 'imuemu-no-such-group' does not exist"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(path));
}

TEST(ControlSocket, StaleSocketReplacedLiveOneAndOtherFilesRefused) {
  TempDir dir;
  const std::string path = dir.path + "/x.sock";
  make_stale_socket(path);
  ASSERT_TRUE(std::filesystem::is_socket(path));
  Daemon daemon(path);
  EXPECT_EQ(query_control_socket(path, "status", 2000ms)["scene"], "bench");

  boost::asio::io_context io;
  try {
    svc::ControlServer second(io, {path, "", 1000ms});
    FAIL() << "a live socket must not be taken over";
  } catch (const svc::ControlSocketError& e) {
    EXPECT_NE(std::string(e.what()).find("another process is serving it"), std::string::npos) << e.what();
  }
  EXPECT_EQ(query_control_socket(path, "status", 2000ms)["scene"], "bench");  // still served

  const std::string regular = dir.path + "/notes.txt";
  std::ofstream(regular) << "keep me";
  EXPECT_THROW(svc::ControlServer(io, {regular, "", 1000ms}), svc::ControlSocketError);
  EXPECT_TRUE(std::filesystem::is_regular_file(regular));
  EXPECT_THROW(svc::ControlServer(io, {dir.path + "/no/such/dir.sock", "", 1000ms}), svc::ControlSocketError);
  EXPECT_THROW(svc::ControlServer(io, {dir.path + "/" + std::string(120, 'a'), "", 1000ms}), svc::ControlSocketError);
}

TEST(ControlSocket, SlowAndGarbageClientsDoNotBlockOthers) {
  TempDir dir;
  const std::string path = dir.path + "/slow.sock";
  Daemon daemon(path, "", 1500ms);
  // Silent client, and one that sends half a command and stalls.
  const int silent = connect_raw(path);
  const int half = connect_raw(path);
  ASSERT_GE(silent, 0);
  ASSERT_GE(half, 0);
  ASSERT_EQ(::write(half, "sta", 3), 3);
  // Others are served at once meanwhile.
  const auto t0 = std::chrono::steady_clock::now();
  for (int i = 0; i < 20; ++i) EXPECT_EQ(query_control_socket(path, "status", 2000ms)["scene"], "bench");
  // A server that served one client at a time would wait for the silent ones
  // to time out (1.5 s) before answering anyone.
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 1000ms);
  // Over-long garbage: an error reply, not a hang or a crash.
  const int garbage = connect_raw(path);
  const std::string junk(5000, '\x7f');
  ASSERT_EQ(::write(garbage, junk.data(), junk.size()), static_cast<ssize_t>(junk.size()));
  EXPECT_EQ(json::parse(read_all(garbage))["error"], "command longer than 4096 bytes");
  ::close(garbage);
  // Binary garbage on one line: unknown command (bytes replaced in the JSON text).
  const int binary = connect_raw(path);
  ASSERT_EQ(::write(binary, "\xff\xfe\x01\n", 4), 4);
  EXPECT_TRUE(json::parse(read_all(binary)).contains("error"));
  ::close(binary);
  // The stalled clients are dropped after the client timeout (EOF, no reply).
  const auto t1 = std::chrono::steady_clock::now();
  EXPECT_EQ(read_all(silent), "");
  EXPECT_EQ(read_all(half), "");
  EXPECT_LT(std::chrono::steady_clock::now() - t1, 3000ms);
  ::close(silent);
  ::close(half);
  EXPECT_EQ(query_control_socket(path, "status", 2000ms)["scene"], "bench");
}

TEST(ControlClient, ErrorsNameTheSocketAndTheCause) {
  TempDir dir;
  const std::string missing = dir.path + "/missing.sock";
  std::string e = error_of(missing, "status", 500ms);
  EXPECT_NE(e.find("no control socket at " + missing), std::string::npos) << e;

  const std::string stale = dir.path + "/stale.sock";
  make_stale_socket(stale);
  e = error_of(stale, "status", 500ms);
  EXPECT_NE(e.find("nothing is listening on control socket " + stale), std::string::npos) << e;

  // A hung daemon: the kernel accepts into the backlog, nobody answers.
  const std::string hung = dir.path + "/hung.sock";
  const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::strncpy(address.sun_path, hung.c_str(), sizeof address.sun_path - 1);
  ASSERT_EQ(::bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  ASSERT_EQ(::listen(fd, 4), 0);
  const auto t0 = std::chrono::steady_clock::now();
  e = error_of(hung, "status", 300ms);
  const auto waited = std::chrono::steady_clock::now() - t0;
  EXPECT_NE(e.find("did not respond on control socket " + hung + " within 300 ms"), std::string::npos) << e;
  EXPECT_GE(waited, 300ms);
  EXPECT_LT(waited, 1500ms);
  ::close(fd);

  EXPECT_NE(error_of(hung, "two\nlines", 300ms).find("one line"), std::string::npos);
}

TEST(ControlClient, PermissionDeniedNamesTheGroup) {
  TempDir dir;
  ::chmod(dir.path.c_str(), 0755);
  const std::string path = dir.path + "/perm.sock";
  Daemon daemon(path);
  const struct group* own = ::getgrgid(::getegid());
  ASSERT_NE(own, nullptr);
  std::string e;
  if (::geteuid() == 0) {
    // root passes any mode check: ask as nobody, through the real command.
    const ShellRun r = run_shell("setpriv --reuid=65534 --regid=65534 --clear-groups " + std::string(IMUEMU_CLI_PATH) +
                            " status --socket " + path + " 2>&1");
    EXPECT_EQ(r.exit_code, 4);
    e = r.out;
  } else {
    ::chmod(path.c_str(), 0);
    e = error_of(path, "status", 500ms);
  }
  EXPECT_NE(e.find("permission denied on control socket " + path), std::string::npos) << e;
  EXPECT_NE(e.find(std::string("group '") + own->gr_name + "'"), std::string::npos) << e;
}

TEST(StatusCommand, PrintsPrettyJsonAndExitCodes) {
  TempDir dir;
  const std::string path = dir.path + "/cli.sock";
  Daemon daemon(path);
  const std::string cli = IMUEMU_CLI_PATH;
  ShellRun r = run_shell(cli + " status --socket " + path);
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(json::parse(r.out), (json{{"samples_emitted", 12345}, {"scene", "bench"}}));
  EXPECT_NE(r.out.find("\n  \"s"), std::string::npos) << "pretty, indented: " << r.out;
  r = run_shell(cli + " status --compact --socket " + path);
  EXPECT_EQ(r.out, "{\"samples_emitted\":12345,\"scene\":\"bench\"}\n");
  r = run_shell(cli + " status --socket " + path + " --command nope 2>&1");
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.out.find("answered with an error"), std::string::npos) << r.out;
  r = run_shell(cli + " status --socket " + dir.path + "/none.sock 2>&1");
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.out.find("imuemu status: no control socket at " + dir.path + "/none.sock"), std::string::npos) << r.out;
  r = run_shell(cli + " status --scene no-such-scene-xyz 2>&1");
  EXPECT_NE(r.out.find("/run/imuemu/no-such-scene-xyz.sock"), std::string::npos) << r.out;
  r = run_shell(cli + " status --socket " + path + " --timeout-s 0 2>&1");
  EXPECT_EQ(r.exit_code, 2);
}

// `imuemu status --summary`: the lines a person reads, from the JSON the
// daemon's own serialiser (emission::to_json) writes, each number where its
// explanation says.
// `imuemu fault`: the command line becomes one request line with a JSON
// object; the daemon's reply is printed; its error is the exit code 4 with
// the daemon's message; a bad command line is 2 and sends nothing.
TEST(FaultCommand, SendsTheRequestAndReportsTheDaemonsAnswer) {
  TempDir dir;
  const std::string path = dir.path + "/fault.sock";
  Daemon daemon(path);
  std::vector<std::pair<std::string, json>> seen;
  std::mutex seen_mutex;
  daemon.io.run([&] {
    for (const char* name : {"fault-inject", "fault-list", "fault-clear"}) {
      daemon.server->add_command_with_args(name, "echo", [&, name = std::string(name)](const json& args) -> json {
        {
          std::lock_guard lock(seen_mutex);
          seen.emplace_back(name, args);
        }
        if (args.value("imu", "") == "nope") throw std::invalid_argument("no imu 'nope' in this scene");
        return json{{"ok", name}};
      });
    }
  });
  const std::string cli = std::string(IMUEMU_CLI_PATH) + " fault ";
  ShellRun r = run_shell(cli + "inject --socket " + path +
                         " --imu imu0 --type bias_step --after-s 0.5 --duration-s 2 --param gyro_bias_rad_s=0.01"
                         " --param axes=xz --param flag_status=true --param seed=7 --compact");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_EQ(r.out, "{\"ok\":\"fault-inject\"}\n");
  r = run_shell(cli + "list --socket " + path + " --compact");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  r = run_shell(cli + "clear --socket " + path + " --imu imu0 --id 3 --compact");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  r = run_shell(cli + "clear --socket " + path + " --imu imu0 --all --compact");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  r = run_shell(cli + "clear --socket " + path + " --imu nope --all 2>&1 >/dev/null");
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_NE(r.out.find("imuemu fault clear: the daemon at " + path + " refused: fault-clear: no imu 'nope' in this scene"),
            std::string::npos) << r.out;
  {
    std::lock_guard lock(seen_mutex);
    ASSERT_EQ(seen.size(), 5u);
    EXPECT_EQ(seen[0].first, "fault-inject");
    EXPECT_EQ(seen[0].second, (json{{"imu", "imu0"}, {"type", "bias_step"}, {"after_s", 0.5}, {"duration_s", 2.0},
                                    {"params", {{"gyro_bias_rad_s", 0.01}, {"axes", "xz"}, {"flag_status", true}, {"seed", 7}}}}));
    EXPECT_EQ(seen[1], (std::pair<std::string, json>{"fault-list", json::object()}));
    EXPECT_EQ(seen[2], (std::pair<std::string, json>{"fault-clear", {{"imu", "imu0"}, {"id", 3}}}));
    EXPECT_EQ(seen[3], (std::pair<std::string, json>{"fault-clear", {{"imu", "imu0"}, {"all", true}}}));
  }
  // Usage errors: nothing is sent.
  for (const std::string bad : {"inject --imu imu0 --type dead --param novalue", "clear --imu imu0",
                                "clear --imu imu0 --id 1 --all", "inject --imu imu0",
                                // Issue 26 N17: -5 was sent as 18446744073709551611.
                                "clear --imu imu0 --id -5", "clear --imu imu0 --id 0"}) {
    r = run_shell(cli + bad + " --socket " + path + " 2>&1");
    EXPECT_EQ(r.exit_code, 2) << bad << ": " << r.out;
  }
  r = run_shell(cli + "clear --imu imu0 --id -5 --socket " + path + " 2>&1");
  EXPECT_NE(r.out.find("expected a fault id (an integer >= 1, from inject or list), got '-5'"), std::string::npos)
      << r.out;
  std::lock_guard lock(seen_mutex);
  EXPECT_EQ(seen.size(), 5u);
}

TEST(StatusSummary, NamesEachCounterFromTheDaemonsJson) {
  imuemu::emission::EngineStats s;
  imuemu::emission::DeviceStats d;
  d.name = "imu0";
  d.output = "native on pty:/tmp/x";
  d.rate_hz = 400;
  d.ticks = 2017;
  d.emitted = 2003;
  d.exact = 1990;
  d.extrapolated = 9;
  d.blending = 4;
  d.producer_late = 11;
  d.deadline_misses = 3;
  d.dropped_late = 3;
  d.write_errors = 3;
  d.dropped_link_down = 8;
  d.transport.frames_sent = 1995;
  d.transport.dropped_queue_full = 1;
  d.transport.write_errors = 2;
  d.transport.dropped_link_down = 8;
  d.engine_lag_ns = 8'500'000'000;
  d.lateness.p50_ns = 67'000;
  d.lateness.p99_ns = 220'000;
  d.lateness.max_ns = 96'330'000;
  s.devices.push_back(d);
  s.emit_delay_ns = 328'000'000;
  const json status{{"scene", "default"},           {"pid", 42},
                    {"uptime_s", 5.04},             {"samples_emitted", 2003},
                    {"emitter_progressing", true},  {"engine", imuemu::emission::to_json(s)}};
  std::ostringstream out;
  imuemu::cli::print_status_summary(status, out);
  const std::string text = out.str();
  std::cout << text;
  EXPECT_NE(text.find("scene default (pid 42, up 5 s): 2003 samples emitted, emitter progressing"), std::string::npos);
  EXPECT_NE(text.find("emission delay 0.328 s"), std::string::npos);
  EXPECT_NE(text.find("imu0 (native on pty:/tmp/x, 400 Hz): 2003 of 2017 ticks emitted (1990 exact, 9 extrapolated, 4 blending back); 11 underruns"), std::string::npos);
  EXPECT_NE(text.find("3 deadline misses (woken more than one period late; 3 not sent)"), std::string::npos);
  EXPECT_NE(text.find("p50 67 us, p99 220 us, max 96330 us; smoother running 8.5 s ahead"), std::string::npos);
  // Issue 26: the parts add up to the whole (8 + 3 = 11), each named for what it counts.
  EXPECT_NE(text.find("1995 frames sent, 0 queued; not taken: 11 packets (8 dropped while the link was down: e.g. no "
                      "reader on the pty; 3 write errors: queue full 1, refused by the kernel or invalid 2)"),
            std::string::npos);
  EXPECT_EQ(text.find("pose source"), std::string::npos);  // a trajectory scene has none
}

// Issue 18: the fault counters are in the status JSON and explained, each
// with its own value (a swapped field shows); none at all: no line.
TEST(StatusSummary, FaultCountersAreInTheJsonAndExplained) {
  imuemu::emission::EngineStats s;
  imuemu::emission::DeviceStats d;
  d.name = "imu0";
  s.devices.push_back(d);
  const auto summary_of = [](const imuemu::emission::EngineStats& st) {
    std::ostringstream out;
    imuemu::cli::print_status_summary(json{{"scene", "f"}, {"engine", imuemu::emission::to_json(st)}}, out);
    return out.str();
  };
  EXPECT_EQ(summary_of(s).find("faults"), std::string::npos);
  s.devices[0].faults = {1, 7, 6, 3, 2, 5, 40};
  const json j = imuemu::emission::to_json(s)["devices"][0]["faults"];
  EXPECT_EQ(j, (json{{"active", 1}, {"started", 7}, {"ended", 6}, {"injected", 3}, {"cleared", 2}, {"dropped_events", 5},
                     {"silenced", 40}}));
  EXPECT_NE(summary_of(s).find("faults: 1 acting now, 7 started and 6 ended (the fault log's events), 3 "
                               "injected and 2 cleared over the control socket, 40 ticks silenced (device off), 5 "
                               "events lost (queue full)"),
            std::string::npos)
      << summary_of(s);
}

// Issue 13: the live-time counters (time_jump, resyncs, held) and the TCP
// connection counters were counted by the pose source but missing from the
// status JSON and the summary. Each has its own value here, so a swapped
// field shows.
TEST(StatusSummary, LiveTimeAndConnectionCountersAreInTheJsonAndExplained) {
  imuemu::emission::EngineStats s;
  imuemu::emission::PoseSourceStats& p = s.pose_source.emplace();
  p.name = "tcp 127.0.0.1:5006";
  p.received = 900;
  p.accepted = 880;
  p.time_jump = 3;
  p.resyncs = 2;
  p.held = 1;
  p.connections = 7;
  p.connections_refused = 5;
  p.connections_idle_closed = 4;
  p.connections_replaced = 6;
  const json engine = imuemu::emission::to_json(s);
  const json& source = engine["pose_source"];
  EXPECT_EQ(source["time_jump"], 3u) << source.dump();
  EXPECT_EQ(source["resyncs"], 2u) << source.dump();
  EXPECT_EQ(source["held"], 1u) << source.dump();
  EXPECT_EQ(source["connections"], 7u) << source.dump();
  EXPECT_EQ(source["connections_refused"], 5u) << source.dump();
  EXPECT_EQ(source["connections_idle_closed"], 4u) << source.dump();
  EXPECT_EQ(source["connections_replaced"], 6u) << source.dump();
  const json status{{"scene", "live"}, {"pid", 9}, {"uptime_s", 2.0}, {"samples_emitted", 800},
                    {"emitter_progressing", true}, {"engine", engine}};
  std::ostringstream out;
  imuemu::cli::print_status_summary(status, out);
  const std::string text = out.str();
  std::cout << text;
  EXPECT_NE(text.find("pose source tcp 127.0.0.1:5006: 880 accepted of 900 received"), std::string::npos) << text;
  EXPECT_NE(text.find("live time: 2 re-acquisitions"), std::string::npos) << text;
  EXPECT_NE(text.find("3 stray poses dropped"), std::string::npos) << text;
  EXPECT_NE(text.find("1 held now"), std::string::npos) << text;
  EXPECT_NE(text.find("connections: 7 accepted, 5 refused (slot taken), 4 closed idle"), std::string::npos) << text;
  EXPECT_NE(text.find("6 replaced"), std::string::npos) << text;
}

// Issue 17: the pose-latency histogram (status pose_latency.buckets) on one
// line of the summary: 30 buckets of 0.1 ms from 3.0 to 6.0 ms, merged three
// by three (at most 12 groups), each group shown with its last bound.
TEST(StatusSummary, PoseLatencyBucketsAreShownCompactly) {
  imuemu::emission::LatenessHistogram h;
  for (int i = 0; i < 30; ++i)
    for (int n = 0; n <= i % 3; ++n) h.record(3'000'000 + i * 100'000 + 50'000);  // 1, 2, 3, 1, 2, 3, ...
  h.record(250'000);  // one at 250 us: a 31st bucket, alone in the first group
  imuemu::emission::EngineStats s;
  imuemu::emission::DeviceStats d;
  d.name = "imu0";
  d.output = "native on pty:/tmp/x";
  d.rate_hz = 1000;
  d.pose_latency = h.summary();
  d.pose_latency.buckets = h.buckets();
  s.devices.push_back(d);
  const json status{{"scene", "live"}, {"pid", 9}, {"uptime_s", 2.0}, {"samples_emitted", 800},
                    {"emitter_progressing", true}, {"engine", imuemu::emission::to_json(s)}};
  std::ostringstream out;
  imuemu::cli::print_status_summary(status, out);
  const std::string text = out.str();
  std::cout << text;
  // 31 buckets: ceil(31 / 12) = 3 per group, 11 groups; the first holds
  // 250 us (1) and [3.0, 3.2) ms (1 + 2), the second [3.2, 3.5) (3 + 1 + 2).
  EXPECT_NE(text.find("pose latency (arrival -> first dependent sample to the transport; 61 poses)"), std::string::npos)
      << text;
  EXPECT_NE(text.find("histogram (poses up to each bound): <= 3.2 ms: 4, <= 3.5 ms: 6, <= 3.8 ms: 6, "),
            std::string::npos)
      << text;
  EXPECT_NE(text.find(", <= 5.9 ms: 6, <= 6.0 ms: 3\n"), std::string::npos) << text;  // the 31st bucket alone
  // A histogram with nothing recorded prints no histogram line.
  s.devices[0].pose_latency = {};
  std::ostringstream empty;
  imuemu::cli::print_status_summary(
      json{{"scene", "live"}, {"engine", imuemu::emission::to_json(s)}}, empty);
  EXPECT_EQ(empty.str().find("histogram"), std::string::npos) << empty.str();
}

TEST(StatusSummary, AnEngineNotRunningIsSaidSo) {
  const json status{{"scene", "bench"}, {"pid", 7}, {"uptime_s", 1.0}, {"samples_emitted", 0},
                    {"emitter_progressing", false}, {"engine", nullptr}, {"waiting_for_device", true}};
  std::ostringstream out;
  imuemu::cli::print_status_summary(status, out);
  EXPECT_NE(out.str().find("emitter NOT progressing"), std::string::npos);
  EXPECT_NE(out.str().find("no emission engine running (waiting for a device to appear)"), std::string::npos);
}

// Issue 13 H2: a daemon whose listen backlog is full (stopped, hung) made
// `imuemu status --timeout-s 1` block in connect() forever. The timeout now
// covers the connect: the query gives up with a clear error.
TEST(ControlClient, FullBacklogTimesOutInsteadOfBlocking) {
  TempDir dir;
  const std::string path = dir.path + "/full.sock";
  const int listener = ::socket(AF_UNIX, SOCK_STREAM, 0);
  ASSERT_GE(listener, 0);
  sockaddr_un address{};
  address.sun_family = AF_UNIX;
  std::strncpy(address.sun_path, path.c_str(), sizeof address.sun_path - 1);
  ASSERT_EQ(::bind(listener, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
  ASSERT_EQ(::listen(listener, 0), 0);  // never accepts
  // Fill the backlog with non-blocking clients until one would block.
  std::vector<int> fillers;
  for (int i = 0; i < 64; ++i) {
    const int fd = ::socket(AF_UNIX, SOCK_STREAM | SOCK_NONBLOCK, 0);
    ASSERT_GE(fd, 0);
    fillers.push_back(fd);
    if (::connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) break;
  }
  ASSERT_EQ(errno, EAGAIN) << std::strerror(errno);
  std::atomic<bool> returned{false};
  std::string error;
  std::thread client([&] {
    error = error_of(path, "status", std::chrono::milliseconds(200));
    returned = true;
  });
  // Generous: the verdict is "returns at all", not how fast.
  for (int i = 0; i < 300 && !returned; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  const bool returned_in_time = returned;
  ::close(listener);  // unblocks a connect() stuck in the backlog (the unfixed client), so the thread ends
  client.join();
  for (const int fd : fillers) ::close(fd);
  EXPECT_TRUE(returned_in_time) << "query_control_socket blocked in connect() past its 200 ms timeout";
  EXPECT_NE(error.find("within 200 ms"), std::string::npos) << error;
  EXPECT_NE(error.find(path), std::string::npos) << error;
}

namespace {

std::size_t occurrences(const std::string& text, const std::string& what) {
  std::size_t n = 0;
  for (std::size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
  return n;
}

}  // namespace

// Issue 26: `imuemud` with no arguments (the built-in scene) listens at
// /tmp/imuemu/default.sock; `imuemu status`, `status --summary` and `imuemu
// fault` looked only at /run/imuemu/SCENE.sock and said no daemon was
// running. Without --socket they now try both places of
// default_control_socket_paths(), in order. And a refusal is said once (it
// was printed as JSON on stdout and again as a sentence on stderr).
TEST(FaultCommand, ClientsFindTheBuiltInScenesSocketAndSayARefusalOnce) {
  const std::string scene = "svcfix-test-" + std::to_string(::getpid());
  const std::vector<std::string> places = svc::default_control_socket_paths(scene);
  ASSERT_EQ(places.size(), 2u);
  EXPECT_EQ(places[0], "/run/imuemu/" + scene + ".sock");
  EXPECT_EQ(places[1], "/tmp/imuemu/" + scene + ".sock");
  // The built-in scene's own setting is the second place (for its name).
  EXPECT_EQ(imuemu::scene::default_scene().daemon.control_socket, svc::default_control_socket_paths("default")[1]);
  std::filesystem::create_directories("/tmp/imuemu");
  const std::string path = places[1];
  Daemon daemon(path);
  daemon.io.run([&] {
    daemon.server->add_command_with_args("fault-clear", "refuses", [](const json&) -> json {
      throw std::invalid_argument("no imu 'nope' in this scene");
    });
  });
  const std::string cli = std::string(IMUEMU_CLI_PATH);
  ShellRun r = run_shell(cli + " status --compact --scene " + scene + " 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("\"samples_emitted\":12345"), std::string::npos) << r.out;
  r = run_shell(cli + " status --summary --scene " + scene + " 2>&1");
  EXPECT_EQ(r.exit_code, 0) << r.out;
  r = run_shell(cli + " fault clear --imu nope --all --scene " + scene + " 2>&1");
  EXPECT_EQ(r.exit_code, 4) << r.out;
  EXPECT_EQ(occurrences(r.out, "no imu 'nope' in this scene"), 1u) << r.out;
  r = run_shell(cli + " fault clear --imu nope --all --scene " + scene + " 2>/dev/null");
  EXPECT_EQ(r.out, "") << "stdout carries only an accepted reply";
  daemon.io.run([&] { daemon.server.reset(); });
  r = run_shell(cli + " status --scene " + scene + " 2>&1");
  EXPECT_EQ(r.exit_code, 4) << r.out;
  EXPECT_NE(r.out.find("looked at /run/imuemu/" + scene + ".sock or /tmp/imuemu/" + scene + ".sock"), std::string::npos)
      << r.out;
}

// Issue 26 N17: a number beyond a double in a request (1e400) was answered
// with the raw "[json.exception.out_of_range.406] ..." text.
TEST(ControlSocket, ANumberBeyondADoubleIsRefusedWithAClearMessage) {
  try {
    (void)svc::parse_control_request("fault-inject {\"imu\": \"imu0\", \"type\": \"dead\", \"after_s\": 1e400}");
    ADD_FAILURE() << "accepted";
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("fault-inject: a number in the arguments is beyond the range of a double"), std::string::npos)
        << what;
    EXPECT_EQ(what.find("[json.exception"), std::string::npos) << what;
  }
}
}  // namespace unity_service_test_control_socket
