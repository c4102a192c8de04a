#include "daemon/service/fault_control.hpp"

#include <cmath>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>

#include "core/limits.hpp"
#include "daemon/scene/fault_config.hpp"
#include "io/fault_log.hpp"

namespace imuemu::service {

namespace {

using nlohmann::json;

void only_keys(const json& args, const std::set<std::string>& allowed, const char* command) {
  for (const auto& [key, value] : args.items()) {
    if (allowed.count(key) == 0) {
      std::string list;
      for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
      throw std::invalid_argument(std::string(command) + ": unknown key '" + key + "' (expected " + list + ")");
    }
  }
}

std::string imu_of(const json& args, bool required) {
  const auto it = args.find("imu");
  if (it == args.end()) {
    if (required) throw std::invalid_argument("missing \"imu\": the [[imu]] name");
    return {};
  }
  if (!it->is_string() || it->get<std::string>().empty()) throw std::invalid_argument("\"imu\": expected a non-empty string");
  return it->get<std::string>();
}

// The scene's [[imu.fault]] after_s/duration_s bound (fault_config.cpp):
// 9e9 s is 9e18 ns, within int64 (9.22e18); the engine adds it to the
// start with saturation (issue 26 N17: 9e9 was refused as "does not fit").
constexpr double kMaxFaultSeconds = 9e9;

TimeNs seconds_of(const json& args, const char* key) {
  const auto it = args.find(key);
  if (it == args.end()) return 0;
  if (!it->is_number())
    throw std::invalid_argument(std::string("\"") + key + "\": expected a number of seconds, got " + it->type_name());
  const double s = it->get<double>();
  if (!std::isfinite(s) || s < 0.0 || s > kMaxFaultSeconds) {
    std::ostringstream text;
    text << "\"" << key << "\": expected a finite number >= 0 and <= 9e9 s (int64 nanoseconds, as a scene's "
         << "[[imu.fault]]), got " << s;
    throw std::invalid_argument(text.str());
  }
  return static_cast<TimeNs>(std::llround(s * 1e9));
}

// A JSON value as the TOML value a scene would hold.
void put_toml(toml::table& t, const std::string& key, const json& v) {
  if (v.is_boolean()) t.insert_or_assign(key, v.get<bool>());
  else if (v.is_number_integer()) {
    if (v.is_number_unsigned() && v.get<std::uint64_t>() > static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max()))
      throw std::invalid_argument("params." + key + ": out of range");
    t.insert_or_assign(key, v.get<std::int64_t>());
  } else if (v.is_number()) t.insert_or_assign(key, v.get<double>());
  else if (v.is_string()) t.insert_or_assign(key, v.get<std::string>());
  else throw std::invalid_argument("params." + key + ": expected a number, a string or true/false");
}

}  // namespace

FaultInjectRequest parse_fault_inject(const json& args) {
  only_keys(args, {"imu", "type", "after_s", "duration_s", "params"}, "fault-inject");
  FaultInjectRequest r;
  r.imu = imu_of(args, true);
  const auto type = args.find("type");
  if (type == args.end()) throw std::invalid_argument("missing \"type\": the fault type");
  if (!type->is_string())
    throw std::invalid_argument(std::string("\"type\": expected a string (a fault type's name, e.g. \"bias_step\"), got ") +
                                type->type_name());
  const std::optional<fault::Kind> kind = fault::kind_from_name(type->get<std::string>());
  if (!kind) {
    std::string names;
    for (const std::string_view n : fault::kind_names()) names += (names.empty() ? "" : ", ") + std::string(n);
    throw std::invalid_argument("\"type\": '" + type->get<std::string>() + "' is not a fault type (" + names + ")");
  }
  r.after_ns = seconds_of(args, "after_s");
  const TimeNs duration_ns = seconds_of(args, "duration_s");
  // The parameters are a scene [[imu.fault]] entry's keys, in datasheet
  // units (docs/faults.md): parsed by the scene's own parser, so the socket
  // and the scene take exactly the same. The start is the engine's (after
  // the next sample it computes); the table's after_s only satisfies the
  // parser.
  toml::table table;
  table.insert_or_assign("type", type->get<std::string>());
  table.insert_or_assign("after_s", 0.0);
  if (const auto params = args.find("params"); params != args.end()) {
    if (!params->is_object()) throw std::invalid_argument("\"params\": expected an object");
    for (const auto& [key, value] : params->items()) {
      if (key == "type" || key == "after_s" || key == "at_s" || key == "duration_s")
        throw std::invalid_argument("params." + key + ": give it as --" + (key == "duration_s" ? "duration-s" : key == "type" ? "type" : "after-s") +
                                    ", not as a parameter");
      put_toml(table, key, value);
    }
  }
  try {
    // rate and default seed: the seed of a run-time fault without one is
    // drawn by the timeline from its id; the rate only scales sample counts.
    r.spec = scene::parse_fault_table(table, "control socket", "fault-inject", r.imu, 1, 0);
  } catch (const std::exception& e) {
    throw std::invalid_argument(e.what());
  }
  r.spec.device = r.imu;
  r.spec.source = "control";
  r.spec.duration_ns = duration_ns;
  fault::validate(r.spec);  // names the field; the engine validates again on its thread
  return r;
}

FaultClearRequest parse_fault_clear(const json& args) {
  only_keys(args, {"imu", "id", "all"}, "fault-clear");
  FaultClearRequest r;
  r.imu = imu_of(args, true);
  const auto id = args.find("id");
  const auto all = args.find("all");
  if ((id == args.end()) == (all == args.end())) throw std::invalid_argument("give either \"id\": N or \"all\": true");
  if (id != args.end()) {
    // A JSON parser gives a non-negative integer as unsigned, a program may
    // build it signed: both are ids when >= 1.
    const bool valid = id->is_number_unsigned() ? id->get<std::uint64_t>() >= 1
                                                : id->is_number_integer() && id->get<std::int64_t>() >= 1;
    if (!valid) throw std::invalid_argument("\"id\": expected a fault id (an integer >= 1)");
    r.id = id->is_number_unsigned() ? id->get<std::uint64_t>() : static_cast<std::uint64_t>(id->get<std::int64_t>());
  } else if (!all->is_boolean() || !all->get<bool>()) {
    throw std::invalid_argument("\"all\": expected true");
  }
  return r;
}

std::string parse_fault_list(const json& args) {
  only_keys(args, {"imu"}, "fault-list");
  return imu_of(args, false);
}

json fault_info_json(const emission::FaultInfo& info) {
  json j{{"imu", info.spec.device},
         {"id", info.id},
         {"type", std::string(fault::kind_name(info.spec.kind))},
         {"state", emission::state_name(info.state)},
         {"source", info.spec.source},
         {"clock", info.spec.clock == fault::Clock::trajectory ? "trajectory" : "since_start"},
         {"start_ns", info.spec.start_ns},
         {"duration_ns", info.spec.duration_ns},
         {"flag_status", info.spec.flag_status},
         {"parameters", fault_log::fault_parameters_json(info.spec)},
         {"description", fault::describe(info.spec)}};
  j["first_sample"] = info.first_sample ? json(*info.first_sample) : json(nullptr);
  return j;
}

}  // namespace imuemu::service
