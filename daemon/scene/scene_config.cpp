// Scene file parsing and validation (docs/scene-format.md). toml++ gives every
// key and value its source position, so each error names the line of the
// offending value (or of the table that lacks a required key).
#include "daemon/scene/scene_config.hpp"

#include <arpa/inet.h>

#include <algorithm>
#include <cstdio>
#include <array>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <set>
#include <sstream>
#include <toml++/toml.h>

#include "daemon/scene/error_model_config.hpp"
#include "daemon/scene/fault_config.hpp"

#include "core/attitude.hpp"
#include "core/limits.hpp"
#include "core/stream.hpp"
#include "core/time_arith.hpp"
#include "drivers/protocols/protocol_options.hpp"
#include "drivers/transport.hpp"
#include "io/installed_paths.hpp"

namespace imuemu::scene {
namespace {

constexpr double kDegToRad = std::numbers::pi / 180.0;

std::string join(const std::vector<std::string>& names) {
  std::string s;
  for (std::size_t i = 0; i < names.size(); ++i) {
    if (i > 0) s += (i + 1 == names.size()) ? " or " : ", ";
    s += names[i];
  }
  return s;
}

std::string type_name(const toml::node& node) {
  switch (node.type()) {
    case toml::node_type::string:
      return "a string";
    case toml::node_type::integer:
      return "an integer";
    case toml::node_type::floating_point:
      return "a floating-point number";
    case toml::node_type::boolean:
      return "a boolean";
    case toml::node_type::table:
      return "a table";
    case toml::node_type::array:
      return "an array";
    default:
      return "a date/time";
  }
}

// The file being parsed: every error goes through here.
struct Context {
  std::string file;
  std::filesystem::path base_dir;

  [[noreturn]] void fail(const toml::source_region& where, const std::string& key, const std::string& what) const {
    throw SceneError(file, where.begin.line, where.begin.column, key, what);
  }
};

// One TOML table at a dotted path: typed getters that name the key, and the
// check that it holds no key outside the allowed set.
class Table {
 public:
  Table(const Context& ctx, const toml::table& table, std::string path)
      : ctx_(ctx), table_(table), path_(std::move(path)) {}

  const std::string& path() const { return path_; }
  const toml::source_region& where() const { return table_.source(); }
  std::string key_path(std::string_view key) const {
    return path_.empty() ? std::string(key) : path_ + "." + std::string(key);
  }
  bool has(std::string_view key) const { return table_.get(key) != nullptr; }
  const toml::node* node(std::string_view key) const { return table_.get(key); }

  [[noreturn]] void fail_at(std::string_view key, const std::string& what) const {
    const toml::node* n = table_.get(key);
    ctx_.fail(n != nullptr ? n->source() : table_.source(), key_path(key), what);
  }

  // Unknown keys are typos until proven otherwise: the first one in file
  // order is reported with the list of keys the table takes.
  void allow_only(const std::vector<std::string>& allowed, const std::string& context_note = "") const {
    const toml::key* first_unknown = nullptr;
    for (auto&& [key, value] : table_) {
      (void)value;
      if (std::find(allowed.begin(), allowed.end(), key.str()) != allowed.end()) continue;
      if (first_unknown == nullptr || key.source().begin < first_unknown->source().begin) first_unknown = &key;
    }
    if (first_unknown == nullptr) return;
    std::string what = "unknown key '" + std::string(first_unknown->str()) + "'; allowed keys in " +
                       (path_.empty() ? std::string("the top level") : path_) + context_note + ": ";
    for (std::size_t i = 0; i < allowed.size(); ++i) what += (i > 0 ? ", " : "") + allowed[i];
    ctx_.fail(first_unknown->source(), key_path(first_unknown->str()), what);
  }

  void require(std::string_view key, const std::string& what_it_is) const {
    if (!has(key))
      ctx_.fail(table_.source(), key_path(key), "missing required key (" + what_it_is + ")");
  }

  std::optional<Table> subtable(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) return std::nullopt;
    if (!n->is_table()) fail_at(key, "expected a table, got " + type_name(*n));
    return Table(ctx_, *n->as_table(), key_path(key));
  }

  std::optional<bool> opt_bool(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) return std::nullopt;
    if (!n->is_boolean()) fail_at(key, "expected true or false, got " + type_name(*n));
    return n->as_boolean()->get();
  }
  bool boolean(std::string_view key, bool fallback) const { return opt_bool(key).value_or(fallback); }

  std::optional<std::int64_t> opt_int(std::string_view key, std::int64_t lo, std::int64_t hi) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) return std::nullopt;
    const std::string range = std::to_string(lo) + ".." + std::to_string(hi);
    if (!n->is_integer()) fail_at(key, "expected an integer in " + range + ", got " + type_name(*n));
    const std::int64_t v = n->as_integer()->get();
    if (v < lo || v > hi) fail_at(key, std::to_string(v) + " is out of range; expected an integer in " + range);
    return v;
  }
  std::int64_t integer(std::string_view key, std::int64_t fallback, std::int64_t lo, std::int64_t hi) const {
    return opt_int(key, lo, hi).value_or(fallback);
  }

  // An integer or floating-point number (TOML writes 10 and 10.0 apart),
  // finite, in [lo, hi]; lo_open makes the lower bound exclusive.
  std::optional<double> opt_number(std::string_view key, double lo, double hi, bool lo_open = false) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) return std::nullopt;
    std::ostringstream range;
    range << (lo_open ? "(" : "[") << lo << ", " << hi << "]";
    double v = 0.0;
    if (n->is_integer())
      v = static_cast<double>(n->as_integer()->get());
    else if (n->is_floating_point())
      v = n->as_floating_point()->get();
    else
      fail_at(key, "expected a number in " + range.str() + ", got " + type_name(*n));
    if (!std::isfinite(v)) fail_at(key, "expected a finite number in " + range.str());
    if (v < lo || v > hi || (lo_open && v == lo)) {
      std::ostringstream value;
      value << v;
      fail_at(key, value.str() + " is out of range; expected a number in " + range.str());
    }
    return v;
  }
  double number(std::string_view key, double fallback, double lo, double hi, bool lo_open = false) const {
    return opt_number(key, lo, hi, lo_open).value_or(fallback);
  }

  std::optional<std::string> opt_string(std::string_view key) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) return std::nullopt;
    if (!n->is_string()) fail_at(key, "expected a string, got " + type_name(*n));
    return n->as_string()->get();
  }
  std::string string(std::string_view key, const std::string& fallback) const {
    return opt_string(key).value_or(fallback);
  }
  std::string required_string(std::string_view key, const std::string& what_it_is) const {
    require(key, what_it_is);
    std::string s = *opt_string(key);
    if (s.empty()) fail_at(key, "must not be empty (" + what_it_is + ")");
    return s;
  }

  // A string out of a fixed set of names.
  std::string choice(std::string_view key, const std::string& fallback, const std::vector<std::string>& allowed) const {
    const std::optional<std::string> s = opt_string(key);
    if (!s) return fallback;
    if (std::find(allowed.begin(), allowed.end(), *s) == allowed.end())
      fail_at(key, "'" + *s + "' is not allowed; expected one of " + join(allowed));
    return *s;
  }

  // An array of exactly n numbers.
  std::optional<std::vector<double>> opt_numbers(std::string_view key, std::size_t count) const {
    const toml::node* n = table_.get(key);
    if (n == nullptr) return std::nullopt;
    const std::string expected = "expected an array of " + std::to_string(count) + " numbers";
    if (!n->is_array()) fail_at(key, expected + ", got " + type_name(*n));
    const toml::array& a = *n->as_array();
    if (a.size() != count) fail_at(key, expected + ", got " + std::to_string(a.size()) + " elements");
    std::vector<double> out;
    for (const toml::node& e : a) {
      double v = 0.0;
      if (e.is_integer())
        v = static_cast<double>(e.as_integer()->get());
      else if (e.is_floating_point())
        v = e.as_floating_point()->get();
      else
        fail_at(key, expected + ", element " + std::to_string(out.size()) + " is " + type_name(e));
      if (!std::isfinite(v)) fail_at(key, expected + ", element " + std::to_string(out.size()) + " is not finite");
      out.push_back(v);
    }
    return out;
  }

  // Rejects a key that only applies in another configuration.
  void forbid(std::string_view key, const std::string& why) const {
    if (has(key)) fail_at(key, why);
  }

  const Context& ctx() const { return ctx_; }
  const toml::table& table() const { return table_; }

 private:
  const Context& ctx_;
  const toml::table& table_;
  std::string path_;
};

