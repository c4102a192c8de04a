// `imuemu emit`: see emit_command.hpp. One device on the emission engine.
//
// Grid and sample counter: sample k (sample_counter = k, from 0) is the
// stream's output grid time t_k = t_first + floor(k * 1e9 / rate) ns with
// t_first the first pose's time (core/pipeline.hpp output_grid): for a
// trajectory file and the same scene, rate and window it is `imuemu generate`'s
// k-th output line, bit for bit when exact (the stream is the batch's loop).
#include "daemon/cli/emit_command.hpp"

#include "daemon/scene/error_model_config.hpp"

#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <memory>
#include <set>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/stream.hpp"
#include "core/time_arith.hpp"
#include "core/time_mapping.hpp"
#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/device/device.hpp"
#include "daemon/engine/emission.hpp"
#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/protocol_options.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/net_transport.hpp"
#include "drivers/pty_transport.hpp"
#include "drivers/serial_transport.hpp"
#include "drivers/socketcan.hpp"
#include "io/pose_source.hpp"
#include "io/sample_trajectory.hpp"
#include "io/scene_poses.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::cli {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_emit_signal(int) { g_stop = true; }

bool member(const std::vector<std::string>& names, const std::string& n) {
  return std::find(names.begin(), names.end(), n) != names.end();
}

// Window half-length as `imuemu generate` picks it for hermite: one median
// knot interval of output samples.
int median_interval_delta(const std::vector<Pose>& knots, std::int64_t rate_hz) {
  std::vector<TimeNs> steps;
  for (std::size_t i = 1; i < knots.size(); ++i) steps.push_back(knots[i].t_ns - knots[i - 1].t_ns);
  if (steps.empty()) return 1;
  std::nth_element(steps.begin(), steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2), steps.end());
  const double median_s = static_cast<double>(steps[steps.size() / 2]) * 1e-9;
  // The one window cap (core/limits.hpp), as generate's automatic window.
  if (const std::optional<int> delta = window_samples(median_s, rate_hz)) return *delta;
  throw limits::SizeLimitError("the automatic window (one median knot interval of " + std::to_string(median_s) +
                               " s at " + std::to_string(rate_hz) + " Hz) is more than " +
                               std::to_string(limits::kMaxWindowSamples) + " samples; give --delta or a lower --rate");
}


// The encoder options from the --<table>-<key> flags, through the protocol
// option table (the one the scene parser reads too). Throws
// std::invalid_argument naming the flag and what it allows.
drivers::ProtocolOptions protocol_options_of(const EmitArgs& a) {
  drivers::ProtocolOptions options = drivers::default_protocol_options(static_cast<double>(a.rate_hz));
  std::set<std::string> given;
  for (const auto& [flag, text] : a.protocol_options) {
    const drivers::ProtocolOption* row = nullptr;
    for (const drivers::ProtocolOption& o : drivers::protocol_option_table())
      if (drivers::command_line_flag(o) == flag) row = &o;
    if (row == nullptr) throw std::invalid_argument(flag + ": not a protocol option");
    if (row->protocol != a.protocol)
      throw std::invalid_argument(flag + ": applies to --protocol " + row->protocol + ", not " + a.protocol);
    try {
      row->apply(options, drivers::parse_option_text(*row, text));
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(flag + " " + e.what());
    }
    given.insert(row->key);
  }
  if (const auto problem = drivers::finish_protocol_options(a.protocol, options, given)) {
    std::string flag = problem->key;
    for (const drivers::ProtocolOption* o : drivers::protocol_options_of(a.protocol))
      if (o->key == problem->key) flag = drivers::command_line_flag(*o);
    throw std::invalid_argument(flag + ": " + problem->message);
  }
  return options;
}

