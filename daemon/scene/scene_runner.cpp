#include "daemon/scene/scene_runner.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#include "core/limits.hpp"
#include "core/time_arith.hpp"
#include "daemon/device/device.hpp"
#include "drivers/gpio_sync.hpp"
#include "drivers/net_transport.hpp"
#include "drivers/pty_transport.hpp"
#include "drivers/serial_transport.hpp"
#include "drivers/socketcan.hpp"
#include "drivers/transport.hpp"
#include "io/pose_source.hpp"
#include "io/sample_trajectory.hpp"
#include "io/scene_poses.hpp"
#include "io/trajectory_csv.hpp"

namespace imuemu::scene {
namespace {

TimeNs seconds_to_ns(double s) { return static_cast<TimeNs>(std::llround(s * 1e9)); }

const char* sample_kind_name(SampleMotion m) {
  switch (m) {
    case SampleMotion::flight: return "flight";
    case SampleMotion::circle: return "circle";
    case SampleMotion::stationary: return "static";
  }
  return "flight";
}

// The built-in sample through the CSV `imuemu sample-trajectory` writes, so
// the daemon's poses are exactly those of `imuemu sample-trajectory` +
// `imuemu generate` (the batch reference the loopback tests compare with).
drivers::GpioSyncOptions gpio_options(const SyncConfig& s, const ImuConfig& imu, const RunnerOptions& options) {
  drivers::GpioSyncOptions g;
  g.chip = s.chip;
  g.line = s.line;
  g.every_n_samples = s.every_n_samples;
  g.pulse_width_ns = s.width_ns;
  g.active_low = s.active_low;
  g.sample_period_ns = kNsPerSecond / imu.rate_hz;
  g.pps_line = s.pps_line;
  g.pps_chip = s.pps_chip;
  g.pps_width_ns = s.pps_width_ns;
  g.pps_active_low = s.pps_active_low;
  g.consumer = "imuemud " + imu.name;
  g.trailing_edge_priority = s.trailing_edge_priority;
  g.log = options.log;
  return g;
}

}  // namespace

std::vector<Pose> scene_trajectory(const SceneConfig& scene) {
  switch (scene.trajectory.kind) {
    case SourceKind::file:
      return io::poses_in_scene(io::read_trajectory_csv(scene.trajectory.file_path), scene.physics.physics);
    case SourceKind::sample:
      return io::sample_trajectory_poses(std::string(sample_kind_name(scene.trajectory.sample)),
                                         scene.trajectory.duration_s, scene.trajectory.knot_interval_s,
                                         scene.physics.physics);
    default:
      throw std::invalid_argument("scene " + scene.name + ": source " + scene.trajectory.source +
                                  " is a live stream, not a trajectory");
  }
}

std::vector<Pose> looped(const std::vector<Pose>& once, const SceneConfig& scene, TimeNs min_span_ns) {
  if (once.size() < 2) return once;
  // Every time sum saturates or is refused (core/time_arith.hpp): a copy
  // whose times do not fit int64 ns is not made.
  const TimeNs span_ns = saturating_sub_ns(once.back().t_ns, once.front().t_ns);
  // Beyond max_gap_s, so the pipeline splits the run there (gap_policy split).
  const TimeNs gap_ns = saturating_add_ns(seconds_to_ns(scene.smoothing.max_gap_s),
                                          seconds_to_ns(scene.trajectory.knot_interval_s));
  const TimeNs shift_ns = saturating_add_ns(span_ns, gap_ns);
  // Copies to cover min_span_ns, at most limits::kMaxLoopKnots knots in all
  // (the run restarts after them), and only those whose times fit.
  const TimeNs wanted = std::max<TimeNs>(1, min_span_ns / shift_ns + (min_span_ns % shift_ns != 0 ? 1 : 0));
  const auto fit = static_cast<TimeNs>(std::max<std::size_t>(1, limits::kMaxLoopKnots / once.size()));
  const TimeNs in_range = (kMaxTimeNs - std::max<TimeNs>(once.back().t_ns, 0)) / shift_ns + 1;
  const auto copies = static_cast<std::size_t>(std::min({wanted, fit, in_range}));
  std::vector<Pose> out;
  out.reserve(once.size() * copies);
  for (std::size_t c = 0; c < copies; ++c) {
    const TimeNs offset_ns = shift_ns * static_cast<TimeNs>(c);  // fits: c < in_range
    for (Pose p : once) {
      p.t_ns += offset_ns;
      out.push_back(p);
    }
  }
  return out;
}

std::string pty_link_path(const ImuConfig& imu, const RunnerOptions& options) {
  if (options.pty_link_dir.empty()) return imu.transport.pty.link;
  return (std::filesystem::path(options.pty_link_dir) / std::filesystem::path(imu.transport.pty.link).filename()).string();
}

std::string reuse_key(const ImuConfig& imu, const RunnerOptions& options) {
  const NetConfig& n = imu.transport.net;
  // A network endpoint kept across a reload keeps its port (a new socket
  // could not bind it while the old engine still holds it) and its client.
  if (imu.transport.type == TransportType::udp)
    return "udp " + n.host + ":" + std::to_string(n.port) + " bind " + std::to_string(n.bind_port) + " queue " +
           std::to_string(n.queue_bytes);
  if (imu.transport.type == TransportType::tcp_server)
    return "tcp " + n.host + ":" + std::to_string(n.port) + " queue " + std::to_string(n.queue_bytes);
  if (imu.transport.type != TransportType::pty) return {};
  return "pty " + pty_link_path(imu, options) + " queue " + std::to_string(imu.transport.pty.queue_bytes) + " mode " +
         std::to_string(imu.transport.pty.mode);
}

io::PoseSourceOptions pose_source_options(const SceneConfig& scene, const RunnerOptions& options) {
  io::PoseSourceOptions so;
  so.physics = scene.physics.physics;
  so.log = options.log;
  // A re-acquired stream is placed just beyond the engine's own gap limit
  // (io/pose_source.hpp max_gap_ns): output resumes about max_gap_s after a
  // sender restart.
  so.max_gap_ns = seconds_to_ns(scene.smoothing.max_gap_s);
  // One vehicle per MAVLink source (docs/pose-wire-format.md §4.5).
  so.mavlink_system_id = scene.trajectory.mavlink_system_id;
  so.mavlink_component_id = scene.trajectory.mavlink_component_id;
  return so;
}

BuiltEngine build_engine(const SceneConfig& scene, const RunnerOptions& options, ReusableTransports* reuse) {
  BuiltEngine built;
  emission::EngineOptions eo;
  const bool live_input = is_live(scene.trajectory.kind);
  if (live_input) {
    const io::PoseSourceOptions so = pose_source_options(scene, options);
    io::NetEndpoint endpoint{scene.trajectory.address, scene.trajectory.port, 0};
    endpoint.tcp_idle_timeout_ns = seconds_to_ns(scene.trajectory.tcp_idle_timeout_s);
    if (scene.trajectory.kind == SourceKind::udp) built.source = io::make_udp_pose_source(endpoint, so);
    else if (scene.trajectory.kind == SourceKind::mavlink_udp) built.source = io::make_mavlink_udp_pose_source(endpoint, so);
    else if (scene.trajectory.kind == SourceKind::tcp) built.source = io::make_tcp_pose_source(endpoint, so);
    else built.source = io::make_fd_pose_source(0, so);
    eo.source = built.source.get();
  } else {
    std::vector<Pose> once = scene_trajectory(scene);
    eo.trajectory = scene.trajectory.loop ? looped(once, scene, kLoopSpanNs) : std::move(once);
  }
  eo.speed = scene.trajectory.speed;
  eo.start = scene.trajectory.start == StartAlignment::next_second ? emission::StartAlignment::next_realtime_second
                                                                   : emission::StartAlignment::now;
  eo.realtime.priority = scene.daemon.realtime_priority;
  eo.realtime.lock_memory = scene.daemon.lock_memory;
  eo.realtime.require_realtime = scene.daemon.require_realtime;
  eo.drop_late_ticks = options.drop_late_ticks.value_or(scene.daemon.drop_late_ticks);

  std::vector<emission::DeviceOptions> devices;
  TimeNs max_emission_delay_ns = 0;
  TimeNs producer_lead_ns = eo.producer_lead_ns;
  for (const ImuConfig& imu : scene.imus) {
    emission::DeviceOptions dev;
    dev.name = imu.name;
    dev.rate_hz = imu.rate_hz;
    dev.pipeline = pipeline_options(scene, imu);
    dev.underrun = scene.live.underrun;
    dev.blend_ns = seconds_to_ns(scene.live.blend_s);
    dev.mounting = imu.mounting;
    dev.sensor_model = imu.error_model.sensor();
    dev.chain = imu.error_model.chain;
    dev.faults.scheduled = imu.faults;  // issue 18: [[imu.fault]], [imu.random_faults]
    dev.faults.random = imu.random_faults;
    const LatencyPlan plan = latency_plan(scene, imu);
    max_emission_delay_ns = std::max(max_emission_delay_ns, plan.emission_delay_ns);
    producer_lead_ns = std::min(producer_lead_ns, plan.producer_lead_ns);
    try {
      // The device's parts (daemon/device/device.hpp): its encoder, its
      // output, its sync line.
      std::unique_ptr<drivers::StreamEncoder> stream_encoder;
      std::unique_ptr<drivers::CanEncoder> can_encoder;
      std::unique_ptr<drivers::Transport> transport;
      drivers::TransportCounters transport_baseline;
      std::unique_ptr<device::CanOutput> can_output;
      if (is_can_protocol(imu.protocol)) {
        can_encoder = drivers::make_can_encoder(imu.protocol, imu.can_options);
        if (drivers::CanCommandResponder* r = can_encoder->command_responder(); r && options.log) {
          r->set_log([log = options.log, name = imu.name](std::string_view line) {
            log(name + ": " + std::string(line));
          });
        }
      } else {
        drivers::StreamEncoderOptions so = imu.stream_options;
        so.nominal_sample_rate_hz = static_cast<double>(imu.rate_hz);
        stream_encoder = drivers::make_stream_encoder(imu.protocol, so);
        if (drivers::CommandResponder* r = stream_encoder->command_responder()) {
          if (options.log) {
            r->set_log([log = options.log, name = imu.name](std::string_view line) {
              log(name + ": " + std::string(line));
            });
          }
        }
      }
      const TransportConfig& t = imu.transport;
      // The same pty or network endpoint as the previous scene's (a reload):
      // kept open, so its reader or client sees no hang-up (and a port stays
      // bound); the engine counts from here.
      const auto take_kept_transport = [&]() {
        if (reuse == nullptr) return false;
        const auto kept = reuse->find(reuse_key(imu, options));
        if (kept == reuse->end() || !kept->second) return false;
        transport = std::move(kept->second);
        reuse->erase(kept);
        transport_baseline = transport->counters();
        return true;
      };
      switch (t.type) {
        case TransportType::pty: {
          if (take_kept_transport()) break;
          drivers::PtyTransportOptions po;
          po.link_path = pty_link_path(imu, options);
          po.queue_bytes = t.pty.queue_bytes;
          po.slave_mode = t.pty.mode;
          po.log = options.log;
          std::error_code ec;
          std::filesystem::create_directories(std::filesystem::path(po.link_path).parent_path(), ec);
          transport = std::make_unique<drivers::PtyTransport>(po);
          break;
        }
        case TransportType::udp:
        case TransportType::tcp_server: {
          if (take_kept_transport()) break;
          drivers::NetTransportOptions no;
          no.kind = t.type == TransportType::udp ? drivers::NetTransportOptions::Kind::udp
                                                 : drivers::NetTransportOptions::Kind::tcp_server;
          no.host = t.net.host;
          no.port = t.net.port;
          no.bind_port = t.net.bind_port;
          no.queue_bytes = t.net.queue_bytes;
          no.log = options.log;
          transport = std::make_unique<drivers::NetTransport>(no);
          break;
        }
        case TransportType::serial: {
          drivers::SerialTransportOptions so;
          so.port = t.serial.port;
          so.settings = t.serial.settings;
          so.queue_bytes = t.serial.queue_bytes;
          so.log = options.log;
          transport = std::make_unique<drivers::SerialTransport>(so);
          break;
        }
        case TransportType::can: {
          drivers::CanTransportOptions co;
          co.interface = t.can.interface;
          co.fd_frames = t.can.fd;
          co.fd_bitrate_switch = t.can.bitrate_switch;
          co.log = options.log;
          // The requests the node answers (none for a send-only encoder).
          if (can_encoder && can_encoder->command_responder())
            co.receive_filters = can_encoder->command_responder()->receive_filters();
          can_output = device::can_transport_output(std::make_unique<drivers::CanTransport>(co));
          break;
        }
        case TransportType::null:
          transport = std::make_unique<drivers::NullTransport>();
          break;
      }
      std::unique_ptr<drivers::GpioSyncOutput> gpio;
      if (imu.sync) gpio = std::make_unique<drivers::GpioSyncOutput>(gpio_options(*imu.sync, imu, options));
      // A CAN protocol on transport null has no CAN output: no device, which
      // the engine refuses (as before the device seam).
      if (can_encoder && can_output)
        dev.device = device::make_can_device(std::move(can_encoder), std::move(can_output), std::move(gpio));
      else if (stream_encoder && transport)
        dev.device = device::make_stream_device(std::move(stream_encoder), std::move(transport), std::move(gpio),
                                                transport_baseline);
    } catch (const std::exception& e) {
      throw DeviceOpenError(imu.name, e.what());
    }
    devices.push_back(std::move(dev));
  }
  if (live_input) {
    eo.emit_delay_ns = max_emission_delay_ns;  // look-ahead + margin, or the scene's latency budget
    eo.producer_lead_ns = producer_lead_ns;
  }
  built.engine = std::make_unique<emission::EmissionEngine>(std::move(eo), std::move(devices));
  for (const emission::DeviceStats& d : built.engine->stats().devices)
    built.outputs.push_back(d.name + ": " + d.output + " at " + std::to_string(d.rate_hz) + " Hz");
  return built;
}

}  // namespace imuemu::scene