// Seconds as int64 ns (the caller has bounded s, so this cannot overflow).
TimeNs ns_from_seconds(double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); }

bool valid_name(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' || c == '-' || c == '.';
  });
}

// ---- sections ----

void parse_scene_section(const Table& t, SceneConfig& out) {
  t.allow_only({"name", "physics", "gravity_m_s2"});
  out.name = t.required_string("name", "the scene's name: logs, status and the default control socket");
  if (!valid_name(out.name))
    t.fail_at("name", "'" + out.name + "' is not allowed; expected 1..64 characters from A-Z a-z 0-9 _ - .");
  t.require("physics", "flat or ecef");
  const std::string physics = t.choice("physics", "", {"flat", "ecef"});
  out.physics.physics = physics == "flat" ? Physics::flat : Physics::ecef;
  if (out.physics.physics == Physics::ecef)
    t.forbid("gravity_m_s2", "applies to physics = \"flat\" only (ecef uses WGS84 normal gravity)");
  out.physics.flat_gravity_m_s2 = Vec3(0.0, 0.0, t.number("gravity_m_s2", 9.80665, 0.0, 100.0));
}

// "ADDR:PORT" with ADDR an IPv4 literal or a bracketed IPv6 literal.
void parse_endpoint(const Table& t, const std::string& rest, TrajectoryConfig& out) {
  const std::string usage = "expected " + out.source.substr(0, 3) + ":ADDRESS:PORT (IPv4 or [IPv6] literal, port 1..65535)";
  const auto colon = rest.rfind(':');
  if (colon == std::string::npos || colon == 0) t.fail_at("source", "'" + out.source + "': " + usage);
  std::string address = rest.substr(0, colon);
  const std::string port_text = rest.substr(colon + 1);
  if (address.size() >= 2 && address.front() == '[' && address.back() == ']') address = address.substr(1, address.size() - 2);
  unsigned char buffer[16];
  if (inet_pton(AF_INET, address.c_str(), buffer) != 1 && inet_pton(AF_INET6, address.c_str(), buffer) != 1)
    t.fail_at("source", "'" + address + "' is not an IP address literal; " + usage);
  unsigned port = 0;
  const auto [end, ec] = std::from_chars(port_text.data(), port_text.data() + port_text.size(), port);
  if (ec != std::errc() || end != port_text.data() + port_text.size() || port < 1 || port > 65535)
    t.fail_at("source", "port '" + port_text + "' is not 1..65535; " + usage);
  out.address = address;
  out.port = static_cast<std::uint16_t>(port);
}

void parse_trajectory_section(const Table& t, const SceneConfig& scene, TrajectoryConfig& out) {
  t.allow_only({"source", "duration_s", "speed", "knot_interval_s", "loop", "start", "tcp_idle_timeout_s",
                "mavlink_system_id", "mavlink_component_id"});
  const std::string usage =
      "expected file:PATH, udp:ADDR:PORT, mavlink:ADDR:PORT, tcp:ADDR:PORT, stdin or sample:flight|circle|static";
  out.source = t.required_string("source", usage);
  const std::string& s = out.source;
  if (s.rfind("file:", 0) == 0) {
    out.kind = SourceKind::file;
    const std::filesystem::path p(s.substr(5));
    if (p.empty()) t.fail_at("source", "'" + s + "': " + usage);
    out.file_path = (p.is_absolute() ? p : t.ctx().base_dir / p).lexically_normal().string();
    std::error_code ec;
    // A relative path not beside the scene is looked for among the installed
    // example scenes' data too (PREFIX/share/imuemu/config), so an example
    // copied to /etc/imuemu, as the unit reads it, still finds its data.
    const std::string examples_path = (io::installed_data_dir() / "config" / p).lexically_normal().string();
    if (!p.is_absolute() && !std::filesystem::is_regular_file(out.file_path, ec) &&
        std::filesystem::is_regular_file(examples_path, ec))
      out.file_path = examples_path;
    if (!std::filesystem::is_regular_file(out.file_path, ec))
      t.fail_at("source", "trajectory file '" + out.file_path + "' does not exist or is not a regular file" +
                              (p.is_absolute() ? ""
                                               : " (relative paths are taken from the scene file's directory, then from the "
                                                 "installed examples' " + examples_path + ")"));
  } else if (s.rfind("udp:", 0) == 0) {
    out.kind = SourceKind::udp;
    parse_endpoint(t, s.substr(4), out);
  } else if (s.rfind("mavlink:", 0) == 0) {
    out.kind = SourceKind::mavlink_udp;  // MAVLink 2 HIL_STATE_QUATERNION over UDP (docs/pose-wire-format.md §4)
    parse_endpoint(t, s.substr(8), out);
  } else if (s.rfind("tcp:", 0) == 0) {
    out.kind = SourceKind::tcp;
    parse_endpoint(t, s.substr(4), out);
  } else if (s == "stdin") {
    out.kind = SourceKind::stdin_lines;
  } else if (s.rfind("sample:", 0) == 0) {
    out.kind = SourceKind::sample;
    const std::string kind = s.substr(7);
    if (kind == "flight")
      out.sample = SampleMotion::flight;
    else if (kind == "circle")
      out.sample = SampleMotion::circle;
    else if (kind == "static")
      out.sample = SampleMotion::stationary;
    else
      t.fail_at("source", "built-in sample '" + kind + "' is not allowed; expected one of flight, circle or static");
    if (out.sample == SampleMotion::circle && scene.physics.physics != Physics::flat)
      t.fail_at("source", "sample:circle is a flat-scene motion (local NED); set scene.physics = \"flat\"");
  } else {
    t.fail_at("source", "'" + s + "': " + usage);
  }

  const bool replay = out.kind == SourceKind::file || out.kind == SourceKind::sample;
  if (out.kind == SourceKind::sample) {
    // Up to 30 days: longer built-in motions only waste memory for knots.
    out.duration_s = t.number("duration_s", 600.0, 0.0, 30.0 * 86400.0, true);
  } else {
    t.forbid("duration_s", "applies to sample: sources only (a file or live source has its own length)");
  }
  if (!replay) {
    t.forbid("speed", "applies to file: and sample: sources only (a live source sets its own pace)");
    t.forbid("loop", "applies to file: and sample: sources only");
  }
  if (const toml::node* n = t.node("speed")) {
    std::string text;
    if (n->is_string()) {
      text = n->as_string()->get();
    } else if (n->is_integer() || n->is_floating_point()) {
      // Shortest round-trip decimal of the number, then the exact decimal parser.
      const double v = n->is_integer() ? static_cast<double>(n->as_integer()->get()) : n->as_floating_point()->get();
      char buffer[64];
      const auto r = std::to_chars(buffer, buffer + sizeof buffer, v);
      text.assign(buffer, r.ptr);
    } else {
      t.fail_at("speed", "expected a positive number or a string like \"2.5\" or \"1/3\", got " + type_name(*n));
    }
    try {
      out.speed = live::parse_speed_factor(text);
    } catch (const std::exception& e) {
      t.fail_at("speed", e.what());
    }
  }
  out.knot_interval_s = t.number("knot_interval_s", 1.0, 0.0, 3600.0, true);
  // The built-in motions are sampled into knots up front.
  if (out.kind == SourceKind::sample &&
      out.duration_s / out.knot_interval_s + 1.0 > static_cast<double>(limits::kMaxKnots))
    t.fail_at(t.has("knot_interval_s") ? "knot_interval_s" : "duration_s",
              "duration_s / knot_interval_s gives more than " + std::to_string(limits::kMaxKnots / 1'000'000) +
                  " million built-in knots; use a longer knot interval");
  out.loop = t.boolean("loop", false);
  if (out.kind == SourceKind::tcp) out.tcp_idle_timeout_s = t.number("tcp_idle_timeout_s", 5.0, 0.0, 86400.0);
  else t.forbid("tcp_idle_timeout_s", "applies to tcp: sources only");
  if (out.kind == SourceKind::mavlink_udp) {
    // MAVLink ids 1..255: 0 addresses everyone (MAV_COMP_ID_ALL, broadcast)
    // and is never a sender's own (MAVLink guide, "Routing").
    if (const auto id = t.opt_int("mavlink_system_id", 1, 255)) out.mavlink_system_id = static_cast<std::uint8_t>(*id);
    if (const auto id = t.opt_int("mavlink_component_id", 1, 255))
      out.mavlink_component_id = static_cast<std::uint8_t>(*id);
  } else {
    t.forbid("mavlink_system_id", "applies to mavlink: sources only");
    t.forbid("mavlink_component_id", "applies to mavlink: sources only");
  }
  out.start = t.choice("start", "now", {"now", "next-second"}) == "now" ? StartAlignment::now : StartAlignment::next_second;
}