// "serial:/dev/ttyUSB0,baud=921600" -> port and settings.
drivers::SerialTransportOptions serial_options_of(const std::string& spec) {
  drivers::SerialTransportOptions o;
  std::string rest = spec.substr(7);
  const auto comma = rest.find(',');
  o.port = rest.substr(0, comma);
  if (o.port.empty()) throw std::invalid_argument("--device " + spec + ": expected serial:PATH[,baud=N]");
  while (comma != std::string::npos && !rest.empty()) {
    rest = rest.substr(rest.find(',') + 1);
    const std::string item = rest.substr(0, rest.find(','));
    if (item.rfind("baud=", 0) != 0) throw std::invalid_argument("--device " + spec + ": unknown option '" + item + "' (expected baud=N)");
    const std::string b = item.substr(5);
    int baud = 0;
    const auto [end, ec] = std::from_chars(b.data(), b.data() + b.size(), baud);
    if (ec != std::errc() || end != b.data() + b.size() || baud <= 0)
      throw std::invalid_argument("--device " + spec + ": baud '" + b + "' is not a positive integer");
    o.settings.baud = baud;
    if (rest.find(',') == std::string::npos) break;
  }
  return o;
}

// "gpiochip0:17" -> chip, line.
std::pair<std::string, unsigned> gpio_of(const std::string& spec) {
  const auto colon = spec.rfind(':');
  unsigned line = 0;
  const std::string l = colon == std::string::npos ? "" : spec.substr(colon + 1);
  const auto [end, ec] = std::from_chars(l.data(), l.data() + l.size(), line);
  if (colon == std::string::npos || colon == 0 || ec != std::errc() || end != l.data() + l.size())
    throw std::invalid_argument("--gpio " + spec + ": expected CHIP:LINE, e.g. gpiochip0:17");
  return {spec.substr(0, colon), line};
}

void print_summary(const emission::EngineStats& s) {
  for (const emission::DeviceStats& d : s.devices) {
    std::cerr << "imuemu emit: " << d.name << " (" << d.output << ", " << d.rate_hz << " Hz): " << d.emitted
              << " samples emitted (" << d.exact << " exact, " << d.extrapolated << " extrapolated, " << d.blending
              << " blending), " << d.producer_late << " underruns, " << d.deadline_misses << " deadline misses (" << d.dropped_late
              << " not sent), "
              << d.dropped_link_down << " dropped (no reader), " << d.write_errors << " write errors, " << d.packets << " packets / " << d.bytes << " bytes sent, "
              << d.queue_overflows << " queue overflows; lateness p50 " << d.lateness.p50_ns / 1000 << " us, p99 "
              << d.lateness.p99_ns / 1000 << " us, p99.9 " << d.lateness.p999_ns / 1000 << " us, max "
              << d.lateness.max_ns / 1000 << " us\n";
    if (d.gpio)
      std::cerr << "imuemu emit: gpio " << d.gpio->pulses << " pulses, " << d.gpio->skipped_pulses << " skipped, "
                << d.gpio->set_errors << " errors\n";
  }
}

}  // namespace

