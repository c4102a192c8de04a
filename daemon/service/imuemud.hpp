// What the other rooms (the imuemu command-line tool, tests) and systemd may
// know of imuemud, the service: where its control socket is by default, how
// long one command line to it may be, and what its exit codes mean. The
// protocol of the socket is in docs/daemon.md and
// daemon/service/control_socket.hpp; the rest of this room (the scene's life
// cycle, the status reports, the fault log) is imuemud's own.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace imuemu::service {

// A fault specification with its parameters fits in well under 1 KiB; 4 KiB
// leaves room without letting a client make the daemon buffer much.
inline constexpr std::size_t kMaxCommandBytes = 4096;

// Where imuemud of scene `scene_name` listens unless told otherwise (same
// rule as the scene file's [daemon] control_socket default):
// /run/imuemu/<scene_name>.sock (RuntimeDirectory=imuemu of imuemud@.service).
std::string default_control_socket_path(const std::string& scene_name);

// The places a daemon of scene `scene_name` listens by default, in the order
// a client without --socket tries them (issue 26: `imuemud` with no
// arguments, the built-in scene, listens at /tmp/imuemu/default.sock, where
// `imuemu status` did not look): /run/imuemu/<scene>.sock (a scene file's
// default, imuemud@.service), then /tmp/imuemu/<scene>.sock (the built-in
// scene's, imuemud run by hand without root).
std::vector<std::string> default_control_socket_paths(const std::string& scene_name);

// The first of default_control_socket_paths() that exists as a socket; none:
// the first (a client's error then names every place it looked, see
// control_socket_places_text()).
std::string find_control_socket(const std::string& scene_name);
// "/run/imuemu/x.sock or /tmp/imuemu/x.sock".
std::string control_socket_places_text(const std::string& scene_name);

// Exit codes for systemd: 0 clean stop (or the trajectory ended); anything
// else is a failure that Restart=on-failure acts on (a scene that does not
// parse fails every time and ends in the unit's start limit, visibly).
inline constexpr int kExitOk = 0;
inline constexpr int kExitStartFailed = 1;
inline constexpr int kExitUsage = 2;
inline constexpr int kExitBadScene = 3;
inline constexpr int kExitLinkRefused = 4;
inline constexpr int kExitEmissionFailed = 5;  // an engine thread failed while running (issue 13 C1)

// imuemud as a function (imuemud_app.cpp): parses argv, runs the service or
// --check-config, returns the exit code above. version_text: what --version
// prints after "imuemud ".
int run_imuemud(int argc, char** argv, const char* version_text);

}  // namespace imuemu::service