void parse_smoothing_section(const Table& t, SmoothingConfig& out) {
  t.allow_only({"method", "sigma", "mu", "spline_window_knots", "delta", "window_s", "kernel", "kernel_order",
                "kernel_half_width_s", "chart", "derivatives", "ends", "gap_policy", "max_gap_s",
                "closed_form_positions", "attitude_node_step", "min_kernel_samples"});
  out.method = interp::method_from_string(t.choice("method", "hermite", {"hermite", "geodesic", "min-accel", "park-ravani"}));
  if (out.method != interp::Method::min_acceleration) {
    t.forbid("sigma", "applies to method = \"min-accel\" only");
    t.forbid("mu", "applies to method = \"min-accel\" only");
  }
  out.sigma = t.number("sigma", 1.0, limits::kMinSpeedFactor, limits::kMaxSpeedFactor);
  out.mu = t.number("mu", 1.0, limits::kMinSpeedFactor, limits::kMaxSpeedFactor);
  out.spline_window_knots = static_cast<int>(t.integer("spline_window_knots", 4, 1, 64));
  if (t.has("delta") && t.has("window_s"))
    t.fail_at("window_s", "give the window either as delta (samples) or as window_s (seconds), not both");
  if (const auto d = t.opt_int("delta", 1, 1'000'000)) out.delta_samples = static_cast<int>(*d);
  if (const auto w = t.opt_number("window_s", 0.0, 3600.0, true)) out.window_s = *w;
  out.kernel = smoothing::kernel_width_from_string(t.choice("kernel", "window", {"window", "thesis", "seconds"}));
  if (out.kernel != smoothing::KernelWidth::seconds)
    t.forbid("kernel_half_width_s", "applies to kernel = \"seconds\" only");
  out.kernel_half_width_s = t.number("kernel_half_width_s", 1.0, 0.0, 3600.0, true);
  out.kernel_order = static_cast<int>(t.integer("kernel_order", 4, 2, 4));
  if (out.kernel_order == 3) t.fail_at("kernel_order", "3 is not allowed; expected 2 (positive bump) or 4 (preserves cubics)");
  out.chart = chart_from_string(t.choice("chart", "local", {"local", "global"}));
  out.derivatives = derivatives_from_string(t.choice("derivatives", "kernel", {"kernel", "finite-difference"}));
  out.ends = ends_from_string(t.choice("ends", "extrapolate", {"extrapolate", "clip"}));
  out.gap_policy = gap_policy_from_string(t.choice("gap_policy", "split", {"split", "error"}));
  out.max_gap_s = t.number("max_gap_s", 10.0, 0.0, 86400.0, true);
  out.closed_form_positions = t.boolean("closed_form_positions", true);
  out.attitude_node_step = static_cast<int>(t.integer("attitude_node_step", 0, 0, 1'000'000));
  out.min_kernel_samples = static_cast<int>(t.integer("min_kernel_samples", 100, 0, 100'000));
}

void parse_live_section(const Table& t, LiveConfig& out) {
  t.allow_only({"underrun", "blend_s", "margin_s", "latency_budget_ms"});
  out.underrun = live::underrun_policy_from_string(t.choice("underrun", "extrapolate", {"extrapolate", "pause"}));
  out.blend_s = t.number("blend_s", 0.2, 0.0, 60.0);
  out.margin_s = t.number("margin_s", 0.1, 0.0, 60.0);
  if (t.has("latency_budget_ms")) {
    // At least 1 ms (the producer's wake-up and the write need time), at
    // most a minute (the smoothing method fits in far less).
    out.latency_budget_ms = t.number("latency_budget_ms", 0.0, 1.0, 60000.0);
    if (t.has("margin_s"))
      t.fail_at("latency_budget_ms", "set either latency_budget_ms or margin_s: the budget replaces look-ahead + margin");
  }
}

void parse_daemon_section(const Table& t, const std::string& scene_name, DaemonConfig& out) {
  t.allow_only({"realtime_priority", "lock_memory", "require_realtime", "control_socket", "control_group",
                "status_interval_s", "watchdog", "late_ticks", "device_missing", "device_retry_initial_s", "device_retry_max_s", "fault_log"});
  out.realtime_priority = static_cast<int>(t.integer("realtime_priority", 0, 0, 99));
  out.lock_memory = t.boolean("lock_memory", false);
  out.require_realtime = t.boolean("require_realtime", false);
  out.control_socket = t.string("control_socket", "/run/imuemu/" + scene_name + ".sock");
  if (!std::filesystem::path(out.control_socket).is_absolute())
    t.fail_at("control_socket", "'" + out.control_socket + "' must be an absolute path");
  // sockaddr_un.sun_path holds 108 bytes including the terminating NUL.
  if (out.control_socket.size() > 107)
    t.fail_at("control_socket", "path is " + std::to_string(out.control_socket.size()) + " bytes; a Unix socket path holds at most 107");
  out.control_group = t.string("control_group", "");
  out.fault_log = t.string("fault_log", "");  // issue 18 ground truth (JSON lines); empty: none
  out.status_interval_s = t.number("status_interval_s", 1.0, 0.0, 86400.0);
  out.watchdog = t.boolean("watchdog", true);
  out.drop_late_ticks = t.choice("late_ticks", "drop", {"drop", "send"}) == "drop";
  out.device_missing = t.choice("device_missing", "fail", {"fail", "wait"}) == "fail" ? DeviceMissingPolicy::fail
                                                                                    : DeviceMissingPolicy::wait;
  if (out.device_missing == DeviceMissingPolicy::fail) {
    t.forbid("device_retry_initial_s", "applies to device_missing = \"wait\" only");
    t.forbid("device_retry_max_s", "applies to device_missing = \"wait\" only");
  }
  out.device_retry_initial_s = t.number("device_retry_initial_s", 0.1, 0.001, 3600.0);
  out.device_retry_max_s = t.number("device_retry_max_s", std::max(2.0, out.device_retry_initial_s), 0.001, 3600.0);
  if (out.device_retry_max_s < out.device_retry_initial_s)
    t.fail_at("device_retry_max_s", "must be >= device_retry_initial_s");
}

void parse_mounting(const Table& t, Mounting& out) {
  t.allow_only({"heading_deg", "pitch_deg", "roll_deg", "quaternion", "lever_arm_m"});
  if (t.has("quaternion") && (t.has("heading_deg") || t.has("pitch_deg") || t.has("roll_deg")))
    t.fail_at("quaternion", "give the rotation either as heading_deg/pitch_deg/roll_deg or as quaternion, not both");
  if (const auto q = t.opt_numbers("quaternion", 4)) {
    const double norm = std::sqrt((*q)[0] * (*q)[0] + (*q)[1] * (*q)[1] + (*q)[2] * (*q)[2] + (*q)[3] * (*q)[3]);
    if (std::abs(norm - 1.0) > 1e-6) {
      std::ostringstream what;
      what << "norm " << norm << " is not a unit quaternion [w, x, y, z] (|q| = 1 within 1e-6)";
      t.fail_at("quaternion", what.str());
    }
    // Normalised so the matrix is a rotation to rounding.
    out.sensor_to_body = attitude::rotation_from_quaternion((*q)[0] / norm, (*q)[1] / norm, (*q)[2] / norm, (*q)[3] / norm);
  } else {
    attitude::HeadingPitchRoll hpr;
    hpr.heading_rad = t.number("heading_deg", 0.0, -360.0, 360.0) * kDegToRad;
    hpr.pitch_rad = t.number("pitch_deg", 0.0, -90.0, 90.0) * kDegToRad;
    hpr.roll_rad = t.number("roll_deg", 0.0, -360.0, 360.0) * kDegToRad;
    out.sensor_to_body = attitude::rotation_from_hpr(hpr);
  }
  if (const auto l = t.opt_numbers("lever_arm_m", 3)) {
    out.lever_arm_b_m = Vec3((*l)[0], (*l)[1], (*l)[2]);
    // A sensor kilometres from the reference point is a unit mistake (mm?).
    if (out.lever_arm_b_m.cwiseAbs().maxCoeff() > 1000.0)
      t.fail_at("lever_arm_m", "components must be within +-1000 m (metres, body forward-right-down)");
  }
}

const std::vector<std::string> kProtocols = {"native", "mavlink2", "mip", "nmea", "ubx", "vectornav", "sbg", "xsens", "dronecan", "j1939"};
// The option table each protocol takes (named as the protocol is).
std::string option_table_of(const std::string& protocol) { return drivers::protocol_option_table_name(protocol); }

// The device's protocol table, read by the one protocol option table
// (drivers/protocols/protocol_options.hpp) that `imuemu emit` also uses:
// keys, types and ranges come from there, the TOML reading and its
// file:line:column errors from here.
void parse_protocol_options(const Table& imu, ImuConfig& out) {
  for (const std::string& p : kProtocols) {
    const std::string table = option_table_of(p);
    if (p != out.protocol && imu.has(table))
      imu.fail_at(table, "options for protocol " + p + ", but this device's protocol is " + out.protocol +
                             " (its options go in " + imu.key_path(option_table_of(out.protocol)) + ")");
  }
  drivers::ProtocolOptions options = drivers::default_protocol_options(static_cast<double>(out.rate_hz));
  if (const std::optional<Table> t = imu.subtable(option_table_of(out.protocol))) {
    const std::vector<const drivers::ProtocolOption*> rows = drivers::protocol_options_of(out.protocol);
    std::vector<std::string> keys;
    for (const drivers::ProtocolOption* row : rows) keys.push_back(row->key);
    t->allow_only(keys);
    std::set<std::string> given;
    for (const drivers::ProtocolOption* row : rows) {
      if (!t->has(row->key)) continue;
      given.insert(row->key);
      drivers::OptionValue value;
      switch (row->type) {
        case drivers::OptionType::boolean:
          value = *t->opt_bool(row->key);
          break;
        case drivers::OptionType::integer:
          value = *t->opt_int(row->key, row->integer_min, row->integer_max);
          break;
        case drivers::OptionType::number:
          value = *t->opt_number(row->key, row->number_min, row->number_max, row->number_min_open);
          break;
        case drivers::OptionType::choice:
          value = t->choice(row->key, row->default_text, row->choices);
          break;
        case drivers::OptionType::text: {
          std::string text = *t->opt_string(row->key);
          if (const std::optional<std::string> why = drivers::text_problem(*row, text))
            t->fail_at(row->key, "'" + text + "' " + *why + "; expected " + drivers::allowed_text(*row));
          value = std::move(text);
          break;
        }
      }
      row->apply(options, value);
    }
    if (const auto problem = drivers::finish_protocol_options(out.protocol, options, given))
      t->fail_at(problem->key, problem->message);
  }
  out.stream_options = options.stream;
  out.can_options = options.can;
}

void parse_transport(const Table& t, const ImuConfig& imu, TransportConfig& out) {
  t.require("type", "pty, serial, udp, tcp_server, can or null");
  const std::string type = t.choice("type", "", {"pty", "serial", "udp", "tcp_server", "can", "null"});
  const bool can_protocol = is_can_protocol(imu.protocol);
  if (type == "pty") {
    out.type = TransportType::pty;
    t.allow_only({"type", "link", "mode", "queue_bytes"}, " (type pty)");
    out.pty.link = t.required_string("link", "absolute path of the symlink to the pty, e.g. /run/imuemu/ttyIMU0");
    if (!std::filesystem::path(out.pty.link).is_absolute())
      t.fail_at("link", "'" + out.pty.link + "' must be an absolute path");
    if (const toml::node* n = t.node("mode")) {
      // 0o660 (TOML octal integer) or "0660" (string, octal).
      std::int64_t mode = -1;
      if (n->is_integer()) {
        mode = n->as_integer()->get();
      } else if (n->is_string()) {
        const std::string s = n->as_string()->get();
        unsigned v = 0;
        const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v, 8);
        if (ec == std::errc() && end == s.data() + s.size() && !s.empty()) mode = v;
      } else {
        t.fail_at("mode", "expected permission bits as 0o660 or \"0660\", got " + type_name(*n));
      }
      if (mode < 0 || mode > 0777) t.fail_at("mode", "expected octal permission bits 0..0777, e.g. 0o660 or \"0660\"");
      out.pty.mode = static_cast<unsigned>(mode);
    }
    out.pty.queue_bytes = static_cast<std::size_t>(t.integer("queue_bytes", 32 * 1024, 1024, 64 << 20));
  } else if (type == "serial") {
    out.type = TransportType::serial;
    t.allow_only({"type", "port", "baud", "data_bits", "parity", "stop_bits", "flow_control", "queue_bytes"}, " (type serial)");
    out.serial.port = t.required_string("port", "the serial device, e.g. /dev/ttyUSB0");
    drivers::SerialSettings& s = out.serial.settings;
    s.baud = static_cast<int>(t.integer("baud", s.baud, 1, 100'000'000));
    s.data_bits = static_cast<int>(t.integer("data_bits", s.data_bits, 5, 8));
    s.stop_bits = static_cast<int>(t.integer("stop_bits", s.stop_bits, 1, 2));
    s.parity = drivers::parse_parity(t.choice("parity", "none", {"none", "odd", "even", "mark", "space"}));
    s.flow_control = drivers::parse_flow_control(t.choice("flow_control", "none", {"none", "rtscts", "xonxoff"}));
    try {
      drivers::validate(s);
    } catch (const std::exception& e) {
      t.ctx().fail(t.where(), t.path(), e.what());
    }
    out.serial.queue_bytes = static_cast<std::size_t>(t.integer("queue_bytes", 0, 0, 64 << 20));
  } else if (type == "udp") {
    // MAVLink's convention: a ground station listens on 14550 and answers to
    // the port a datagram came from (drivers/net_transport.hpp).
    out.type = TransportType::udp;
    t.allow_only({"type", "host", "port", "bind_port", "queue_bytes"}, " (type udp)");
    out.net.host = t.string("host", "127.0.0.1");
    if (out.net.host.empty()) t.fail_at("host", "expected an IPv4 address or host name");
    out.net.port = static_cast<std::uint16_t>(t.integer("port", 14550, 1, 65535));
    out.net.bind_port = static_cast<std::uint16_t>(t.integer("bind_port", 0, 0, 65535));
    out.net.queue_bytes = static_cast<std::size_t>(t.integer("queue_bytes", 32 * 1024, 1024, 64 << 20));
  } else if (type == "tcp_server") {
    // One client at a time (as PX4's simulator link: the simulator listens, PX4 connects).
    out.type = TransportType::tcp_server;
    t.allow_only({"type", "listen", "port", "queue_bytes"}, " (type tcp_server)");
    out.net.host = t.string("listen", "0.0.0.0");
    if (out.net.host.empty()) t.fail_at("listen", "expected an IPv4 address to listen on, e.g. 0.0.0.0");
    t.require("port", "the TCP port to listen on, 1..65535");
    out.net.port = static_cast<std::uint16_t>(t.integer("port", 0, 1, 65535));
    out.net.queue_bytes = static_cast<std::size_t>(t.integer("queue_bytes", 32 * 1024, 1024, 64 << 20));
  } else if (type == "can") {
    out.type = TransportType::can;
    t.allow_only({"type", "interface", "fd", "bitrate_switch", "bitrate", "data_bitrate"}, " (type can)");
    out.can.interface = t.required_string("interface", "the SocketCAN interface, e.g. can0 or vcan0");
    if (out.can.interface.size() > 15)  // IFNAMSIZ - 1
      t.fail_at("interface", "'" + out.can.interface + "' is longer than 15 characters (IFNAMSIZ)");
    out.can.fd = t.boolean("fd", false);
    if (!out.can.fd) {
      t.forbid("bitrate_switch", "applies to fd = true only");
      t.forbid("data_bitrate", "applies to fd = true only (classic CAN has one bit rate)");
    }
    out.can.bitrate_switch = t.boolean("bitrate_switch", true);
    // ISO 11898-1: the arbitration phase runs at up to 1 Mbit/s.
    out.can.bitrate = t.integer("bitrate", 1'000'000, 1'000, 1'000'000);
    out.can.data_bitrate = t.integer("data_bitrate", out.can.bitrate, out.can.bitrate, 20'000'000);
  } else {
    out.type = TransportType::null;
    t.allow_only({"type"}, " (type null)");
  }
  if (out.type == TransportType::can && !can_protocol)
    t.fail_at("type", "protocol " + imu.protocol + " is a byte stream; it needs transport type pty, serial, udp, tcp_server or null");
  if ((out.type == TransportType::pty || out.type == TransportType::serial || out.type == TransportType::udp ||
       out.type == TransportType::tcp_server) &&
      can_protocol)
    t.fail_at("type", "protocol " + imu.protocol + " sends CAN frames; it needs transport type can or null");
}

void parse_sync(const Table& t, const ImuConfig& imu, SyncConfig& out) {
  t.allow_only({"chip", "line", "every_n_samples", "width_us", "active_low", "pps_line", "pps_chip", "pps_width_ms",
                "pps_active_low", "trailing_edge_priority"});
  out.chip = t.required_string("chip", "GPIO chip: gpiochip0, /dev/gpiochip0, 0 or its label");
  t.require("line", "line offset on the chip");
  out.line = static_cast<unsigned>(*t.opt_int("line", 0, 65535));
  out.every_n_samples = static_cast<std::uint64_t>(t.integer("every_n_samples", 1, 1, 1'000'000));
  out.width_ns = ns_from_seconds(t.number("width_us", 100.0, 0.0, 1e6, true) * 1e-6);
  // Pulses must end before the next one is due (drivers/gpio_sync.hpp).
  const double spacing_ns = static_cast<double>(out.every_n_samples) * 1e9 / static_cast<double>(imu.rate_hz);
  if (static_cast<double>(out.width_ns) >= spacing_ns) {
    std::ostringstream what;
    what << "a " << static_cast<double>(out.width_ns) * 1e-3 << " us pulse every " << out.every_n_samples
         << " samples at " << imu.rate_hz << " Hz overlaps the next one (" << spacing_ns * 1e-3 << " us apart)";
    t.fail_at(t.has("width_us") ? "width_us" : "every_n_samples", what.str());
  }
  out.active_low = t.boolean("active_low", false);
  if (const auto l = t.opt_int("pps_line", 0, 65535)) out.pps_line = static_cast<unsigned>(*l);
  if (!out.pps_line) {
    for (const char* k : {"pps_chip", "pps_width_ms", "pps_active_low"}) t.forbid(k, "applies when pps_line is set");
  }
  out.pps_chip = t.string("pps_chip", "");
  out.pps_width_ns = ns_from_seconds(t.number("pps_width_ms", 100.0, 0.0, 999.0, true) * 1e-3);
  out.pps_active_low = t.boolean("pps_active_low", false);
  if (out.pps_line && *out.pps_line == out.line && (out.pps_chip.empty() || out.pps_chip == out.chip))
    t.fail_at("pps_line", "is the sync line itself; the 1PPS output needs its own line");
  out.trailing_edge_priority = static_cast<int>(t.integer("trailing_edge_priority", 0, 0, 99));
}

// [imu.device] (issue 27, docs/mip-device.md): how the emulated MIP device
// behaves toward its driver and who it says it is.
void parse_mip_device(const Table& t, drivers::MipDeviceConfig& d) {
  t.allow_only({"answers_commands", "power_up_mode", "model_name", "model_number", "serial_number", "lot_number",
                "device_options", "firmware_version", "hardware_revision"});
  d.answers_commands = t.boolean("answers_commands", d.answers_commands);
  d.power_up_idle = t.choice("power_up_mode", "streaming", {"streaming", "idle"}) == "idle";
  // Get Device Information (0x01,0x03) carries each string in 16 characters.
  for (const auto& [key, field] : {std::pair<const char*, std::string*>{"model_name", &d.model_name},
                                   {"model_number", &d.model_number},
                                   {"serial_number", &d.serial_number},
                                   {"lot_number", &d.lot_number},
                                   {"device_options", &d.device_options}}) {
    *field = t.string(key, *field);
    if (field->size() > 16) t.fail_at(key, "'" + *field + "' is longer than the 16 characters of its MIP field");
    for (const char c : *field)
      if (c < 0x20 || c > 0x7E) t.fail_at(key, "printable ASCII only (a 16-character MIP string field)");
  }
  // "major.minor.patch", sent as 1000 major + 100 minor + patch (u16), as
  // the MIP SDK decodes it: 1.1.08 -> 1108.
  if (const std::optional<std::string> v = t.opt_string("firmware_version")) {
    unsigned major = 0, minor = 0, patch = 0;
    char extra = 0;
    if (std::sscanf(v->c_str(), "%u.%u.%u%c", &major, &minor, &patch, &extra) != 3 || major > 64 || minor > 9 ||
        patch > 99)
      t.fail_at("firmware_version", "'" + *v + "': expected major.minor.patch with minor 0..9 and patch 0..99 "
                                              "(e.g. \"1.1.08\"), major 0..64");
    d.firmware_version = static_cast<std::uint16_t>(1000 * major + 100 * minor + patch);
  }
  d.hardware_revision = t.string("hardware_revision", d.hardware_revision);
}

// "major.minor" of a DroneCAN SoftwareVersion / HardwareVersion (uint8 each).
void parse_major_minor(const Table& t, const char* key, std::uint8_t& major, std::uint8_t& minor) {
  const std::optional<std::string> v = t.opt_string(key);
  if (!v) return;
  unsigned a = 0, b = 0;
  char extra = 0;
  if (std::sscanf(v->c_str(), "%u.%u%c", &a, &b, &extra) != 2 || a > 255 || b > 255)
    t.fail_at(key, "'" + *v + "': expected major.minor, each 0..255 (e.g. \"1.2\")");
  major = static_cast<std::uint8_t>(a);
  minor = static_cast<std::uint8_t>(b);
}

void check_printable(const Table& t, const char* key, const std::string& value, std::size_t max_bytes) {
  if (value.size() > max_bytes)
    t.fail_at(key, "'" + value + "' is longer than " + std::to_string(max_bytes) + " characters");
  for (const char c : value)
    if (c < 0x20 || c > 0x7E || c == '*') t.fail_at(key, "printable ASCII only (no '*')");
}

// [imu.device] for protocol dronecan (issue 27, docs/can-device.md): the
// identity GetNodeInfo reports and the power-up NodeStatus.
void parse_dronecan_device(const Table& t, drivers::dronecan::DroneCanOptions& d) {
  t.allow_only({"power_up_initialization", "node_name", "software_version", "vcs_commit", "hardware_version",
                "unique_id"});
  d.initialization_at_power_up = t.boolean("power_up_initialization", d.initialization_at_power_up);
  d.name = t.string("node_name", d.name);
  if (d.name.empty()) t.fail_at("node_name", "must not be empty");
  check_printable(t, "node_name", d.name, drivers::dronecan::kNodeNameMaxBytes);
  parse_major_minor(t, "software_version", d.software_major, d.software_minor);
  parse_major_minor(t, "hardware_version", d.hardware_major, d.hardware_minor);
  d.software_vcs_commit = static_cast<std::uint32_t>(t.integer("vcs_commit", d.software_vcs_commit, 0, 0xFFFFFFFFLL));
  if (const std::optional<std::string> u = t.opt_string("unique_id")) {
    std::array<std::uint8_t, 16> id{};
    bool ok = u->size() == 32;
    for (std::size_t i = 0; ok && i < 16; ++i) {
      unsigned byte = 0;
      ok = std::sscanf(u->substr(2 * i, 2).c_str(), "%2x", &byte) == 1 && std::isxdigit(static_cast<unsigned char>((*u)[2 * i])) &&
           std::isxdigit(static_cast<unsigned char>((*u)[2 * i + 1]));
      id[i] = static_cast<std::uint8_t>(byte);
    }
    if (!ok) t.fail_at("unique_id", "'" + *u + "': expected 32 hexadecimal digits (the 128-bit unique id)");
    d.unique_id = id;
  }
}

// [imu.device] for protocol j1939 (issue 27, docs/can-device.md): what
// Component and Software Identification report.
void parse_j1939_device(const Table& t, drivers::j1939::J1939Options& d) {
  t.allow_only({"make", "model", "serial_number", "unit_number", "software_id"});
  d.make = t.string("make", d.make);
  check_printable(t, "make", d.make, 5);  // SPN 586: up to 5 characters
  d.model = t.string("model", d.model);
  check_printable(t, "model", d.model, 32);
  d.serial_number = t.string("serial_number", d.serial_number);
  check_printable(t, "serial_number", d.serial_number, 32);
  d.unit_number = t.string("unit_number", d.unit_number);
  check_printable(t, "unit_number", d.unit_number, 32);
  if (const std::optional<std::string> s = t.opt_string("software_id")) {
    check_printable(t, "software_id", *s, 200);
    d.software_ids = {*s};
  }
}

ImuConfig parse_imu(const Table& t) {
  ImuConfig imu;
  imu.line = t.where().begin.line;
  std::vector<std::string> allowed = {"name",      "rate_hz",     "protocol", "mounting",     "transport",
                                      "sync",      "error_model", "fault",    "random_faults", "device"};
  for (const std::string& p : kProtocols) allowed.push_back(option_table_of(p));
  t.allow_only(allowed);
  imu.name = t.required_string("name", "the device's name in logs, status and the control socket");
  if (!valid_name(imu.name))
    t.fail_at("name", "'" + imu.name + "' is not allowed; expected 1..64 characters from A-Z a-z 0-9 _ - .");
  t.require("rate_hz", "output rate in Hz, integer 1..100000");
  imu.rate_hz = *t.opt_int("rate_hz", 1, 100'000);
  t.require("protocol", "one of native, mavlink2, mip, nmea, ubx, vectornav, sbg, xsens, dronecan or j1939");
  imu.protocol = t.choice("protocol", "", kProtocols);
  // A GNSS receiver (issue 28): rate_hz is its navigation rate.
  if (drivers::is_gnss_protocol(imu.protocol) && imu.rate_hz > drivers::kMaxGnssRateHz)
    t.fail_at("rate_hz", "protocol " + imu.protocol + " is a GNSS receiver: its navigation rate is 1.." +
                             std::to_string(drivers::kMaxGnssRateHz) + " Hz, not " + std::to_string(imu.rate_hz));
  if (const auto m = t.subtable("mounting")) parse_mounting(*m, imu.mounting);
  parse_protocol_options(t, imu);
  // The key of the protocol's random terms (GNSS receiver errors, MAVLink
  // barometer, magnetometer and HIL_GPS), with the seed, as the IMU noise's.
  imu.stream_options.device_name = imu.name;
  if (const auto dt = t.subtable("device")) {
    // The devices that answer their driver (issue 27): MIP, DroneCAN, J1939.
    if (imu.protocol == "mip") parse_mip_device(*dt, imu.stream_options.mip_device);
    else if (imu.protocol == "dronecan") parse_dronecan_device(*dt, imu.can_options.dronecan);
    else if (imu.protocol == "j1939") parse_j1939_device(*dt, imu.can_options.j1939);
    else
      t.fail_at("device", "applies to protocols mip, dronecan and j1939 (the devices that answer their driver); "
                          "this device's protocol is " + imu.protocol);
  }
  try {
    if (is_can_protocol(imu.protocol))
      (void)drivers::make_can_encoder(imu.protocol, imu.can_options);
    else
      (void)drivers::make_stream_encoder(imu.protocol, imu.stream_options);
  } catch (const std::exception& e) {
    t.fail_at(option_table_of(imu.protocol), e.what());
  }
  t.require("transport", "a table with type = pty, serial, can or null");
  parse_transport(*t.subtable("transport"), imu, imu.transport);
  if (const auto s = t.subtable("sync")) {
    imu.sync.emplace();
    parse_sync(*s, imu, *imu.sync);
  }
  if (const auto e = t.subtable("error_model")) {  // daemon/scene/error_model_config.cpp
    const toml::table& em = *t.node("error_model")->as_table();
    imu.error_model = parse_error_model_table(em, t.ctx().file, e->path());
    // Vibration reaches the sensor through its mounting (lever arm, axes).
    imu.error_model.chain.vibration.lever_arm_m = imu.mounting.lever_arm_b_m;
    imu.error_model.chain.vibration.sensor_to_body = imu.mounting.sensor_to_body;
    // The chain against this device's rate (a preset may not run at it, a
    // filter frequency may lie beyond half the internal rate).
    const std::string at_rate = " (at rate_hz " + std::to_string(imu.rate_hz) + ")";
    const toml::node* sc = em.get("signal_chain");
    try {
      (void)signal_chain::resolve(imu.error_model.chain, imu.rate_hz);
    } catch (const SettingError& ex) {  // one key at fault (a stage's frequency, compensate_delay): there
      if (sc != nullptr && sc->is_table())
        throw_at_setting(*sc->as_table(), t.ctx().file, e->path() + ".signal_chain", ex, at_rate);
      throw SceneError(t.ctx().file, em.source().begin.line, em.source().begin.column, e->path() + ".signal_chain",
                       std::string(ex.what()) + at_rate);
    } catch (const std::invalid_argument& ex) {
      const toml::source_region at = sc != nullptr ? sc->source() : em.source();
      throw SceneError(t.ctx().file, at.begin.line, at.begin.column, e->path() + ".signal_chain",
                       std::string(ex.what()) + at_rate);
    }
  }
  // The MAVLink barometer, magnetometer and HIL_GPS random terms, keyed as
  // the IMU's: the error model's seed and the device's name (above).
  imu.stream_options.aiding_seed = imu.error_model.spec.seed;
  // Faults (daemon/scene/fault_config.cpp), seeded from the error model's seed.
  DeviceFaults faults = parse_device_faults(t.table(), t.ctx().file, t.path(), imu.name, imu.rate_hz, imu.error_model.spec.seed);
  imu.faults = std::move(faults.faults);
  imu.random_faults = std::move(faults.random);
  return imu;
}

// Resources two devices cannot share.
void check_unique(const Context& ctx, const toml::array& imus, const SceneConfig& scene) {
  std::map<std::string, std::string> owner;  // resource -> "imu[i]"
  auto claim = [&](std::size_t i, const std::string& resource, const std::string& key, const std::string& label) {
    const std::string who = "imu[" + std::to_string(i) + "]";
    const auto [it, inserted] = owner.emplace(resource, who + " (" + scene.imus[i].name + ")");
    if (inserted) return;
    // Point at the offending value: walk the key path inside this [[imu]].
    const toml::node* n = imus[i].as_table();
    std::string rest = key;
    while (n != nullptr && !rest.empty()) {
      const auto dot = rest.find('.');
      n = n->as_table() != nullptr ? n->as_table()->get(rest.substr(0, dot)) : nullptr;
      rest = dot == std::string::npos ? "" : rest.substr(dot + 1);
    }
    const toml::source_region where = n != nullptr ? n->source() : imus[i].source();
    ctx.fail(where, who + "." + key, label + " is already used by " + it->second + "; each device needs its own");
  };
  std::map<std::string, std::size_t> can_bus;  // interface -> first device on it
  for (std::size_t i = 0; i < scene.imus.size(); ++i) {
    const ImuConfig& imu = scene.imus[i];
    claim(i, "name:" + imu.name, "name", "name '" + imu.name + "'");
    if (imu.transport.type == TransportType::can) {
      // One bus, one set of bit rates: the budget adds the devices' traffic.
      const auto [it, first] = can_bus.emplace(imu.transport.can.interface, i);
      const CanConfig& a = scene.imus[it->second].transport.can;
      const CanConfig& b = imu.transport.can;
      if (!first && (a.fd != b.fd || a.bitrate != b.bitrate || a.data_bitrate != b.data_bitrate))
        ctx.fail(imus[i].source(), "imu[" + std::to_string(i) + "].transport",
                 "interface " + b.interface + " is also used by imu[" + std::to_string(it->second) + "] (" +
                     scene.imus[it->second].name + ") with other fd/bitrate/data_bitrate; one bus has one setting");
    }
    const TransportConfig& tr = imu.transport;
    if (tr.type == TransportType::pty) {
      claim(i, "path:" + tr.pty.link, "transport.link", "pty link " + tr.pty.link);
      if (tr.pty.link == scene.daemon.control_socket)
        ctx.fail(imus[i].source(), "imu[" + std::to_string(i) + "].transport.link", "is the control socket's path");
    }
    if (tr.type == TransportType::serial) claim(i, "path:" + tr.serial.port, "transport.port", "serial port " + tr.serial.port);
    if (tr.type == TransportType::can && imu.protocol == "dronecan")
      claim(i, "dronecan:" + tr.can.interface + ":" + std::to_string(imu.can_options.dronecan.node_id), "dronecan.node_id",
            "DroneCAN node id " + std::to_string(imu.can_options.dronecan.node_id) + " on " + tr.can.interface);
    if (tr.type == TransportType::can && imu.protocol == "j1939")
      claim(i, "j1939:" + tr.can.interface + ":" + std::to_string(imu.can_options.j1939.source_address),
            "j1939.source_address",
            "J1939 source address " + std::to_string(imu.can_options.j1939.source_address) + " on " + tr.can.interface);
    if (imu.sync) {
      claim(i, "gpio:" + imu.sync->chip + ":" + std::to_string(imu.sync->line), "sync.line",
            "GPIO line " + imu.sync->chip + ":" + std::to_string(imu.sync->line));
      if (imu.sync->pps_line) {
        const std::string chip = imu.sync->pps_chip.empty() ? imu.sync->chip : imu.sync->pps_chip;
        claim(i, "gpio:" + chip + ":" + std::to_string(*imu.sync->pps_line), "sync.pps_line",
              "GPIO line " + chip + ":" + std::to_string(*imu.sync->pps_line));
      }
    }
  }
}

SceneConfig parse_document(const Context& ctx, const toml::table& root) {
  SceneConfig scene;
  scene.file = ctx.file;
  const Table top(ctx, root, "");
  top.allow_only({"scene", "trajectory", "smoothing", "live", "daemon", "imu"});
  top.require("scene", "[scene] with name and physics");
  parse_scene_section(*top.subtable("scene"), scene);
  top.require("trajectory", "[trajectory] with source");
  parse_trajectory_section(*top.subtable("trajectory"), scene, scene.trajectory);
  if (const auto s = top.subtable("smoothing")) parse_smoothing_section(*s, scene.smoothing);
  if (const auto l = top.subtable("live")) parse_live_section(*l, scene.live);
  {
    static const toml::table empty;
    const auto d = top.subtable("daemon");
    parse_daemon_section(d ? *d : Table(ctx, empty, "daemon"), scene.name, scene.daemon);
  }

  top.require("imu", "one or more [[imu]] tables");
  const toml::node* imu_node = root.get("imu");
  if (!imu_node->is_array_of_tables() || imu_node->as_array()->empty())
    top.fail_at("imu", "expected one or more [[imu]] tables, got " + type_name(*imu_node));
  const toml::array& imus = *imu_node->as_array();
  for (std::size_t i = 0; i < imus.size(); ++i) {
    const Table t(ctx, *imus[i].as_table(), "imu[" + std::to_string(i) + "]");
    scene.imus.push_back(parse_imu(t));
    // A GNSS receiver (issue 28) reports geodetic positions: a flat scene's
    // local NED frame has no geodetic anchor.
    if (drivers::is_gnss_protocol(scene.imus.back().protocol) && scene.physics.physics != Physics::ecef)
      t.fail_at("protocol", "protocol " + scene.imus.back().protocol +
                                " is a GNSS receiver: it reports WGS84 positions, which a flat scene does not have; "
                                "set scene.physics = \"ecef\"");
    // A window beyond a million samples is a unit mistake, and would make
    // the engine allocate gigabytes for its kernel.
    const double window_samples = std::round(scene.smoothing.window_s.value_or(scene.trajectory.knot_interval_s) *
                                             static_cast<double>(scene.imus.back().rate_hz));
    const int delta = pipeline_options(scene, scene.imus.back()).kernel.delta;
    if (delta > limits::kMaxWindowSamples)
      ctx.fail(imus[i].source(), t.path(),
               "the smoothing window is " + std::to_string(static_cast<long long>(window_samples)) + " samples at " +
                   std::to_string(scene.imus.back().rate_hz) +
                   " Hz (smoothing.window_s, or trajectory.knot_interval_s by default); at most " +
                   std::to_string(limits::kMaxWindowSamples));
    // The engine's own checks on the combination (window, rate, spline).
    try {
      const StreamPipeline probe(pipeline_options(scene, scene.imus.back()));
    } catch (const std::exception& e) {
      ctx.fail(imus[i].source(), t.path(), std::string("the smoothing options do not work at this rate: ") + e.what());
    }
  }
  check_unique(ctx, imus, scene);
  return scene;
}

}  // namespace

namespace {
// Messages quote the offending value or name: a 100 KB name is shown as its
// first kMaxEchoBytes and an ellipsis, not echoed whole.
constexpr std::size_t kMaxEchoBytes = 200;
std::string bounded(const std::string& text) {
  if (text.size() <= kMaxEchoBytes) return text;
  return text.substr(0, kMaxEchoBytes) + "... (" + std::to_string(text.size()) + " bytes)";
}
}  // namespace

SceneError::SceneError(std::string file, std::uint32_t line, std::uint32_t column, std::string key, const std::string& what)
    : std::runtime_error(bounded(file) + (line > 0 ? ":" + std::to_string(line) + ":" + std::to_string(column) : std::string()) +
                         ": " + (key.empty() ? std::string() : bounded(key) + ": ") +
                         (what.size() <= 8 * kMaxEchoBytes ? what : what.substr(0, 8 * kMaxEchoBytes) + "... (" +
                                                                        std::to_string(what.size()) + " bytes)")),
      file_(std::move(file)),
      line_(line),
      column_(column),
      key_(std::move(key)) {}

bool is_can_protocol(std::string_view protocol) { return protocol == "dronecan" || protocol == "j1939"; }

SceneConfig parse_scene_text(std::string_view toml_text, const std::string& file_name, const std::string& base_dir) {
  Context ctx{file_name, std::filesystem::path(base_dir)};
  toml::table root;
  try {
    root = toml::parse(toml_text, file_name);
  } catch (const toml::parse_error& e) {
    throw SceneError(file_name, e.source().begin.line, e.source().begin.column, "",
                     "TOML syntax: " + std::string(e.description()));
  }
  try {
    return parse_document(ctx, root);
  } catch (const SceneError&) {
    throw;
  } catch (const std::exception& e) {
    // A check below the parser that threw on its own (should not happen:
    // every value is range-checked first); still name the file.
    throw SceneError(file_name, 0, 0, "", e.what());
  }
}

SceneConfig parse_scene_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, 0, 0, "", "cannot open the scene file");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw SceneError(path, 0, 0, "", "cannot read the scene file");
  std::filesystem::path dir = std::filesystem::path(path).parent_path();
  if (dir.empty()) dir = ".";
  return parse_scene_text(text.str(), path, dir.string());
}

