// `imuemu stream`: live poses in (file replay, UDP, TCP, stdin), IMU samples
// out in real time on the monotonic clock, through the streaming engine and
// the live emitter (docs/streaming.md). The daemon (imuemud) drives devices;
// this command writes CSV lines, for trying a scene, piping into other tools
// and the tests.
#include <signal.h>
#include <time.h>

#include <atomic>
#include <algorithm>
#include <cerrno>
#include <cstring>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>
#include <stdexcept>
#include <string>

#include "core/live_emitter.hpp"
#include "core/stream.hpp"
#include "core/time_mapping.hpp"
#include "core/time_arith.hpp"
#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "daemon/scene/error_model_config.hpp"
#include "io/pose_source.hpp"
#include "io/sample_writers.hpp"

namespace imuemu::cli {
namespace {

std::atomic<bool> g_stop{false};
extern "C" void on_signal(int) { g_stop = true; }

void sleep_until_monotonic(TimeNs due_ns) {
  timespec ts{static_cast<time_t>(due_ns / kNsPerSecond), static_cast<long>(due_ns % kNsPerSecond)};
  while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR && !g_stop) {
  }
}


struct Output {
  std::FILE* file = nullptr;
  bool owned = false;
  ~Output() {
    if (owned && file != nullptr) std::fclose(file);
  }
};

// The IMU fields exactly as `generate` writes them (io/sample_writers.hpp:
// shortest round-trip doubles), then the emission status.
void write_row(std::FILE* f, const live::Emission& e) {
  char row[io::kMaxImuCsvFieldsChars + 1];
  char* const end = io::write_imu_csv_fields(row, e.imu);
  *end = ',';
  std::fwrite(row, 1, static_cast<std::size_t>(end - row) + 1, f);
  std::fputs(to_string(e.status).c_str(), f);
  std::fputc('\n', f);
}

}  // namespace

// "udp:127.0.0.1:5005" -> address, port.
io::NetEndpoint endpoint_of(const std::string& spec, const std::string& scheme) {
  const std::string rest = spec.substr(scheme.size() + 1);
  const auto colon = rest.rfind(':');
  if (colon == std::string::npos) throw std::invalid_argument("--source " + spec + ": expected " + scheme + ":ADDRESS:PORT");
  io::NetEndpoint ep;
  ep.address = rest.substr(0, colon);
  unsigned port = 0;
  const std::string p = rest.substr(colon + 1);
  const auto [end, ec] = std::from_chars(p.data(), p.data() + p.size(), port);
  if (ec != std::errc() || end != p.data() + p.size() || port > 65535)
    throw std::invalid_argument("--source " + spec + ": port '" + p + "' is not 0..65535");
  ep.port = static_cast<std::uint16_t>(port);
  ep.receive_buffer_bytes = 1 << 20;
  return ep;
}

