// The commands imuemud serves on its control socket (protocol:
// daemon/service/control_socket.hpp, docs/daemon.md): "status" (scene,
// devices, counters, lateness, watchdog: daemon/service/status_report.hpp),
// the run-time faults of issue 18 ("fault-inject", "fault-list",
// "fault-clear": arguments checked by daemon/service/fault_control.hpp
// before anything reaches the engine) and, with IMUEMU_TEST_HOOKS=1 only,
// the test hooks "stall-emitter" (the emission thread stops progressing: the
// watchdog test, tests/hil/systemd_run.sh) and "fault-producer" (the
// producer thread throws: tests/service/test_imuemud.cpp proves it ends in exit 5).
// Every handler runs on the service io thread and asks the scene's life
// cycle (daemon/service/scene_lifecycle.hpp) for what it needs.
#pragma once

#include "daemon/service/control_socket.hpp"
#include "daemon/service/scene_lifecycle.hpp"

namespace imuemu::service {

// Registers the commands; `lifecycle` must outlive the server's connections.
void add_control_commands(ControlServer& control, SceneLifecycle& lifecycle, bool test_hooks);

}  // namespace imuemu::service