PipelineOptions pipeline_options(const SceneConfig& scene, const ImuConfig& imu) {
  const SmoothingConfig& s = scene.smoothing;
  PipelineOptions po;
  po.scene = scene.physics;
  po.rate_hz = imu.rate_hz;
  po.ends = s.ends;
  po.chart = s.chart;
  po.derivatives = s.derivatives;
  po.gap_policy = s.gap_policy;
  po.max_gap_s = s.max_gap_s;
  po.closed_form_positions = s.closed_form_positions;
  po.attitude_node_step = s.attitude_node_step;
  po.min_kernel_samples = s.min_kernel_samples;
  po.interpolation.method = s.method;
  po.interpolation.sigma = s.sigma;
  po.interpolation.mu = s.mu;
  po.interpolation.spline_window_knots = s.spline_window_knots;
  // Window: as `imuemu stream` (one knot interval) unless given.
  const double window_s = s.window_s.value_or(scene.trajectory.knot_interval_s);
  // Beyond the cap (limits::kMaxWindowSamples) the window reads as one more
  // than the cap, which the parser and the engine refuse: the int never overflows.
  const double window_samples = std::round(window_s * static_cast<double>(imu.rate_hz));
  po.kernel.delta = s.delta_samples ? *s.delta_samples
                    : window_samples > static_cast<double>(limits::kMaxWindowSamples)
                        ? static_cast<int>(limits::kMaxWindowSamples + 1)
                        : static_cast<int>(std::max(1.0, window_samples));
  po.kernel.order = s.kernel_order;
  po.kernel.width = s.kernel;
  po.kernel.half_width_s = s.kernel_half_width_s;
  // Only a live scene with a latency budget may change the method (and
  // latency_plan asks this function back with the budget cleared).
  po.causal = scene.live.latency_budget_ms && is_live(scene.trajectory.kind) && latency_plan(scene, imu).causal;
  return po;
}

