#include "daemon/service/control_commands.hpp"

#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/fault/fault.hpp"
#include "daemon/service/fault_control.hpp"
#include "log/log.hpp"

namespace imuemu::service {

void add_control_commands(ControlServer& control, SceneLifecycle& lifecycle, bool test_hooks) {
  control.add_command("status", "scene, devices, counters, lateness, watchdog",
                      [&lifecycle] { return lifecycle.status_json(); });
  // Issue 18: run-time faults. The arguments are checked here (nothing
  // reaches the engine otherwise); the engine's producer thread takes the
  // request through its mailbox (a few ms at most, bounded).
  control.add_command_with_args(
      "fault-inject", "{\"imu\", \"type\", \"after_s\", \"duration_s\", \"params\": {...}}: start a fault (docs/faults.md)",
      [&lifecycle](const nlohmann::json& args) {
        const FaultInjectRequest r = parse_fault_inject(args);
        emission::EmissionEngine& engine = lifecycle.running_engine();
        const auto injected = engine.inject_fault(r.imu, r.spec, r.after_ns);
        // Described at the start the engine gave it, since the device's
        // first sample: the time base of `fault-list` and the fault log
        // (issue 26: the request's own start, 0, was logged).
        fault::FaultSpec started = r.spec;
        started.clock = fault::Clock::since_start;
        started.start_ns = injected.start_since_start_ns;
        log_notice("fault injected on " + r.imu + ": id " + std::to_string(injected.id) + ", " +
                   fault::describe(started) + ", from sample " + std::to_string(injected.first_sample));
        return nlohmann::json{{"imu", r.imu},
                              {"id", injected.id},
                              {"type", std::string(fault::kind_name(r.spec.kind))},
                              {"first_sample", injected.first_sample},
                              {"start_since_start_ns", injected.start_since_start_ns},
                              {"duration_ns", r.spec.duration_ns}};
      });
  control.add_command_with_args("fault-list", "{} or {\"imu\"}: the scheduled and active faults",
                                [&lifecycle](const nlohmann::json& args) {
                                  const std::string imu = parse_fault_list(args);
                                  nlohmann::json faults = nlohmann::json::array();
                                  for (const auto& f : lifecycle.running_engine().list_faults(imu))
                                    faults.push_back(fault_info_json(f));
                                  return nlohmann::json{{"faults", std::move(faults)}};
                                });
  control.add_command_with_args("fault-clear", "{\"imu\", \"id\"} or {\"imu\", \"all\": true}: end faults",
                                [&lifecycle](const nlohmann::json& args) {
                                  const FaultClearRequest r = parse_fault_clear(args);
                                  const std::vector<std::uint64_t> cleared =
                                      lifecycle.running_engine().clear_faults(r.imu, r.id);
                                  std::string ids;
                                  for (const std::uint64_t id : cleared) ids += (ids.empty() ? "" : ", ") + std::to_string(id);
                                  log_notice("faults cleared on " + r.imu + ": " + ids);
                                  lifecycle.write_fault_events();  // the end events at once
                                  return nlohmann::json{{"imu", r.imu}, {"cleared", cleared}};
                                });
  if (test_hooks) {
    control.add_command("stall-emitter", "TEST HOOK: the emission thread stops progressing (watchdog test)", [&lifecycle] {
      log_warning("test hook: emitter stalled on request");
      if (emission::EmissionEngine* engine = lifecycle.engine()) engine->set_emission_stall_for_test(true);
      return nlohmann::json{{"stalled", true}};
    });
    control.add_command("fault-producer", "TEST HOOK: the producer thread throws (no exception may abort imuemud)",
                        [&lifecycle] {
                          log_warning("test hook: producer fault on request");
                          emission::EmissionEngine* engine = lifecycle.engine();
                          if (engine) engine->inject_producer_fault_for_test();
                          return nlohmann::json{{"fault", engine != nullptr}};
                        });
  }
}

}  // namespace imuemu::service