int emit(const EmitArgs& a) {
  const int inputs = (a.trajectory_path.empty() ? 0 : 1) + (a.sample_kind.empty() ? 0 : 1) + (a.source.empty() ? 0 : 1);
  if (inputs != 1) {
    std::cerr << "imuemu emit: give exactly one of --trajectory, --sample, --source\n";
    return kUsageError;
  }
  const bool can = member(drivers::can_protocol_names(), a.protocol);
  // A GNSS receiver (issue 28): its device rate is the navigation rate, and
  // it needs geodetic positions (an ecef scene).
  if (drivers::is_gnss_protocol(a.protocol)) {
    if (a.rate_hz > drivers::kMaxGnssRateHz) {
      std::cerr << "imuemu emit: --rate " << a.rate_hz << ": a GNSS receiver (--protocol " << a.protocol
                << ") navigates at 1.." << drivers::kMaxGnssRateHz << " Hz (default 1)\n";
      return kUsageError;
    }
    if (a.scene != "ecef") {
      std::cerr << "imuemu emit: --protocol " << a.protocol
                << " reports geodetic positions: it needs --scene ecef (a flat scene has no geodetic origin)\n";
      return kUsageError;
    }
  }
  // Checked before anything is opened.
  live::SpeedFactor speed;
  if (a.speed != "1") {
    // Faster (or slower) than real time: for a receiver that only reads the
    // stamps (a GNSS client fed minutes of fixes in seconds). Live poses
    // arrive in real time: no speed there.
    if (!a.source.empty()) {
      std::cerr << "imuemu emit: --speed applies to --trajectory and --sample, not to live --source input\n";
      return kUsageError;
    }
    try {
      speed = live::parse_speed_factor(a.speed);
    } catch (const std::exception& e) {
      std::cerr << "imuemu emit: --speed " << a.speed << ": " << e.what() << "\n";
      return kUsageError;
    }
  }
  emission::DeviceOptions dev;
  emission::EngineOptions eo;
  eo.speed = speed;
  std::unique_ptr<io::PoseSource> source;
  SceneModel scene;
  scene.physics = a.scene == "flat" ? Physics::flat : Physics::ecef;
  scene.flat_gravity_m_s2 = Vec3(0.0, 0.0, a.gravity_m_s2);
  dev.name = "imu0";
  dev.rate_hz = a.rate_hz;
  dev.pipeline.scene = scene;
  dev.pipeline.rate_hz = a.rate_hz;
  try {
    const scene::ErrorModelConfig em = scene::error_model_from_option(a.sensor, a.seed);
    dev.sensor_model = em.sensor();
    dev.chain = em.chain;
  } catch (const std::exception& e) {
    std::cerr << "imuemu emit: --sensor: " << e.what() << "\n";
    return kBadInput;
  }

  // Input.
  try {
    if (!a.source.empty()) {
      io::PoseSourceOptions so;
      so.physics = scene.physics;
      so.log = [](std::string_view line) { std::cerr << line << "\n"; };
      so.max_gap_ns = option_ns("--max-gap-s", dev.pipeline.max_gap_s);  // the engine's gap limit (re-acquisition)
      if (a.source.rfind("udp:", 0) == 0) source = io::make_udp_pose_source(endpoint_of(a.source, "udp"), so);
      else if (a.source.rfind("tcp:", 0) == 0) {
        io::NetEndpoint ep = endpoint_of(a.source, "tcp");
        ep.tcp_idle_timeout_ns = static_cast<TimeNs>(std::llround(a.tcp_idle_timeout_s * 1e9));  // 0..86400 s (CLI range)
        source = io::make_tcp_pose_source(ep, so);
      }
      else if (a.source == "stdin") source = io::make_fd_pose_source(0, so);
      else throw std::invalid_argument("--source '" + a.source + "': expected udp:ADDR:PORT, tcp:ADDR:PORT or stdin");
      dev.pipeline.gap_policy = GapPolicy::split;
      const std::optional<int> window = window_samples(a.knot_interval_s, a.rate_hz);
      if (a.delta <= 0 && !window)
        throw UsageError("--knot-interval-s " + bound_text(a.knot_interval_s) + " at --rate " + std::to_string(a.rate_hz) +
                         " Hz makes a window of more than " + std::to_string(limits::kMaxWindowSamples) +
                         " samples; give --delta, a shorter interval or a lower rate");
      dev.pipeline.kernel.delta = a.delta > 0 ? a.delta : *window;
      eo.source = source.get();
      eo.emit_delay_ns = saturating_add_ns(StreamPipeline::lookahead_ns(dev.pipeline, option_ns("--knot-interval-s", a.knot_interval_s)),
                                           option_ns("--margin-s", a.margin_s));
    } else {
      eo.trajectory = a.trajectory_path.empty() ? io::sample_trajectory_poses(a.sample_kind, a.sample_duration_s, a.sample_period_s, scene.physics)
                                                : io::poses_in_scene(io::read_trajectory_csv(a.trajectory_path), scene.physics);
      dev.pipeline.kernel.delta = a.delta > 0 ? a.delta : median_interval_delta(eo.trajectory, a.rate_hz);
    }
  } catch (const io::CsvFormatError& e) {
    std::cerr << "imuemu emit: " << e.what() << "\n";
    return kBadInput;
  } catch (const std::exception& e) {
    std::cerr << "imuemu emit: " << e.what() << "\n";
    return kUsageError;
  }

  // Encoder and device (daemon/device/device.hpp: the encoder, its output, the sync line).
  std::unique_ptr<drivers::CanEncoder> can_encoder;
  std::unique_ptr<drivers::StreamEncoder> stream_encoder;
  try {
    drivers::ProtocolOptions protocol_options = protocol_options_of(a);
    // MAVLink's barometer / magnetometer random terms: the sensor model's seed.
    if (dev.sensor_model) protocol_options.stream.aiding_seed = dev.sensor_model->seed;
    if (can) {
      if (a.device.rfind("can:", 0) != 0)
        throw std::invalid_argument("--device " + a.device + ": protocol " + a.protocol + " needs can:IFACE");
      can_encoder = drivers::make_can_encoder(a.protocol, protocol_options.can);
    } else {
      if (!member(drivers::stream_protocol_names(), a.protocol))
        throw std::invalid_argument("--protocol " + a.protocol + ": expected native, mavlink2, mip, nmea, ubx, vectornav, sbg, xsens, dronecan or j1939");
      stream_encoder = drivers::make_stream_encoder(a.protocol, protocol_options.stream);
      // A GNSS receiver's epochs are the device's grid from the first pose:
      // on the top of each GPS second only when the first pose is on one.
      if (drivers::is_gnss_protocol(a.protocol) && !eo.trajectory.empty()) {
        const drivers::GnssReceiverConfig& g = protocol_options.stream.gnss;
        const TimeNs first_ns = eo.trajectory.front().t_ns;
        // UTC and GPS time differ by whole seconds: the fraction is the same.
        const TimeNs gps_first_ns = g.time_base == drivers::GnssTimeBase::utc
                                        ? first_ns
                                        : saturating_add_ns(g.gps_time_at_t0_ns, first_ns);
        const TimeNs after_second_ns = ((gps_first_ns % kNsPerSecond) + kNsPerSecond) % kNsPerSecond;
        if (after_second_ns != 0)
          std::cerr << "imuemu emit: warning: the trajectory starts " << static_cast<double>(after_second_ns) * 1e-6
                    << " ms after a GPS second, so every epoch of the receiver falls that far after the top of the "
                       "GPS second; start the trajectory on a whole second (or set "
                    << "--" << drivers::protocol_option_table_name(a.protocol) << "-gps-time-at-t0-ns)\n";
      }
      // A device that answers its driver (MIP): what the driver changed, on stderr.
      if (drivers::CommandResponder* r = stream_encoder->command_responder())
        r->set_log([](std::string_view line) { std::cerr << "imuemu emit: " << line << "\n"; });
      if (a.device.rfind("can:", 0) == 0)
        throw std::invalid_argument("--device " + a.device + ": protocol " + a.protocol + " is a byte stream (pty:, serial:, udp: or tcp-listen:)");
    }
  } catch (const std::exception& e) {
    std::cerr << "imuemu emit: " << e.what() << "\n";
    return kUsageError;
  }
  try {
    auto log = [](std::string_view line) { std::cerr << "imuemu emit: " << line << "\n"; };
    std::unique_ptr<drivers::Transport> transport;
    std::unique_ptr<device::CanOutput> can_output;
    if (a.device.rfind("pty:", 0) == 0) {
      drivers::PtyTransportOptions po;
      po.link_path = a.device.substr(4);
      po.log = log;
      transport = std::make_unique<drivers::PtyTransport>(po);
    } else if (a.device.rfind("serial:", 0) == 0) {
      drivers::SerialTransportOptions so = serial_options_of(a.device);
      so.log = log;
      transport = std::make_unique<drivers::SerialTransport>(so);
    } else if (drivers::is_net_device(a.device)) {
      drivers::NetTransportOptions no = drivers::parse_net_device(a.device);
      no.log = log;
      transport = std::make_unique<drivers::NetTransport>(no);
    } else if (a.device.rfind("can:", 0) == 0) {
      drivers::CanTransportOptions co;
      co.interface = a.device.substr(4);
      co.fd_frames = a.can_fd;
      co.log = log;
      if (can_encoder && can_encoder->command_responder()) {
        co.receive_filters = can_encoder->command_responder()->receive_filters();
        can_encoder->command_responder()->set_log(log);
      }
      can_output = device::can_transport_output(std::make_unique<drivers::CanTransport>(co));
    } else {
      throw std::invalid_argument("--device '" + a.device + "': expected pty:LINKPATH, serial:PATH[,baud=N], udp:HOST:PORT[,bind=PORT], tcp-listen:[HOST:]PORT or can:IFACE");
    }
    std::unique_ptr<drivers::GpioSyncOutput> gpio;
    if (!a.gpio.empty()) {
      drivers::GpioSyncOptions go;
      std::tie(go.chip, go.line) = gpio_of(a.gpio);
      go.every_n_samples = a.sync_every;
      go.pulse_width_ns = static_cast<TimeNs>(std::llround(a.sync_width_us * 1e3));
      go.active_low = a.sync_active_low;
      go.sample_period_ns = kNsPerSecond / a.rate_hz;
      go.trailing_edge_priority = a.priority;
      go.log = log;
      gpio = std::make_unique<drivers::GpioSyncOutput>(go);
    }
    dev.device = can ? device::make_can_device(std::move(can_encoder), std::move(can_output), std::move(gpio))
                     : device::make_stream_device(std::move(stream_encoder), std::move(transport), std::move(gpio));
  } catch (const std::invalid_argument& e) {
    std::cerr << "imuemu emit: " << e.what() << "\n";
    return kUsageError;
  } catch (const std::exception& e) {
    std::cerr << "imuemu emit: " << e.what() << "\n";
    return kOutputError;
  }

  if (a.seconds >= 0) eo.max_ticks_per_device = static_cast<std::uint64_t>(std::llround(a.seconds * static_cast<double>(a.rate_hz)));
  eo.start = a.start == "next-second" ? emission::StartAlignment::next_realtime_second : emission::StartAlignment::now;
  eo.realtime.priority = a.priority;
  eo.realtime.lock_memory = a.lock_memory;
  eo.realtime.require_realtime = a.require_realtime;
  eo.drop_late_ticks = a.late_ticks == "drop";

  const int delta_used = dev.pipeline.kernel.delta;
  std::vector<emission::DeviceOptions> devices;
  devices.push_back(std::move(dev));
  std::unique_ptr<emission::EmissionEngine> engine;
  try {
    engine = std::make_unique<emission::EmissionEngine>(std::move(eo), std::move(devices));
  } catch (const std::exception& e) {
    std::cerr << "imuemu emit: " << e.what() << "\n";
    return kCannotProcess;
  }
  {
    const emission::EngineStats s0 = engine->stats();
    std::cerr << "imuemu emit: " << s0.devices.front().output << " at " << a.rate_hz << " Hz, window Delta "
              << delta_used << ", from " << (a.source.empty() ? "the trajectory" : a.source);
    if (!a.source.empty())
      std::cerr << ", each tick " << static_cast<double>(s0.emit_delay_ns) * 1e-9
                << " s after its pose time (the engine's look-ahead + margin)";
    std::cerr << "\n";
  }
  struct sigaction sa {};
  sa.sa_handler = on_emit_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  try {
    engine->start();
  } catch (const std::exception& e) {
    std::cerr << "imuemu emit: " << e.what() << "\n";
    return kCannotProcess;
  }
  const emission::EngineStats started = engine->stats();
  if (!started.realtime_note.empty()) std::cerr << "imuemu emit: " << started.realtime_note << " (running without it)\n";
  while (!engine->wait(std::chrono::milliseconds(100))) {
    if (g_stop) {
      engine->request_stop();
      break;
    }
    if (!engine->stats().running) break;
  }
  engine->stop();
  const emission::EngineStats s = engine->stats();
  print_summary(s);
  if (!a.stats_json_path.empty()) {
    std::ofstream out(a.stats_json_path);
    out << emission::to_json(s).dump(2) << "\n";
    if (!out) {
      std::cerr << "imuemu emit: cannot write " << a.stats_json_path << "\n";
      return kOutputError;
    }
  }
  return kOk;
}

