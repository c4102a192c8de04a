// What the other rooms (the imuemu command-line tool, tests) and systemd may
// know of imuemud, the service: where its control socket is by default, how
// long one command line to it may be, and what its exit codes mean. The
// protocol of the socket is in docs/daemon.md and
// daemon/service/control_socket.hpp; the rest of this room (the scene's life
// cycle, the status reports, the fault log) is imuemud's own.
#pragma once

#include <cstddef>
#include <string>

namespace imuemu::service {

// A fault specification with its parameters fits in well under 1 KiB; 4 KiB
// leaves room without letting a client make the daemon buffer much.
inline constexpr std::size_t kMaxCommandBytes = 4096;

// Where imuemud of scene `scene_name` listens unless told otherwise (same
// rule as the scene file's [daemon] control_socket default):
// /run/imuemu/<scene_name>.sock (RuntimeDirectory=imuemu of imuemud@.service).
std::string default_control_socket_path(const std::string& scene_name);

// Exit codes for systemd: 0 clean stop (or the trajectory ended); anything
// else is a failure that Restart=on-failure acts on (a scene that does not
// parse fails every time and ends in the unit's start limit, visibly).
inline constexpr int kExitOk = 0;
inline constexpr int kExitStartFailed = 1;
inline constexpr int kExitUsage = 2;
inline constexpr int kExitBadScene = 3;
inline constexpr int kExitLinkRefused = 4;
inline constexpr int kExitEmissionFailed = 5;  // an engine thread failed while running (issue 13 C1)

}  // namespace imuemu::service