int stream(const StreamArgs& args) {
  PipelineOptions po;
  po.scene.physics = args.scene == "flat" ? Physics::flat : Physics::ecef;
  po.scene.flat_gravity_m_s2 = Vec3(0.0, 0.0, args.gravity_m_s2);
  po.rate_hz = args.rate_hz;
  // Every seconds/Hz option through the one checked conversion
  // (cli_options.hpp), before any object is built from them.
  TimeNs knot_interval_ns = 0, blend_ns = 0, margin_ns = 0, duration_ns = kMaxTimeNs;
  try {
    knot_interval_ns = option_ns("--knot-interval-s", args.knot_interval_s);
    blend_ns = option_ns("--blend-s", args.blend_s);
    margin_ns = option_ns("--margin-s", args.margin_s);
    if (args.duration_s > 0) duration_ns = option_ns("--duration-s", args.duration_s);
    if (args.delta > 0) {
      po.kernel.delta = args.delta;
    } else {
      const std::optional<int> delta = window_samples(args.knot_interval_s, args.rate_hz);
      if (!delta)
        throw UsageError("--knot-interval-s " + bound_text(args.knot_interval_s) + " at --rate " +
                         std::to_string(args.rate_hz) + " Hz makes a window of more than " +
                         std::to_string(limits::kMaxWindowSamples) +
                         " samples (the cap); give --delta 1.." + std::to_string(limits::kMaxWindowSamples) +
                         ", a shorter interval or a lower rate");
      po.kernel.delta = *delta;
    }
  } catch (const UsageError& e) {
    std::cerr << "imuemu stream: " << e.what() << "\n";
    return kUsageError;
  }
  po.gap_policy = GapPolicy::split;
  po.max_gap_s = args.max_gap_s;
  const bool as_fast_as_possible = args.speed == "max";
  // The sensor stage: the device's signal chain on tick k (sensor model,
  // internal rate, filters), as in generate and imuemud.
  std::optional<signal_chain::DeviceChain> sensor_chain;
  try {
    const scene::ErrorModelConfig em = scene::error_model_from_option(args.sensor, args.seed);
    if (!em.ideal()) {
      sensor_chain.emplace(po.scene, em.sensor(), em.chain, args.rate_hz, "imu0");
      for (const std::string& line : scene::error_model_lines(em, static_cast<double>(args.rate_hz)))
        std::cerr << "imuemu stream: sensor imu0: " << line << "\n";
    }
  } catch (const std::exception& e) {
    std::cerr << "imuemu stream: --sensor: " << e.what() << "\n";
    return kBadInput;
  }
  std::uint64_t saturated = 0;
  std::optional<std::pair<std::uint64_t, Kinematics>> previous;  // tick k - 1, for the interval's motion
  auto measured = [&](std::uint64_t k, live::Emission e) {
    if (sensor_chain) {
      const Kinematics* prev = previous && previous->first + 1 == k ? &previous->second : nullptr;
      const signal_chain::ChainOutput m = sensor_chain->step(k, e.kinematics, e.imu, prev, std::nullopt);
      previous.emplace(k, e.kinematics);
      e.imu.gyro_rad_s = m.gyro_rad_s;
      e.imu.accel_m_s2 = m.accel_m_s2;
      e.imu.t_ns = saturating_sub_ns(e.imu.t_ns, m.stamp_shift_ns);
      if (m.saturated_axes != 0) ++saturated;
    }
    return e;
  };
  // The engine and the emitter check their options in their constructors:
  // a refusal there is a message and exit 4, never an escaped exception.
  std::unique_ptr<StreamPipeline> engine_owner;
  std::unique_ptr<live::LiveEmitter> emitter_owner;
  try {
    engine_owner = std::make_unique<StreamPipeline>(po);
    live::LiveEmitterOptions lo;
    lo.scene = po.scene;
    lo.underrun = args.underrun == "pause" ? live::UnderrunPolicy::pause : live::UnderrunPolicy::extrapolate;
    lo.blend_ns = blend_ns;
    emitter_owner = std::make_unique<live::LiveEmitter>(lo);
  } catch (const std::exception& e) {
    std::cerr << "imuemu stream: " << e.what() << "\n";
    return kCannotProcess;
  }
  StreamPipeline& engine = *engine_owner;
  live::StreamSampleSource samples(engine);
  live::LiveEmitter& emitter = *emitter_owner;
  live::SpeedFactor speed;
  std::unique_ptr<io::PoseSource> source;
  io::PoseSourceOptions so;
  so.physics = po.scene.physics;
  so.log = [](std::string_view line) { std::cerr << line << "\n"; };
  try {
    so.max_gap_ns = option_ns("--max-gap-s", po.max_gap_s);  // re-acquired streams just beyond the engine's gap limit
    if (!as_fast_as_possible) speed = live::parse_speed_factor(args.speed);
    if (args.source.rfind("file:", 0) == 0) {
      io::FileReplayOptions fr;
      fr.as_fast_as_possible = as_fast_as_possible;
      fr.speed = as_fast_as_possible ? 1.0
                                     : static_cast<double>(speed.numerator) / static_cast<double>(speed.denominator);
      source = io::make_file_replay_source(args.source.substr(5), fr, so);
    } else if (args.source.rfind("udp:", 0) == 0) {
      source = io::make_udp_pose_source(endpoint_of(args.source, "udp"), so);
    } else if (args.source.rfind("tcp:", 0) == 0) {
      io::NetEndpoint ep = endpoint_of(args.source, "tcp");
      ep.tcp_idle_timeout_ns = static_cast<TimeNs>(std::llround(args.tcp_idle_timeout_s * 1e9));  // 0..86400 s (CLI range)
      source = io::make_tcp_pose_source(ep, so);
    } else if (args.source == "stdin") {
      source = io::make_fd_pose_source(0, so);
    } else {
      throw std::invalid_argument("--source '" + args.source + "': expected file:PATH, udp:ADDR:PORT, tcp:ADDR:PORT or stdin");
    }
    if (as_fast_as_possible && args.source.rfind("file:", 0) != 0)
      throw std::invalid_argument("--speed max applies to file replay only");
  } catch (const std::exception& e) {
    std::cerr << "imuemu stream: " << e.what() << "\n";
    return kUsageError;
  }

  Output out;
  if (args.out_path == "-") {
    out.file = stdout;
  } else {
    out.file = std::fopen(args.out_path.c_str(), "w");
    out.owned = true;
    if (out.file == nullptr) {
      std::cerr << "imuemu stream: cannot write '" << args.out_path << "': " << std::strerror(errno) << "\n";
      return kOutputError;
    }
  }
  std::fprintf(out.file, "time_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2,status\n");

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  const TimeNs delay_ns = saturating_add_ns(StreamPipeline::lookahead_ns(po, knot_interval_ns), margin_ns);
  std::cerr << "imuemu stream: " << source->name() << " -> " << args.rate_hz << " Hz, Delta " << po.kernel.delta
            << ", emitting " << static_cast<double>(delay_ns) * 1e-9 << " s behind the poses\n";
  source->start();

  std::vector<io::SourcedPose> batch;
  std::size_t refused = 0;
  // --speed max writes the engine's samples directly, without the live
  // emitter, whose counters then stay 0: these rows are counted here.
  std::uint64_t replayed_exact = 0;
  bool input_done = false, finished = false;
  auto take_input = [&] {
    batch.clear();
    source->queue().drain(batch);
    for (const io::SourcedPose& p : batch) {
      try {
        engine.push(p.pose);
      } catch (const std::exception& e) {  // a pose the method cannot take: counted, never fatal
        ++refused;
        std::cerr << "imuemu stream: pose at line " << p.line << " refused: " << e.what() << "\n";
      }
    }
    if (!finished && source->finished() && source->queue().size() == 0) input_done = true;
  };

  int code = kOk;
  try {
    if (as_fast_as_possible) {
      // Replay at the speed of the computation: no clock, no underruns.
      StreamSample s;
      while (!g_stop) {
        take_input();
        while (engine.pop(s)) {
          write_row(out.file, measured(scene::grid_index(engine.first_knot_ns(), s.imu.t_ns, po.rate_hz),
                                       {live::EmissionStatus::exact, s.kinematics, s.imu}));
          ++replayed_exact;
        }
        if (input_done) break;
        sleep_until_monotonic(io::monotonic_now_ns() + 1'000'000);
      }
      if (engine.knots_pushed() >= 2) {
        engine.finish();
        while (engine.pop(s)) {
          write_row(out.file, measured(scene::grid_index(engine.first_knot_ns(), s.imu.t_ns, po.rate_hz),
                                       {live::EmissionStatus::exact, s.kinematics, s.imu}));
          ++replayed_exact;
        }
      }
    } else {
      // Wait for the first pose: it fixes the output grid and the clock.
      while (!g_stop && engine.knots_pushed() == 0) {
        take_input();
        if (input_done) break;
        if (engine.knots_pushed() == 0) sleep_until_monotonic(io::monotonic_now_ns() + 1'000'000);
      }
      if (engine.knots_pushed() > 0) {
        const TimeNs t0 = engine.first_knot_ns();
        // The first pose's time is "now" on the sender's clock; each tick goes
        // out the engine's look-ahead (plus margin) after its own time.
        const live::TimeMapping clock = live::TimeMapping::start_now(t0, io::monotonic_now_ns(), speed);
        const TimeNs end_ns = saturating_add_ns(t0, duration_ns);
        for (std::int64_t k = 0; !g_stop; ++k) {
          const TimeNs tick = t0 + (k / po.rate_hz) * kNsPerSecond + (k % po.rate_hz) * kNsPerSecond / po.rate_hz;
          if (tick > end_ns) break;
          sleep_until_monotonic(clock.monotonic_at(saturating_add_ns(tick, delay_ns)));
          take_input();
          if (input_done && !finished) {
            if (engine.knots_pushed() >= 2) engine.finish();
            finished = true;
          }
          if (finished && engine.ready() == 0 && tick > engine.last_knot_ns()) break;  // past the end of the input
          const live::Emission e = emitter.emit(tick, samples);
          if (e.has_sample()) write_row(out.file, measured(static_cast<std::uint64_t>(k), e));
          if (k % 64 == 0) std::fflush(out.file);
        }
      }
    }
  } catch (const std::exception& e) {
    std::cerr << "imuemu stream: " << e.what() << "\n";
    code = kCannotProcess;
  }
  source->stop();
  std::fflush(out.file);
  const io::PoseSourceCounters c = source->counters();
  const live::LiveCounters& lc = emitter.counters();
  std::cerr << "imuemu stream: poses " << c.accepted << " accepted, " << c.rejected() << " rejected (" << c.duplicate
            << " duplicate, " << c.out_of_order << " out of order), " << c.lost() << " lost, " << refused
            << " refused by the method; samples " << lc.exact + replayed_exact << " exact, " << lc.extrapolated << " extrapolated, "
            << lc.blending << " blending, " << lc.paused << " paused, " << lc.waiting << " waiting (" << lc.underrun_events << " underruns, " << lc.stale_discarded << " stale)";
  if (sensor_chain) std::cerr << ", " << saturated << " saturated";
  std::cerr << "\n";
  if (std::ferror(out.file)) return kOutputError;
  return code;
}

}  // namespace imuemu::cli
