// [[imu.fault]] and [imu.random_faults] (daemon/scene/fault_config.hpp).
#include "daemon/scene/fault_config.hpp"

#include <algorithm>
#include <cmath>
#include <functional>
#include <numbers>
#include <sstream>

#include "daemon/scene/scene_config.hpp"

namespace imuemu::scene {
// The daemon is a unity build: these helpers' names differ from
// error_model_config.cpp's (FaultWhere, key_path).
namespace {

using fault::Kind;

constexpr double kDeg = std::numbers::pi / 180.0;
constexpr double kMg = 9.80665e-3;  // standard gravity / 1000 (datasheets' mg)

struct FaultWhere {
  const std::string& file;
  [[noreturn]] void fail(const toml::source_region& at, const std::string& key, const std::string& what) const {
    throw SceneError(file, at.begin.line, at.begin.column, key, what);
  }
};

std::string key_path(const std::string& path, std::string_view key) { return path + "." + std::string(key); }

enum class ValueType { number, integer };

// One parameter key: the kinds it belongs to, the group of keys that set the
// same field (two of one group are ambiguous), its range and what it sets.
struct ParamKey {
  std::string key;
  std::vector<Kind> kinds;
  std::string group;
  ValueType type = ValueType::number;
  double lo = -1e300, hi = 1e300;  // as written (datasheet units)
  std::string expected;
  std::function<void(fault::FaultSpec&, double)> set;
  int triad = 0;  // 1 gyro, 2 accel: the sensor it implies; 0 none
};

const std::vector<ParamKey>& param_keys() {
  using S = fault::FaultSpec;
  static const std::vector<ParamKey> keys = {
      {"bias_deg_s", {Kind::bias_step, Kind::plausible_drift}, "gyro_bias", ValueType::number, -1e6, 1e6,
       "a gyro bias in deg/s (plausible_drift: the final bias, > 0)", [](S& s, double v) { s.gyro_bias_rad_s = v * kDeg; }, 1},
      {"bias_deg_h", {Kind::bias_step, Kind::plausible_drift}, "gyro_bias", ValueType::number, -1e9, 1e9,
       "a gyro bias in deg/h", [](S& s, double v) { s.gyro_bias_rad_s = v * kDeg / 3600.0; }, 1},
      {"bias_mg", {Kind::bias_step, Kind::plausible_drift}, "accel_bias", ValueType::number, -1e6, 1e6,
       "an accelerometer bias in mg", [](S& s, double v) { s.accel_bias_m_s2 = v * kMg; }, 2},
      {"spike_deg_s", {Kind::spikes}, "gyro_bias", ValueType::number, -1e6, 1e6, "a gyro spike amplitude in deg/s",
       [](S& s, double v) { s.gyro_bias_rad_s = v * kDeg; }, 1},
      {"spike_mg", {Kind::spikes}, "accel_bias", ValueType::number, -1e6, 1e6, "an accelerometer spike amplitude in mg",
       [](S& s, double v) { s.accel_bias_m_s2 = v * kMg; }, 2},
      {"spike_rate_hz", {Kind::spikes}, "rate", ValueType::number, 0.0, fault::kMaxSpikeRateHz,
       "spikes per second (Poisson), > 0", [](S& s, double v) { s.rate_hz = v; }, 0},
      {"ramp_deg_s_per_s", {Kind::bias_ramp, Kind::plausible_drift}, "gyro_ramp", ValueType::number, -1e6, 1e6,
       "a gyro bias ramp in deg/s per second", [](S& s, double v) { s.gyro_ramp_rad_s2 = v * kDeg; }, 1},
      {"ramp_deg_h_per_s", {Kind::bias_ramp, Kind::plausible_drift}, "gyro_ramp", ValueType::number, -1e9, 1e9,
       "a gyro bias ramp in deg/h per second", [](S& s, double v) { s.gyro_ramp_rad_s2 = v * kDeg / 3600.0; }, 1},
      {"ramp_mg_per_s", {Kind::bias_ramp, Kind::plausible_drift}, "accel_ramp", ValueType::number, -1e6, 1e6,
       "an accelerometer bias ramp in mg per second", [](S& s, double v) { s.accel_ramp_m_s3 = v * kMg; }, 2},
      {"scale_ppm", {Kind::scale_step}, "scale", ValueType::number, -1e6, 1e7, "a scale-factor change in ppm",
       [](S& s, double v) { s.scale_ppm = v; }, 0},
      {"noise_factor", {Kind::noise_gain}, "noise", ValueType::number, 1.0, fault::kMaxNoiseFactor,
       "the white noise's factor k", [](S& s, double v) { s.noise_factor = v; }, 0},
      {"divisor", {Kind::slow}, "divisor", ValueType::integer, 2, fault::kMaxDivisor,
       "the value changes every divisor-th sample", [](S& s, double v) { s.divisor = static_cast<std::uint32_t>(v); }, 0},
      // At least 1 ns: a smaller value rounds to 0 ns (issue 26 N17: 1e-7 was refused as "expected an on time > 0").
      {"on_ms", {Kind::intermittent}, "on", ValueType::number, 1e-6, 1e9,
       "the failing part of each cycle in ms, at least 1e-6 ms = 1 ns",
       [](S& s, double v) { s.on_ns = static_cast<TimeNs>(std::llround(v * 1e6)); }, 0},
      {"off_ms", {Kind::intermittent}, "off", ValueType::number, 1e-6, 1e9,
       "the working part of each cycle in ms, at least 1e-6 ms = 1 ns",
       [](S& s, double v) { s.off_ns = static_cast<TimeNs>(std::llround(v * 1e6)); }, 0},
      {"delay_ms", {Kind::delayed}, "delay", ValueType::number, 0.0, 1e3, "the added latency in ms, (0, 1000]",
       [](S& s, double v) { s.delay_ns = static_cast<TimeNs>(std::llround(v * 1e6)); }, 0},
      {"probability", {Kind::drop, Kind::duplicate, Kind::bad_checksum, Kind::truncate, Kind::bad_length,
                       Kind::can_wrong_id, Kind::can_missing_frame},
       "probability", ValueType::number, 0.0, 1.0, "a per-packet probability in (0, 1] (default 1: every packet)",
       [](S& s, double v) { s.probability = v; }, 0},
      {"burst_samples", {Kind::drop}, "burst", ValueType::integer, 1, fault::kMaxBurstSamples,
       "samples dropped per burst", [](S& s, double v) { s.burst_samples = static_cast<std::uint32_t>(v); }, 0},
      {"burst_rate_hz", {Kind::drop}, "rate", ValueType::number, 0.0, fault::kMaxSpikeRateHz,
       "bursts per second (Poisson), > 0", [](S& s, double v) { s.rate_hz = v; }, 0},
      {"bit_error_rate", {Kind::bit_errors}, "ber", ValueType::number, 0.0, 0.5, "a per-bit error rate in (0, 0.5]",
       [](S& s, double v) { s.bit_error_rate = v; }, 0},
      {"truncate_bytes", {Kind::truncate}, "truncate", ValueType::integer, 1, 65535, "bytes cut off each frame",
       [](S& s, double v) { s.truncate_bytes = static_cast<std::uint32_t>(v); }, 0},
      {"sequence_step", {Kind::sequence_jump}, "sequence", ValueType::integer, -1e15, 1e15,
       "the counter's jump, nonzero", [](S& s, double v) { s.sequence_step = static_cast<std::int64_t>(v); }, 0},
      {"time_step_ms", {Kind::time_jump}, "time_step", ValueType::number, -1e9, 1e9,
       "the protocol time's jump in ms, nonzero",
       [](S& s, double v) { s.time_step_ns = static_cast<TimeNs>(std::llround(v * 1e6)); }, 0},
      {"babble_factor", {Kind::babble}, "babble", ValueType::integer, 2, fault::kMaxBabbleFactor,
       "frames per tick", [](S& s, double v) { s.babble_factor = static_cast<std::uint32_t>(v); }, 0},
      {"can_id", {Kind::can_wrong_id}, "can_id", ValueType::integer, 0, 0x1FFFFFFF,
       "the wrong CAN identifier (11 or 29 bits)", [](S& s, double v) { s.can_id = static_cast<std::uint32_t>(v); }, 0},
  };
  return keys;
}

const ParamKey* find_param(std::string_view key) {
  for (const ParamKey& p : param_keys())
    if (p.key == key) return &p;
  return nullptr;
}

bool belongs(const ParamKey& p, Kind kind) { return std::find(p.kinds.begin(), p.kinds.end(), kind) != p.kinds.end(); }

std::string keys_of(Kind kind) {
  std::string s;
  for (const ParamKey& p : param_keys())
    if (belongs(p, kind)) s += (s.empty() ? "" : ", ") + p.key;
  return s.empty() ? "none" : s;
}

std::string kinds_text() {
  std::string s;
  for (std::string_view n : fault::kind_names()) s += (s.empty() ? "" : ", ") + std::string(n);
  return s;
}

double number_of(const FaultWhere& w, const toml::node& n, const std::string& key, const std::string& expected) {
  if (n.is_integer()) return static_cast<double>(n.as_integer()->get());
  if (n.is_floating_point() && std::isfinite(n.as_floating_point()->get())) return n.as_floating_point()->get();
  w.fail(n.source(), key, "expected a finite number (" + expected + ")");
}

std::string range_text(const ParamKey& p) {
  std::ostringstream s;
  s << "[" << p.lo << ", " << p.hi << "]";
  return s.str();
}

// A parameter's value: its type and range, open at 0 where zero means nothing.
double param_value(const FaultWhere& w, const toml::node& n, const std::string& key, const ParamKey& p) {
  if (p.type == ValueType::integer) {
    if (!n.is_integer()) w.fail(n.source(), key, "expected an integer in " + range_text(p) + " (" + p.expected + ")");
    const double v = static_cast<double>(n.as_integer()->get());
    if (v < p.lo || v > p.hi) w.fail(n.source(), key, "out of range; expected an integer in " + range_text(p) + " (" + p.expected + ")");
    return v;
  }
  const double v = number_of(w, n, key, p.expected);
  if (v < p.lo || v > p.hi) w.fail(n.source(), key, "out of range; expected a number in " + range_text(p) + " (" + p.expected + ")");
  return v;
}

TimeNs seconds_ns(const FaultWhere& w, const toml::node& n, const std::string& key, double lo, const std::string& expected) {
  const double v = number_of(w, n, key, expected);
  constexpr double kMaxS = 9e9;  // within int64 ns
  if (v < lo || v > kMaxS) {
    std::ostringstream s;
    s << "out of range; expected " << expected << " in [" << lo << ", " << kMaxS << "] s";
    w.fail(n.source(), key, s.str());
  }
  return static_cast<TimeNs>(std::llround(v * 1e9));
}

std::uint64_t seed_of(const FaultWhere& w, const toml::node& n, const std::string& key) {
  if (!n.is_integer() || n.as_integer()->get() < 0) w.fail(n.source(), key, "expected an integer >= 0");
  return static_cast<std::uint64_t>(n.as_integer()->get());
}

bool bool_of(const FaultWhere& w, const toml::node& n, const std::string& key) {
  if (!n.is_boolean()) w.fail(n.source(), key, "expected true or false");
  return n.as_boolean()->get();
}

fault::Triad triad_of(const FaultWhere& w, const toml::node& n, const std::string& key) {
  const std::optional<std::string> s = n.value<std::string>();
  if (s == "gyro") return fault::Triad::gyro;
  if (s == "accel") return fault::Triad::accel;
  if (s == "both") return fault::Triad::both;
  w.fail(n.source(), key, "expected \"gyro\", \"accel\" or \"both\"");
}

std::uint8_t axes_of(const FaultWhere& w, const toml::node& n, const std::string& key) {
  const std::optional<std::string> s = n.value<std::string>();
  std::uint8_t bits = 0;
  bool ok = s.has_value() && !s->empty();
  if (ok)
    for (char c : *s) {
      const int bit = c == 'x' ? 0 : c == 'y' ? 1 : c == 'z' ? 2 : -1;
      if (bit < 0 || (bits & (1u << bit)) != 0) ok = false;
      if (bit >= 0) bits = static_cast<std::uint8_t>(bits | (1u << bit));
    }
  if (!ok) w.fail(n.source(), key, "expected a non-empty subset of \"xyz\" (each axis once), e.g. \"xz\"");
  return bits;
}

// Keys in file order (the first offending one is reported).
std::vector<std::pair<const toml::key*, const toml::node*>> in_file_order(const toml::table& t) {
  std::vector<std::pair<const toml::key*, const toml::node*>> entries;
  for (auto&& [key, value] : t) entries.emplace_back(&key, &value);
  std::sort(entries.begin(), entries.end(),
            [](const auto& a, const auto& b) { return a.first->source().begin < b.first->source().begin; });
  return entries;
}

// The parameters, sensor, axes, flag_status and seed keys of a fault or
// random table into spec; `applies(p)`: the parameter fits this table;
// `handled`: the table's own keys (skipped here). Returns the sensor the
// parameters named (1 gyro, 2 accel, 3 both, 0 none) and whether `sensor`
// was given.
struct CommonResult {
  int named_triads = 0;
  bool sensor_given = false;
};
CommonResult parse_common(const FaultWhere& w, const toml::table& t, const std::string& path, fault::FaultSpec& spec,
                          bool sensor_keys, const std::function<bool(const ParamKey&)>& applies,
                          const std::vector<std::string>& handled, const std::string& allowed_note) {
  CommonResult r;
  std::vector<std::pair<std::string, std::string>> groups;  // group -> key
  for (const auto& [key, node] : in_file_order(t)) {
    const std::string k(key->str());
    const std::string full = key_path(path, k);
    if (std::find(handled.begin(), handled.end(), k) != handled.end()) continue;
    if (k == "flag_status") {
      spec.flag_status = bool_of(w, *node, full);
    } else if (k == "seed") {
      spec.seed = seed_of(w, *node, full);
    } else if ((k == "sensor" || k == "axes") && sensor_keys) {
      if (k == "sensor") {
        spec.triad = triad_of(w, *node, full);
        r.sensor_given = true;
      } else {
        spec.axes = axes_of(w, *node, full);
      }
    } else if (const ParamKey* p = find_param(k); p != nullptr && applies(*p)) {
      for (const auto& [group, other] : groups)
        if (group == p->group)
          w.fail(key->source(), full, "ambiguous: '" + other + "' already sets this; give one of them");
      groups.emplace_back(p->group, k);
      p->set(spec, param_value(w, *node, full, *p));
      r.named_triads |= p->triad;
    } else {
      w.fail(key->source(), full, "unknown key '" + k + "'" + allowed_note);
    }
  }
  return r;
}

}  // namespace

std::vector<std::string> fault_parameter_keys() {
  std::vector<std::string> out;
  for (const ParamKey& p : param_keys()) out.push_back(p.key);
  return out;
}

fault::FaultSpec parse_fault_table(const toml::table& t, const std::string& file, const std::string& path,
                                   const std::string& device, std::int64_t rate_hz, std::uint64_t default_seed) {
  const FaultWhere w{file};
  const toml::node* type = t.get("type");
  if (type == nullptr) w.fail(t.source(), key_path(path, "type"), "missing required key (the fault type: " + kinds_text() + ")");
  const std::optional<std::string> name = type->value<std::string>();
  const std::optional<Kind> kind = name ? fault::kind_from_name(*name) : std::nullopt;
  if (!kind) w.fail(type->source(), key_path(path, "type"), "expected one of " + kinds_text());
  fault::FaultSpec spec = fault::default_spec(*kind);
  spec.device = device;
  spec.seed = default_seed;
  spec.source = "scene";
  const toml::node* at = t.get("at_s");
  const toml::node* after = t.get("after_s");
  if ((at == nullptr) == (after == nullptr))
    w.fail(at != nullptr ? at->source() : t.source(), path,
           at != nullptr ? "give either at_s or after_s, not both"
                         : "missing the start: at_s (trajectory time, s) or after_s (s since the device's first sample)");
  if (at != nullptr) {
    spec.clock = fault::Clock::trajectory;
    spec.start_ns = seconds_ns(w, *at, key_path(path, "at_s"), -9e9, "a trajectory time");
  } else {
    spec.clock = fault::Clock::since_start;
    spec.start_ns = seconds_ns(w, *after, key_path(path, "after_s"), 0.0, "a time since the start >= 0");
  }
  if (const toml::node* d = t.get("duration_s"))
    spec.duration_ns = seconds_ns(w, *d, key_path(path, "duration_s"), 0.0, "a duration >= 0 (0: until cleared)");
  const bool sensor = fault::is_sensor_fault(*kind);
  const std::string note = "; keys of a " + std::string(*name) + " fault: type, at_s or after_s, duration_s, " +
                           (sensor ? "sensor, axes, " : "") + "flag_status, seed, " + keys_of(*kind);
  const CommonResult r = parse_common(
      w, t, path, spec, sensor, [&](const ParamKey& p) { return belongs(p, *kind); }, {"type", "at_s", "after_s", "duration_s"}, note);
  if (sensor && !r.sensor_given && (r.named_triads == 1 || r.named_triads == 2))
    spec.triad = static_cast<fault::Triad>(r.named_triads);  // only gyro (or accel) parameters: that sensor
  try {
    fault::validate(spec);
    if (spec.kind == Kind::delayed && spec.delay_ns > fault::max_delay_ns_at(rate_hz))
      throw std::invalid_argument("delay_ms: at most " + std::to_string(fault::max_delay_ns_at(rate_hz) / 1'000'000) +
                                  " ms at " + std::to_string(rate_hz) + " Hz (the device's history)");
  } catch (const std::invalid_argument& e) {
    w.fail(t.source(), path, std::string(e.what()) + " (keys of a " + *name + " fault: " + keys_of(*kind) + ")");
  }
  return spec;
}

DeviceFaults parse_device_faults(const toml::table& imu, const std::string& file, const std::string& imu_path,
                                 const std::string& device, std::int64_t rate_hz, std::uint64_t default_seed) {
  const FaultWhere w{file};
  DeviceFaults out;
  if (const toml::node* n = imu.get("fault")) {
    const std::string path = key_path(imu_path, "fault");
    if (!n->is_array_of_tables()) w.fail(n->source(), path, "expected [[" + std::string("imu.fault") + "]] tables");
    const toml::array& a = *n->as_array();
    for (std::size_t i = 0; i < a.size(); ++i)
      out.faults.push_back(parse_fault_table(*a[i].as_table(), file, path + "[" + std::to_string(i) + "]", device,
                                             rate_hz, default_seed));
    if (out.faults.size() > 256)
      w.fail(n->source(), path, std::to_string(out.faults.size()) + " faults; at most 256 per device");
  }
  if (const toml::node* n = imu.get("random_faults")) {
    const std::string path = key_path(imu_path, "random_faults");
    const toml::table* t = n->as_table();
    if (t == nullptr) w.fail(n->source(), path, "expected a table [imu.random_faults]");
    fault::RandomFaults& r = out.random;
    r.seed = default_seed;
    const toml::node* per_hour = t->get("per_hour");
    if (per_hour == nullptr) w.fail(t->source(), key_path(path, "per_hour"), "missing required key (mean faults per hour)");
    r.per_hour = number_of(w, *per_hour, key_path(path, "per_hour"), "faults per hour");
    if (r.per_hour < 0.0 || r.per_hour > fault::kMaxRandomPerHour)
      w.fail(per_hour->source(), key_path(path, "per_hour"), "out of range; expected a number in [0, 1800] faults per hour");
    const toml::node* types = t->get("types");
    if (types == nullptr) w.fail(t->source(), key_path(path, "types"), "missing required key (an array of fault types)");
    const toml::array* ta = types->as_array();
    if (ta == nullptr || ta->empty()) w.fail(types->source(), key_path(path, "types"), "expected a non-empty array of fault types (" + kinds_text() + ")");
    for (const toml::node& e : *ta) {
      const std::optional<std::string> name = e.value<std::string>();
      const std::optional<Kind> kind = name ? fault::kind_from_name(*name) : std::nullopt;
      if (!kind) w.fail(e.source(), key_path(path, "types"), "expected fault types from " + kinds_text());
      r.kinds.push_back(*kind);
    }
    if (const toml::node* d = t->get("duration_s")) {
      r.duration_ns = seconds_ns(w, *d, key_path(path, "duration_s"), 0.0, "each fault's duration > 0");
      if (r.duration_ns <= 0) w.fail(d->source(), key_path(path, "duration_s"), "expected each fault's duration > 0 s");
    }
    fault::FaultSpec& p = r.parameters;
    p.device = device;
    p.seed = 0;
    // "seed" is the random process's seed (each fault's own is drawn from it).
    if (const toml::node* seed_node = t->get("seed")) r.seed = seed_of(w, *seed_node, key_path(path, "seed"));
    parse_common(w, *t, path, p, true,
                 [&](const ParamKey& k) {
                   return std::any_of(r.kinds.begin(), r.kinds.end(), [&](Kind kind) { return belongs(k, kind); });
                 },
                 {"per_hour", "types", "duration_s", "seed"},
                 "; keys of [imu.random_faults]: per_hour, types, duration_s, seed, sensor, axes, flag_status and the "
                 "parameters of the listed types");
    try {
      fault::validate(r);
      if (std::find(r.kinds.begin(), r.kinds.end(), Kind::delayed) != r.kinds.end() &&
          p.delay_ns > fault::max_delay_ns_at(rate_hz))
        throw std::invalid_argument("delay_ms: at most " + std::to_string(fault::max_delay_ns_at(rate_hz) / 1'000'000) +
                                    " ms at " + std::to_string(rate_hz) + " Hz");
    } catch (const std::invalid_argument& e) {
      w.fail(t->source(), path, e.what());
    }
  }
  return out;
}

std::vector<std::string> fault_lines(const std::vector<fault::FaultSpec>& faults, const fault::RandomFaults& random) {
  std::vector<std::string> out;
  for (std::size_t i = 0; i < faults.size(); ++i)
    out.push_back("fault " + std::to_string(i + 1) + ": " + fault::describe(faults[i]));
  if (random.per_hour > 0.0) {
    std::ostringstream s;
    s << "random faults: " << random.per_hour << " per hour of ";
    for (std::size_t i = 0; i < random.kinds.size(); ++i) s << (i > 0 ? ", " : "") << fault::kind_name(random.kinds[i]);
    s << ", " << static_cast<double>(random.duration_ns) * 1e-9 << " s each, seed " << random.seed;
    out.push_back(s.str());
  }
  return out;
}

}  // namespace imuemu::scene
