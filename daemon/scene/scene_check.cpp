#include "daemon/scene/scene_check.hpp"

#include "daemon/device/device.hpp"
#include "daemon/scene/error_model_config.hpp"
#include "daemon/scene/fault_config.hpp"

#include <algorithm>
#include <cstdio>
#include <iomanip>
#include <numbers>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <sstream>

#include "core/limits.hpp"
#include "core/mounting.hpp"
#include "core/signal_chain/signal_chain.hpp"
#include "core/stream.hpp"
#include "daemon/scene/scene_runner.hpp"

#include <climits>
#include <filesystem>
#include <unistd.h>

namespace imuemu::scene {
namespace {

std::string describe_transport(const TransportConfig& t) {
  switch (t.type) {
    case TransportType::pty:
      return "pty " + t.pty.link;
    case TransportType::serial:
      return "serial " + t.serial.port + " " + drivers::to_string(t.serial.settings);
    case TransportType::can:
      return "can " + t.can.interface + (t.can.fd ? " (CAN FD)" : "");
    case TransportType::udp:
      return "udp -> " + t.net.host + ":" + std::to_string(t.net.port) +
             (t.net.bind_port != 0 ? " from port " + std::to_string(t.net.bind_port) : "");
    case TransportType::tcp_server:
      return "tcp server " + t.net.host + ":" + std::to_string(t.net.port);
    case TransportType::null:
      return "null";
  }
  return "?";
}

drivers::CanBitRates bit_rates(const CanConfig& c) {
  drivers::CanBitRates r;
  r.nominal_bit_rate = static_cast<double>(c.bitrate);
  r.data_bit_rate = static_cast<double>(c.data_bitrate > 0 ? c.data_bitrate : c.bitrate);
  return r;
}

std::string fixed(double v, int digits) {
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", digits, v);
  return buffer;
}

std::string seconds_text(TimeNs ns) { return fixed(static_cast<double>(ns) * 1e-9, 3) + " s"; }
// Latencies of the causal method are a few ms: shown to 0.1 ms.
std::string ms_text(TimeNs ns) { return fixed(static_cast<double>(ns) * 1e-6, 1) + " ms"; }

// A path as the kernel resolves it, as far as can be told without following
// links that do not exist yet: absolute, ".", ".." and repeated slashes
// removed, the existing part of the directory canonical.
std::string normalised(const std::string& path) {
  namespace fs = std::filesystem;
  fs::path p = fs::path(path).lexically_normal();
  std::error_code ec;
  const fs::path parent = fs::weakly_canonical(p.parent_path(), ec);
  if (!ec && !parent.empty()) p = parent / p.filename();
  std::string text = p.string();
  while (text.size() > 1 && text.rfind("//", 0) == 0) text.erase(0, 1);  // POSIX: "//x" is "/x" on Linux
  return text;
}

}  // namespace

double chain_cpu_seconds(const signal_chain::ChainWork& w) {
  return w.internal_samples * kCpuSecondsPerInternalSample + w.increment_nodes * kCpuSecondsPerIncrementNode +
         w.vibration_rotations * kCpuSecondsPerVibrationRotation + w.vibration_direct * kCpuSecondsPerVibrationDirect;
}

void check_start_paths(const SceneConfig& scene, const RunnerOptions& options, const std::string& control_socket,
                       const OutputPaths& outputs) {
  namespace fs = std::filesystem;
  std::map<std::string, std::string> owner;  // normalised path -> what uses it
  auto claim = [&](const std::string& path, const std::string& what) {
    const std::string key = normalised(path);
    const auto [it, fresh] = owner.emplace(key, what);
    if (!fresh)
      throw std::invalid_argument(scene.file + ": " + what + " and " + it->second + " are the same path (" + key + ")");
  };
  if (!control_socket.empty()) {
    claim(control_socket, "the control socket " + control_socket);
    // The start creates the socket's directory if it can: the nearest
    // existing ancestor must be a writable directory.
    fs::path dir = fs::path(control_socket).parent_path();
    std::error_code ec;
    while (!dir.empty() && !fs::exists(dir, ec) && dir != dir.parent_path()) dir = dir.parent_path();
    if (!fs::is_directory(dir, ec))
      throw std::invalid_argument(scene.file + ": control socket " + control_socket + ": " + dir.string() +
                                  " is not a directory");
    if (dir != fs::path(control_socket).parent_path() && ::access(dir.c_str(), W_OK) != 0)
      throw std::invalid_argument(scene.file + ": control socket " + control_socket + ": its directory does not exist and " +
                                  dir.string() + " is not writable");
  }
  // Two devices cannot listen on one local port (the second bind fails at
  // start, after the first device is already open): said before anything opens.
  std::map<std::string, std::string> local_ports;
  for (const ImuConfig& imu : scene.imus) {
    const NetConfig& n = imu.transport.net;
    std::string key;
    if (imu.transport.type == TransportType::tcp_server) key = "tcp " + std::to_string(n.port);
    if (imu.transport.type == TransportType::udp && n.bind_port != 0) key = "udp " + std::to_string(n.bind_port);
    if (key.empty()) continue;
    const auto [it, fresh] = local_ports.emplace(key, imu.name);
    if (!fresh)
      throw std::invalid_argument(scene.file + ": imu '" + imu.name + "': local " + key.substr(0, 3) + " port " +
                                  key.substr(4) + " is also imu '" + it->second + "''s");
  }
  for (const ImuConfig& imu : scene.imus) {
    if (imu.transport.type != TransportType::pty) continue;
    const std::string link = pty_link_path(imu, options);
    const std::string what = "imu '" + imu.name + "': pty link " + link;
    const fs::path p = fs::path(link).lexically_normal();
    if (!p.has_filename() || p == p.root_path())
      throw std::invalid_argument(scene.file + ": " + what + ": names a directory, not a file");
    if (link.size() >= PATH_MAX || p.filename().string().size() > NAME_MAX)
      throw std::invalid_argument(scene.file + ": " + what.substr(0, 200) + "...: longer than PATH_MAX (" +
                                  std::to_string(PATH_MAX - 1) + ") or a name longer than NAME_MAX (" +
                                  std::to_string(NAME_MAX) + ")");
    std::error_code ec;
    if (fs::is_directory(fs::symlink_status(p, ec)))
      throw std::invalid_argument(scene.file + ": " + what + ": is an existing directory");
    claim(link, what);
    // The pty's flock file: created at the start, removed at exit.
    claim(link + ".lock", what + "'s lock file " + link + ".lock");
  }
  auto check_output = [&](const std::string& path, const std::string& what) {
    if (path.empty()) return;
    const std::string named = what + " " + path;
    claim(path, named);
    std::error_code ec;
    const fs::path p = fs::path(path).lexically_normal();
    const std::string text = p.string();
    const auto in_dev_pts = [](const std::string& t) { return t.rfind("/dev/pts/", 0) == 0 || t == "/dev/ptmx"; };
    if (in_dev_pts(text) || text.rfind("/dev/tty", 0) == 0)
      throw std::invalid_argument(scene.file + ": " + named + ": is a terminal, not a file for an output");
    if (fs::is_symlink(fs::symlink_status(p, ec))) {
      const std::string target = fs::read_symlink(p, ec).string();
      if (!ec && in_dev_pts(target))
        throw std::invalid_argument(scene.file + ": " + named + ": is a symbolic link to the terminal " + target +
                                    " (a pty link, perhaps of another imuemud), not a file for an output");
    }
    if (fs::is_directory(p, ec)) throw std::invalid_argument(scene.file + ": " + named + ": is a directory");
  };
  check_output(outputs.fault_log, "the fault log");
  check_output(outputs.stats_json, "--stats-json");
  if (!outputs.stats_json.empty()) {
    const fs::path p = fs::path(outputs.stats_json);
    const fs::path dir = p.parent_path().empty() ? fs::path(".") : p.parent_path();
    std::error_code ec;
    if (!fs::is_directory(dir, ec))
      throw std::invalid_argument("--stats-json " + outputs.stats_json + ": " + dir.string() + " is not a directory");
    const bool exists = fs::exists(fs::symlink_status(p, ec));
    if (::access(exists ? p.c_str() : dir.c_str(), W_OK) != 0)
      throw std::invalid_argument("--stats-json " + outputs.stats_json + ": cannot be written: " +
                                  (exists ? p.string() : dir.string()) + ": " + std::strerror(errno));
  }
}

void check_startable(const SceneConfig& scene, const RunnerOptions& options) {
  const bool replay = scene.trajectory.kind == SourceKind::file || scene.trajectory.kind == SourceKind::sample;
  if (replay) {
    const std::vector<Pose> once = scene_trajectory(scene);
    for (const ImuConfig& imu : scene.imus) {
      std::vector<Pose> knots;
      knots.reserve(once.size());
      for (const Pose& p : once) knots.push_back(sensor_pose(p, imu.mounting));
      const PipelineOptions po = pipeline_options(scene, imu);
      try {
        (void)batch_sample_count(knots, po.rate_hz);
        StreamPipeline::check_trajectory(knots, po);
      } catch (const std::exception& e) {
        throw std::invalid_argument(scene.file + ": imu '" + imu.name + "': trajectory " + scene.trajectory.source +
                                    ": " + e.what());
      }
    }
  }
  check_start_paths(scene, options, scene.daemon.control_socket, OutputPaths{scene.daemon.fault_log, ""});
}

std::string refusal_text(const SceneCheck& check) {
  std::string text = "refused: ";
  for (std::size_t i = 0; i < check.refusals.size(); ++i) text += (i ? "; " : "") + check.refusals[i];
  if (check.refusals.empty()) text += "see above";
  return text;
}

SceneCheck check_scene(const SceneConfig& scene) {
  SceneCheck check;
  check.file = scene.file;
  check.scene = scene.name;
  check.physics = scene.physics.physics == Physics::flat ? "flat" : "ecef";
  check.source = scene.trajectory.source;
  check.knot_interval_s = scene.trajectory.knot_interval_s;
  const auto knot_interval_ns = static_cast<TimeNs>(std::llround(scene.trajectory.knot_interval_s * 1e9));

  // CAN traffic grouped by interface: the devices there share one bus.
  std::map<std::string, std::vector<std::size_t>> can_devices;
  std::vector<std::vector<drivers::CanTraffic>> can_traffic(scene.imus.size());

  for (std::size_t i = 0; i < scene.imus.size(); ++i) {
    const ImuConfig& imu = scene.imus[i];
    ImuCheck c;
    c.name = imu.name;
    c.protocol = imu.protocol;
    c.transport = describe_transport(imu.transport);
    c.rate_hz = imu.rate_hz;
    const PipelineOptions po = pipeline_options(scene, imu);
    c.delta_samples = po.kernel.delta;
    const LatencyPlan plan = latency_plan(scene, imu);
    c.lookahead_ns = plan.lookahead_ns;
    c.emission_delay_ns = plan.emission_delay_ns;
    c.causal = plan.causal;
    c.smoothing_lookahead_ns = plan.smoothing_lookahead_ns;
    c.producer_lead_ns = plan.producer_lead_ns;
    c.arrival_slack_ns = plan.arrival_slack_ns;
    if (c.causal) {
      const double x = 2.0 * std::numbers::pi * scene.trajectory.knot_interval_s;  // 2 pi f h at f = 1 Hz
      c.accel_error_1hz_with_rates = x * x / 12.0;
      c.accel_error_1hz_estimated = 2.0 * x * x;
      if (plan.arrival_slack_ns < 0)
        check.warnings.push_back(imu.name + ": latency_budget_ms is below one pose interval + the producer lead (" +
                                 ms_text(knot_interval_ns + plan.producer_lead_ns) +
                                 "): the end of every pose interval is extrapolated (flagged) and blended back");
      if (scene.trajectory.knot_interval_s > 0.01 && scene.trajectory.kind != SourceKind::mavlink_udp)
        check.warnings.push_back(imu.name + ": the causal method at " + fixed(1.0 / scene.trajectory.knot_interval_s, 0) +
                                 " Hz poses: below 100 Hz it needs the poses' own rates (pose datagram v2, MAVLink) "
                                 "to be accurate (docs/streaming.md \"Low-latency live input\")");
    }
    // The chain's work per output sample as the producer runs it: the
    // increments in the encoder's convention are computed for every sample.
    c.compensated_increments = is_can_protocol(imu.protocol)
                                   ? drivers::make_can_encoder(imu.protocol, imu.can_options)->compensated_increments()
                                   : drivers::make_stream_encoder(imu.protocol, imu.stream_options)->compensated_increments();
    // The parser resolved this chain at this rate already: it does not throw here.
    const signal_chain::ResolvedChain chain = signal_chain::resolve(imu.error_model.chain, imu.rate_hz);
    c.oversampling = chain.oversampling;
    if (!imu.error_model.chain.vibration.empty())
      c.vibration_components = signal_chain::Vibration(imu.error_model.chain.vibration, imu.name).random_components();
    c.work = signal_chain::predict_work(
        chain, imu.error_model.sensor().has_value(), c.vibration_components,
        c.compensated_increments ? signal_chain::IncrementConvention::compensated : signal_chain::IncrementConvention::raw,
        scene.physics.physics);
    c.cpu_fraction = static_cast<double>(imu.rate_hz) * (kCpuSecondsPerSample + chain_cpu_seconds(c.work));
    if (c.cpu_fraction > 1.0)
      check.warnings.push_back(imu.name + ": estimated CPU " + fixed(100.0 * c.cpu_fraction, 1) +
                               " % of one core: its producer cannot keep up and the device will fall behind "
                               "(late samples dropped); lower the rate, the oversampling or the random vibration's "
                               "components (resolution_hz)");
    const auto rate = static_cast<double>(imu.rate_hz);
    c.faults = fault_lines(imu.faults, imu.random_faults);
    // A scene fault the protocol cannot show is what a start would refuse.
    // (daemon/device/device.hpp check_supports, from the encoder alone: no port opened.)
    auto check_faults = [&](const auto& encoder) {
      std::vector<fault::Kind> kinds;
      for (const fault::FaultSpec& f : imu.faults) kinds.push_back(f.kind);
      kinds.insert(kinds.end(), imu.random_faults.kinds.begin(), imu.random_faults.kinds.end());
      for (const fault::Kind kind : kinds) {
        try {
          device::check_supports(imu.name, encoder, kind);
        } catch (const std::invalid_argument& e) {
          check.refused = true;
          check.warnings.push_back(std::string("fault refused: ") + e.what());
          check.refusals.push_back(std::string("a fault the protocol cannot show: ") + e.what());
        }
      }
    };
    if (is_can_protocol(imu.protocol)) {
      const auto encoder = drivers::make_can_encoder(imu.protocol, imu.can_options);
      check_faults(*encoder);
      can_traffic[i] = drivers::measure_can_traffic(*encoder, rate,
                                                    imu.transport.type == TransportType::can && imu.transport.can.bitrate_switch);
      double frames = 0.0;
      for (const drivers::CanTraffic& t : can_traffic[i]) frames += t.frames_per_second;
      c.can_frames_per_second = frames;
      if (imu.transport.type == TransportType::can) {
        c.link = drivers::can_budget(can_traffic[i], bit_rates(imu.transport.can));
        can_devices[imu.transport.can.interface].push_back(i);
      }
    } else {
      const auto encoder = drivers::make_stream_encoder(imu.protocol, imu.stream_options);
      check_faults(*encoder);
      c.bytes_per_second = encoder->configured_bytes_per_second(rate);
      c.worst_case_bytes_per_second = static_cast<double>(encoder->max_bytes_per_sample()) * rate;
      if (imu.transport.type == TransportType::serial)
        c.link = drivers::uart_budget(*encoder, rate, imu.transport.serial.settings);
    }
    if (c.link) {
      if (c.link->verdict == drivers::BudgetVerdict::refuse) {
        check.refused = true;
        check.refusals.push_back(imu.name + ": its link is loaded beyond 100 %: " + c.link->message);
      }
      if (c.link->verdict != drivers::BudgetVerdict::ok)
        check.warnings.push_back(imu.name + ": link " + drivers::to_string(c.link->verdict) + ": " + c.link->message);
    }
    check.total_cpu_fraction += c.cpu_fraction;
    check.max_emission_delay_ns = std::max(check.max_emission_delay_ns, c.emission_delay_ns);
    c.error_model = error_model_lines(imu.error_model, rate);
    check.imus.push_back(std::move(c));
  }

  for (const auto& [interface, devices] : can_devices) {
    if (devices.size() < 2) continue;
    std::vector<drivers::CanTraffic> all;
    SceneCheck::SharedLink shared;
    shared.link = "can " + interface;
    for (std::size_t i : devices) {
      all.insert(all.end(), can_traffic[i].begin(), can_traffic[i].end());
      shared.devices.push_back(scene.imus[i].name);
    }
    // The parser makes devices on one interface agree on its bit rates.
    shared.budget = drivers::can_budget(all, bit_rates(scene.imus[devices.front()].transport.can));
    if (shared.budget.verdict == drivers::BudgetVerdict::refuse) {
      check.refused = true;
      check.refusals.push_back(shared.link + " is loaded beyond 100 %: " + shared.budget.message);
    }
    if (shared.budget.verdict != drivers::BudgetVerdict::ok)
      check.warnings.push_back(shared.link + " shared by " + std::to_string(devices.size()) + " devices: " +
                               drivers::to_string(shared.budget.verdict) + ": " + shared.budget.message);
    check.shared_links.push_back(std::move(shared));
  }
  if (check.total_cpu_fraction > 0.5)
    check.warnings.push_back("estimated CPU " + fixed(100.0 * check.total_cpu_fraction, 1) +
                             " % of one core: little headroom for the emission deadlines");
  return check;
}

std::string to_text(const SceneCheck& c) {
  std::ostringstream out;
  out << "scene " << c.scene << " (" << c.file << "): " << c.physics << " physics, source " << c.source
      << ", knots every " << fixed(c.knot_interval_s, 3) << " s\n";
  for (const ImuCheck& d : c.imus) {
    out << "  imu " << d.name << ": " << d.rate_hz << " Hz " << d.protocol << " over " << d.transport << "\n"
        << (d.causal ? "    causal Hermite (latency budget below the smoothing look-ahead of " +
                           ms_text(d.smoothing_lookahead_ns) + "); look-ahead " + ms_text(d.lookahead_ns) +
                           " (one pose interval)"
                     : "    window Delta " + std::to_string(d.delta_samples) + " samples; look-ahead " +
                           seconds_text(d.lookahead_ns))
        << (d.emission_delay_ns == 0 && !d.causal
                ? std::string(", emitted on the trajectory's own schedule (a file or sample source is read ahead: no "
                              "emission delay)")
                : ", emitted " + (d.causal ? ms_text(d.emission_delay_ns) : seconds_text(d.emission_delay_ns)) +
                      " after the pose" + (d.causal ? " (latency budget)" : " (look-ahead + margin or latency budget)"))
        << "\n";
    if (d.causal)
      out << "    latency: producer lead " << ms_text(d.producer_lead_ns) << "; a pose arriving up to "
          << ms_text(d.arrival_slack_ns) << " after its mapped time is used exactly, a later one is bridged "
          << "(extrapolated, flagged, blended back)\n"
          << "    accuracy: acceleration error <= " << std::scientific << std::setprecision(1)
          << d.accel_error_1hz_with_rates << " (poses with rates) / " << d.accel_error_1hz_estimated
          << " (rates estimated) of a 1 Hz motion's acceleration amplitude; x f^2 at f Hz\n"
          << std::defaultfloat;
    if (d.bytes_per_second)
      out << "    traffic " << fixed(*d.bytes_per_second, 0) << " B/s as configured (worst case "
          << fixed(d.worst_case_bytes_per_second.value_or(0.0), 0) << " B/s: every output on every sample)\n";
    if (d.can_frames_per_second) out << "    traffic " << fixed(*d.can_frames_per_second, 1) << " CAN frames/s\n";
    if (d.link)
      out << "    link " << fixed(100.0 * d.link->load_fraction, 1) << " % (" << drivers::to_string(d.link->verdict)
          << "): " << d.link->message << "\n";
    else
      out << "    link: no line rate (" << d.transport.substr(0, d.transport.find(' ')) << ")\n";
    out << "    cpu ~" << fixed(100.0 * d.cpu_fraction, 2) << " % of one core";
    if (d.oversampling > 1 || d.vibration_components > 0)
      out << " (signal chain at " << d.oversampling << "x, " << d.vibration_components << " random vibration components)";
    out << "; per sample: " << fixed(d.work.internal_samples, 0) << " internal samples, "
        << fixed(d.work.increment_nodes, 0) << " nodes of " << (d.compensated_increments ? "compensated" : "raw")
        << " increments";
    if (d.vibration_components > 0)
      out << ", " << fixed(d.work.vibration_rotations, 0) << " vibration components rotated and "
          << fixed(d.work.vibration_direct, 0) << " evaluated";
    out << "\n";
    for (std::size_t i = 0; i < d.error_model.size(); ++i)
      out << (i == 0 ? "    sensor model: " : "      ") << d.error_model[i] << "\n";
    for (const std::string& f : d.faults) out << "    fault: " << f << "\n";
  }
  for (const SceneCheck::SharedLink& s : c.shared_links) {
    out << "  " << s.link << " shared by";
    for (const std::string& n : s.devices) out << " " << n;
    out << ": " << fixed(100.0 * s.budget.load_fraction, 1) << " % (" << drivers::to_string(s.budget.verdict) << ")\n";
  }
  out << "  total: cpu ~" << fixed(100.0 * c.total_cpu_fraction, 2) << " % of one core (estimate: "
      << kCpuSecondsPerSample * 1e6 << " us per sample per device, measured by bench/bench_stream, plus "
      << kCpuSecondsPerInternalSample * 1e6 << " us per internal sample of a signal chain, "
      << kCpuSecondsPerIncrementNode * 1e6 << " us per increment node, " << kCpuSecondsPerVibrationRotation * 1e9
      << " ns per random vibration component rotated and " << kCpuSecondsPerVibrationDirect * 1e9
      << " ns evaluated, bench/bench_signal_chain); "
      << "largest emission delay " << seconds_text(c.max_emission_delay_ns) << "\n";
  for (const std::string& w : c.warnings) out << "  warning: " << w << "\n";
  out << (c.refused ? "REFUSED: a link cannot carry its traffic, or a fault cannot be shown (warnings above)\n" : "OK\n");
  return out.str();
}

std::string to_json(const SceneCheck& c) {
  using nlohmann::json;
  auto budget_json = [](const drivers::LinkBudget& b) {
    return json{{"load_fraction", b.load_fraction},
                {"bits_per_second_used", b.bits_per_second_used},
                {"capacity_bits_per_second", b.capacity_bits_per_second},
                {"verdict", drivers::to_string(b.verdict)},
                {"message", b.message},
                {"worst_case_load_fraction", b.worst_case_load_fraction ? json(*b.worst_case_load_fraction) : json(nullptr)}};
  };
  json j;
  j["file"] = c.file;
  j["scene"] = c.scene;
  j["physics"] = c.physics;
  j["source"] = c.source;
  j["knot_interval_s"] = c.knot_interval_s;
  j["imus"] = json::array();
  for (const ImuCheck& d : c.imus) {
    json e{{"name", d.name},
           {"protocol", d.protocol},
           {"transport", d.transport},
           {"rate_hz", d.rate_hz},
           {"delta_samples", d.delta_samples},
           {"lookahead_ns", d.lookahead_ns},
           {"emission_delay_ns", d.emission_delay_ns},
           {"method", d.causal ? "causal-hermite" : "smoothing"},
           {"smoothing_lookahead_ns", d.smoothing_lookahead_ns},
           {"producer_lead_ns", d.producer_lead_ns},
           {"arrival_slack_ns", d.arrival_slack_ns},
           {"accel_error_1hz_with_rates", d.accel_error_1hz_with_rates},
           {"accel_error_1hz_estimated", d.accel_error_1hz_estimated},
           {"cpu_fraction", d.cpu_fraction},
           {"oversampling", d.oversampling},
           {"vibration_components", d.vibration_components},
           {"increments", d.compensated_increments ? "compensated" : "raw"},
           {"work_per_sample", json{{"internal_samples", d.work.internal_samples},
                                    {"increment_nodes", d.work.increment_nodes},
                                    {"vibration_rotations", d.work.vibration_rotations},
                                    {"vibration_direct", d.work.vibration_direct}}}};
    e["bytes_per_second"] = d.bytes_per_second ? json(*d.bytes_per_second) : json(nullptr);
    e["worst_case_bytes_per_second"] = d.worst_case_bytes_per_second ? json(*d.worst_case_bytes_per_second) : json(nullptr);
    e["can_frames_per_second"] = d.can_frames_per_second ? json(*d.can_frames_per_second) : json(nullptr);
    e["link"] = d.link ? budget_json(*d.link) : json(nullptr);
    e["error_model"] = d.error_model;
    e["faults"] = d.faults;
    j["imus"].push_back(std::move(e));
  }
  j["shared_links"] = json::array();
  for (const SceneCheck::SharedLink& s : c.shared_links)
    j["shared_links"].push_back(json{{"link", s.link}, {"devices", s.devices}, {"budget", budget_json(s.budget)}});
  j["total_cpu_fraction"] = c.total_cpu_fraction;
  j["cpu_basis"] = "rate_hz x (" + std::to_string(kCpuSecondsPerSample) +
                   " s per sample per device (bench/bench_stream) + work_per_sample x (" +
                   std::to_string(kCpuSecondsPerInternalSample) + " s per internal sample, " +
                   std::to_string(kCpuSecondsPerIncrementNode) + " s per increment node, " +
                   std::to_string(kCpuSecondsPerVibrationRotation) + " s per vibration rotation, " +
                   std::to_string(kCpuSecondsPerVibrationDirect) +
                   " s per vibration evaluation) for a signal chain (bench/bench_signal_chain))";
  j["max_emission_delay_ns"] = c.max_emission_delay_ns;
  j["refused"] = c.refused;
  j["warnings"] = c.warnings;
  return j.dump(2);
}

}  // namespace imuemu::scene