LatencyPlan latency_plan(const SceneConfig& scene, const ImuConfig& imu) {
  LatencyPlan plan;
  const auto knot_interval_ns = static_cast<TimeNs>(std::llround(scene.trajectory.knot_interval_s * 1e9));
  const auto margin_ns = static_cast<TimeNs>(std::llround(scene.live.margin_s * 1e9));
  SceneConfig smoothing_scene = scene;
  smoothing_scene.live.latency_budget_ms.reset();  // pipeline_options below must not ask back
  plan.smoothing_lookahead_ns = StreamPipeline::lookahead_ns(pipeline_options(smoothing_scene, imu), knot_interval_ns);
  plan.lookahead_ns = plan.smoothing_lookahead_ns;
  plan.emission_delay_ns = saturating_add_ns(plan.smoothing_lookahead_ns, margin_ns);
  // A file or sample source is known whole: the engine reads ahead of it and
  // sends every tick on the trajectory's own schedule, with no delay
  // (scene_runner.cpp sets emit_delay_ns for live input only). Issue 26:
  // check-config said "emitted 8.638 s after the pose" where status said 0.
  if (!is_live(scene.trajectory.kind)) {
    plan.emission_delay_ns = 0;
    return plan;
  }
  if (!scene.live.latency_budget_ms) return plan;
  const auto budget_ns = static_cast<TimeNs>(std::llround(*scene.live.latency_budget_ms * 1e6));
  plan.emission_delay_ns = budget_ns;
  // The window of Eq. 3.68 fits in the budget, with the producer's default
  // lead (it computes each tick that long before it is due).
  if (budget_ns >= saturating_add_ns(plan.smoothing_lookahead_ns, plan.producer_lead_ns)) return plan;
  plan.causal = true;
  plan.lookahead_ns = CausalHermite::lookahead_ns(knot_interval_ns);
  // The producer computes a tick producer_lead before it is due: half of what
  // the budget leaves beyond one pose interval, between 0.5 ms (the
  // producer's wake-up must still come before the emission thread's) and the
  // default 20 ms.
  plan.producer_lead_ns = std::clamp<TimeNs>((budget_ns - knot_interval_ns) / 2, 500'000, 20'000'000);
  plan.arrival_slack_ns = budget_ns - plan.producer_lead_ns - knot_interval_ns;
  return plan;
}

}  // namespace imuemu::scene