void add_emit_command(CLI::App& app, int& exit_code) {
  auto args = std::make_shared<EmitArgs>();
  EmitArgs& a = *args;
  std::vector<std::string> protocols = drivers::stream_protocol_names();
  for (const auto& n : drivers::can_protocol_names()) protocols.push_back(n);
  auto* c = app.add_subcommand("emit", "Emulate one IMU in real time on a pty, serial port or CAN interface");
  c->add_option("--trajectory", a.trajectory_path, "Trajectory CSV (docs/trajectory-format.md), all poses up front");
  c->add_option("--sample", a.sample_kind, "Built-in trajectory instead: flight, circle or static")
      ->check(CLI::IsMember({"flight", "circle", "static"}));
  c->add_option("--duration-s", a.sample_duration_s, "--sample: trajectory duration")->capture_default_str()->check(seconds_in(0.0, kMaxDurationS, true));
  c->add_option("--sample-period-s", a.sample_period_s, "--sample: knot period")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS, true));
  c->add_option("--source", a.source, "Live poses instead: udp:ADDR:PORT | tcp:ADDR:PORT | stdin (as imuemu stream)");
  c->add_option("--tcp-idle-timeout-s", a.tcp_idle_timeout_s, "--source tcp: close a client that sent nothing for this long (0: never)")
      ->capture_default_str()->check(seconds_in(0.0, 86400.0));
  c->add_option("--knot-interval-s", a.knot_interval_s, "--source: expected pose spacing (window, look-ahead)")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS, true));
  c->add_option("--margin-s", a.margin_s, "--source: extra delay beyond the engine's look-ahead")->capture_default_str()->check(seconds_in(0.0, kMaxIntervalS));
  c->add_option("--scene", a.scene, "ecef or flat")->capture_default_str()->check(CLI::IsMember({"ecef", "flat"}));
  c->add_option("--gravity", a.gravity_m_s2, "flat scene gravity (m/s^2)")->capture_default_str()->check(finite_in(0.0, kMaxGravityM_s2));
  c->add_option("--rate", a.rate_hz, "Output rate in Hz (integer); nmea and ubx: the navigation rate, 1..10, default 1")->capture_default_str()->check(CLI::Range(1, 1000000));
  c->add_option("--delta", a.delta, "Window half-length Delta (samples); default one median knot interval")->check(CLI::Range(std::int64_t{1}, limits::kMaxWindowSamples));
  c->add_option("--protocol", a.protocol, "Wire protocol")->capture_default_str()->check(CLI::IsMember(protocols));
  c->add_option("--device", a.device, "pty:LINKPATH | serial:PATH[,baud=N] | udp:HOST:PORT[,bind=PORT] | tcp-listen:[HOST:]PORT | can:IFACE")->required();
  c->add_flag("--can-fd", a.can_fd, "can: send CAN FD frames (the interface needs MTU 72)");
  c->add_option("--seconds", a.seconds, "Stop after this many seconds of emission (default: end of the trajectory)")->check(seconds_in(0.0, kMaxDurationS));
  c->add_option("--gpio", a.gpio, "Sync pulse output CHIP:LINE (libgpiod), edge at the sample instant");
  c->add_option("--sync-every", a.sync_every, "Pulse on every Nth sample")->capture_default_str()->check(CLI::PositiveNumber);
  c->add_option("--sync-width-us", a.sync_width_us, "Pulse width (us)")->capture_default_str()->check(finite_in(0.0, 1e6, true));
  c->add_flag("--sync-active-low", a.sync_active_low, "The pulse drives the line low");
  c->add_option("--priority", a.priority, "SCHED_FIFO priority of the emission thread (1..99; 0: normal)")->capture_default_str()->check(CLI::Range(0, 99));
  c->add_flag("--lock-memory", a.lock_memory, "mlockall(MCL_CURRENT|MCL_FUTURE)");
  c->add_flag("--require-realtime", a.require_realtime, "Fail instead of running without the priority or the memory lock");
  c->add_option("--stats-json", a.stats_json_path, "Write the final statistics (JSON) here");
  c->add_option("--sensor", a.sensor, kSensorOptionHelp)->capture_default_str();
  c->add_option("--seed", a.seed, "Noise seed of the sensor model (integer >= 0; default: the file's, 0 for a preset)")->check(CLI::NonNegativeNumber);
  c->add_option("--late-ticks", a.late_ticks,
                "A tick whose wake-up missed its deadline by more than a period: drop (as a real IMU that skips a "
                "sample: the sample time jumps; a sequence gap only in native) or send (late)")
      ->capture_default_str()->check(CLI::IsMember({"drop", "send"}));
  c->add_option("--speed", a.speed,
                "Trajectory seconds per wall second (2.5, 30, 1/3; --trajectory and --sample only): stamps and "
                "contents as at 1, sent faster or slower")
      ->capture_default_str();
  c->add_option("--start", a.start, "now, or next-second (the next whole second of CLOCK_REALTIME)")->capture_default_str()
      ->check(CLI::IsMember({"now", "next-second"}));
  // Protocol options: one flag per row of the protocol option table (the
  // scene file's [imu.<table>] keys), checked by the table when emit runs.
  auto texts = std::make_shared<std::map<std::string, std::string>>();
  std::vector<std::pair<std::string, CLI::Option*>> protocol_flags;
  for (const drivers::ProtocolOption& o : drivers::protocol_option_table()) {
    const std::string flag = drivers::command_line_flag(o);
    std::string help = o.protocol + ": " + o.help + " (" + drivers::allowed_text(o) + "; default " + o.default_text + ")";
    const std::string type = o.type == drivers::OptionType::boolean   ? "BOOL"
                             : o.type == drivers::OptionType::integer ? "INT"
                             : o.type == drivers::OptionType::number  ? "NUMBER"
                             : o.type == drivers::OptionType::text    ? "TEXT"
                                                                      : "CHOICE";
    protocol_flags.emplace_back(flag, c->add_option(flag, (*texts)[flag], help)->type_name(type)->group("Protocol options"));
  }
  CLI::Option* rate_option = c->get_option("--rate");
  c->callback([args, texts, protocol_flags, rate_option, &exit_code] {
    // A GNSS receiver's default rate is 1 Hz (its navigation rate), not an IMU's.
    if (rate_option->count() == 0 && drivers::is_gnss_protocol(args->protocol)) args->rate_hz = 1;
    for (const auto& [flag, option] : protocol_flags)
      if (option->count() > 0) args->protocol_options[flag] = texts->at(flag);
    exit_code = emit(*args);
  });
}

}  // namespace imuemu::cli
