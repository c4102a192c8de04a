// `imuemu listen`: see listen_command.hpp.
#include "daemon/cli/listen_command.hpp"

#include <signal.h>
#include <time.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "core/time_arith.hpp"
#include "daemon/cli/arrival_jitter.hpp"
#include "daemon/cli/cli_options.hpp"
#include "daemon/cli/commands.hpp"
#include "drivers/byte_stream_reader.hpp"
#include "drivers/socketcan.hpp"
#include "drivers/transport.hpp"

namespace imuemu::cli {
namespace {

TimeNs monotonic_now_ns() {
  timespec ts{};
  ::clock_gettime(CLOCK_MONOTONIC, &ts);
  return static_cast<TimeNs>(ts.tv_sec) * kNsPerSecond + ts.tv_nsec;
}

bool is_can_protocol(const std::string& protocol) {
  const auto names = drivers::can_protocol_names();
  return std::find(names.begin(), names.end(), protocol) != names.end();
}

bool is_stream_protocol(const std::string& protocol) {
  const auto names = drivers::stream_protocol_names();
  return std::find(names.begin(), names.end(), protocol) != names.end();
}

// "can:vcan0" or "vcan0" -> "vcan0".
std::string can_interface_of(const std::string& device) {
  return device.rfind("can:", 0) == 0 ? device.substr(4) : device;
}

// How a protocol's sequence field counts, for the own continuity check.
//  per_sample: +1 per IMU sample (native: the sample counter; DroneCAN: the
//    RawIMU transfer id, widened by the decoder).
//  per_message: +1 per message of the sender (MAVLink's seq is shared with
//    HEARTBEAT), so the messages decoded in between are subtracted.
//  none: mip and j1939 carry no counter.
enum class SequenceKind { per_sample, per_message, none };
SequenceKind sequence_kind(const std::string& protocol) {
  if (protocol == "native" || protocol == "dronecan") return SequenceKind::per_sample;
  if (protocol == "mavlink2") return SequenceKind::per_message;
  return SequenceKind::none;
}

nlohmann::json vec_json(const Vec3& v) { return nlohmann::json::array({v.x(), v.y(), v.z()}); }

std::string format_vec(const Vec3& v) {
  char buffer[128];
  std::snprintf(buffer, sizeof buffer, "%+.6e %+.6e %+.6e", v.x(), v.y(), v.z());
  return buffer;
}

std::string format_seconds(TimeNs t_ns) {
  // Exact: integer seconds and nanoseconds, never through a double.
  char buffer[64];
  const TimeNs whole = t_ns / kNsPerSecond;
  TimeNs frac = t_ns % kNsPerSecond;
  const bool negative = t_ns < 0;
  if (frac < 0) frac = -frac;
  std::snprintf(buffer, sizeof buffer, "%s%lld.%09lld", negative && whole == 0 ? "-" : "",
                static_cast<long long>(whole), static_cast<long long>(frac));
  return buffer;
}

// Everything one listening run accumulates, whatever the transport.
class Session {
 public:
  Session(const ListenArgs& args, std::ostream& out, const ListenSampleHook& hook)
      : args_(args),
        out_(out),
        hook_(hook),
        kind_(sequence_kind(args.protocol)),
        jitter_(args.expect_rate_hz > 0.0 ? 1e9 / args.expect_rate_hz : 0.0) {
    if (!args_.out_path.empty()) {
      csv_.open(args_.out_path, std::ios::out | std::ios::trunc);
      if (!csv_) throw std::runtime_error("listen: cannot write --out '" + args_.out_path + "'");
      csv_ << "sequence,t_ns,gyro_x_rad_s,gyro_y_rad_s,gyro_z_rad_s,accel_x_m_s2,accel_y_m_s2,accel_z_m_s2,"
              "dtheta_x_rad,dtheta_y_rad,dtheta_z_rad,dv_x_m_s,dv_y_m_s,dv_z_m_s,status\n";
    }
  }

  bool done() const { return args_.count > 0 && samples_ >= args_.count; }

  // One decoded sample. `messages_so_far`: the decoder's frame counter now
  // (for the per-message sequence check).
  void on_sample(const drivers::DecodedSample& s, TimeNs arrival_ns, std::uint64_t messages_so_far) {
    if (done()) return;  // the rest of a chunk after --count
    ++samples_;
    check_sequence(s, messages_so_far);
    if (s.has_time) {
      if (!first_t_ns_) first_t_ns_ = s.t_ns;
      if (last_t_ns_ && s.t_ns > *last_t_ns_) count_grid_steps(ns_between(*last_t_ns_, s.t_ns));
      last_t_ns_ = s.t_ns;
      ++timed_samples_;
    }
    if (first_arrival_ns_ < 0) first_arrival_ns_ = arrival_ns;
    if (last_arrival_ns_ >= 0) jitter_.record(arrival_ns - last_arrival_ns_);
    last_arrival_ns_ = arrival_ns;

    if (csv_.is_open()) write_csv(s);
    if (!args_.quiet && (samples_ - 1) % std::max<std::uint64_t>(1, args_.every) == 0) print(s, arrival_ns);
    if (hook_) hook_(s, arrival_ns);
  }

  void finish(ListenSummary& summary, const drivers::DecoderCounters& counters) {
    if (csv_.is_open()) {
      csv_.flush();
      if (!csv_) throw std::runtime_error("listen: writing --out '" + args_.out_path + "' failed");
    }
    out_.flush();
    summary.frames = counters.frames;
    summary.checksum_errors = counters.checksum_errors;
    summary.resync_bytes = counters.resync_bytes;
    summary.sequence_gaps = counters.sequence_gaps;
    summary.other_errors = counters.other_errors;
    summary.samples = samples_;
    if (kind_ != SequenceKind::none) summary.own_sequence_gaps = own_gaps_;
    summary.sequence_backward_steps = backward_steps_;
    summary.first_sample_t_ns = first_t_ns_;
    summary.last_sample_t_ns = last_t_ns_;
    if (timed_samples_ >= 2 && *last_t_ns_ > *first_t_ns_) {
      summary.rate_from_sample_time_hz =
          static_cast<double>(timed_samples_ - 1) / seconds_between(*first_t_ns_, *last_t_ns_);
    }
    if (samples_ >= 2 && last_arrival_ns_ > first_arrival_ns_) {
      summary.rate_from_arrival_hz =
          static_cast<double>(samples_ - 1) / seconds_between(first_arrival_ns_, last_arrival_ns_);
    }
    if (jitter_.count() > 0) {
      const double nominal_ns =
          args_.expect_rate_hz > 0.0
              ? 1e9 / args_.expect_rate_hz
              : static_cast<double>(last_arrival_ns_ - first_arrival_ns_) / static_cast<double>(jitter_.count());
      const JitterSummary j = *jitter_.summary(nominal_ns);
      summary.jitter_p50_us = j.p50_us;
      summary.jitter_p99_us = j.p99_us;
      summary.jitter_max_us = j.max_us;
    }
    if (args_.expect_rate_hz > 0.0) {
      summary.expected_rate_hz = args_.expect_rate_hz;
      // The device's rate is the rate of its sample-time grid: a sample it
      // skipped (a time step of k periods) is a missing sample, counted
      // apart, not a slower device. Without sample times, the arrival rate.
      if (grid_steps_ > 0 && *last_t_ns_ > *first_t_ns_) {
        summary.rate_of_sample_time_grid_hz =
            static_cast<double>(grid_steps_) / seconds_between(*first_t_ns_, *last_t_ns_);
        summary.missing_samples = missing_samples_;
      }
      const std::optional<double> measured =
          summary.rate_of_sample_time_grid_hz ? summary.rate_of_sample_time_grid_hz : summary.rate_from_arrival_hz;
      summary.rate_ok = measured && std::abs(*measured - args_.expect_rate_hz) <= args_.rate_tolerance * args_.expect_rate_hz;
    }
  }

 private:
  // A forward time step of about k expected periods (k >= 2 when rounded)
  // is k grid steps, k - 1 of them missing samples. Needs --expect-rate;
  // steps of zero or backwards are the sequence check's business.
  void count_grid_steps(std::uint64_t step_ns) {
    if (args_.expect_rate_hz <= 0.0) return;
    const double periods = static_cast<double>(step_ns) * args_.expect_rate_hz / 1e9;
    const double k = std::max(1.0, std::round(periods));
    if (k > 1e12) return;  // a time jump, not a run of missing samples
    const auto steps = static_cast<std::uint64_t>(k);
    grid_steps_ += steps;
    missing_samples_ += steps - 1;
  }

  void check_sequence(const drivers::DecodedSample& s, std::uint64_t messages_so_far) {
    if (kind_ == SequenceKind::none || !s.has_sequence) return;
    if (have_sequence_) {
      // Modular step: a counter wrapping at 2^64 is no gap; a step in the
      // upper half is a step backwards (sender restarted or reordering).
      const std::uint64_t step = s.sequence - last_sequence_;
      if (step == 0 || step > (std::numeric_limits<std::uint64_t>::max() >> 1)) {
        ++backward_steps_;
      } else {
        const std::uint64_t expected =
            kind_ == SequenceKind::per_sample ? 1 : std::max<std::uint64_t>(1, messages_so_far - last_messages_);
        if (step > expected) own_gaps_ += step - expected;
      }
    }
    have_sequence_ = true;
    last_sequence_ = s.sequence;
    last_messages_ = messages_so_far;
  }

  void write_csv(const drivers::DecodedSample& s) {
    char buffer[512];
    std::snprintf(buffer, sizeof buffer,
                  "%s,%s,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%.17g,%u\n",
                  s.has_sequence ? std::to_string(s.sequence).c_str() : "",
                  s.has_time ? std::to_string(s.t_ns).c_str() : "", s.gyro_rad_s.x(), s.gyro_rad_s.y(),
                  s.gyro_rad_s.z(), s.accel_m_s2.x(), s.accel_m_s2.y(), s.accel_m_s2.z(), s.delta_theta_rad.x(),
                  s.delta_theta_rad.y(), s.delta_theta_rad.z(), s.delta_velocity_m_s.x(), s.delta_velocity_m_s.y(),
                  s.delta_velocity_m_s.z(), s.status);
    csv_ << buffer;
  }

  void print(const drivers::DecodedSample& s, TimeNs arrival_ns) {
    if (args_.json) {
      nlohmann::json j{{"type", "sample"},
                       {"index", samples_ - 1},
                       {"sequence", s.has_sequence ? nlohmann::json(s.sequence) : nlohmann::json(nullptr)},
                       {"t_ns", s.has_time ? nlohmann::json(s.t_ns) : nlohmann::json(nullptr)},
                       {"arrival_monotonic_ns", arrival_ns},
                       {"gyro_rad_s", vec_json(s.gyro_rad_s)},
                       {"accel_m_s2", vec_json(s.accel_m_s2)},
                       {"delta_theta_rad", vec_json(s.delta_theta_rad)},
                       {"delta_velocity_m_s", vec_json(s.delta_velocity_m_s)},
                       {"status", s.status}};
      out_ << j.dump() << '\n';
    } else {
      out_ << "sample " << samples_ - 1;
      if (s.has_sequence) out_ << " seq " << s.sequence;
      if (s.has_time) out_ << " t " << format_seconds(s.t_ns) << " s";
      out_ << " gyro " << format_vec(s.gyro_rad_s) << " rad/s accel " << format_vec(s.accel_m_s2) << " m/s^2";
      if (!s.delta_theta_rad.isZero(0.0) || !s.delta_velocity_m_s.isZero(0.0)) {
        out_ << " dtheta " << format_vec(s.delta_theta_rad) << " rad dv " << format_vec(s.delta_velocity_m_s)
             << " m/s";
      }
      char status[16];
      std::snprintf(status, sizeof status, "0x%x", s.status);
      out_ << " status " << status << '\n';
    }
  }

  const ListenArgs& args_;
  std::ostream& out_;
  const ListenSampleHook& hook_;
  SequenceKind kind_;
  std::ofstream csv_;
  std::uint64_t samples_ = 0, timed_samples_ = 0;
  std::uint64_t grid_steps_ = 0, missing_samples_ = 0;
  bool have_sequence_ = false;
  std::uint64_t last_sequence_ = 0, last_messages_ = 0, own_gaps_ = 0, backward_steps_ = 0;
  std::optional<TimeNs> first_t_ns_, last_t_ns_;
  TimeNs first_arrival_ns_ = -1, last_arrival_ns_ = -1;
  // Bounded: exact for short runs, a fixed histogram beyond (arrival_jitter.hpp).
  ArrivalJitter jitter_;
};

void validate(const ListenArgs& args) {
  if (!is_stream_protocol(args.protocol) && !is_can_protocol(args.protocol)) {
    std::string names;
    for (const auto& n : drivers::stream_protocol_names()) names += n + " ";
    for (const auto& n : drivers::can_protocol_names()) names += n + " ";
    throw std::invalid_argument("--protocol '" + args.protocol + "': expected one of " + names);
  }
  if (args.device.empty()) throw std::invalid_argument("--device: empty");
  // The command line checks the same ranges (finite_in, seconds_in: exit 2);
  // these hold for callers of listen() that build ListenArgs themselves.
  if (!std::isfinite(args.duration_s) || args.duration_s < 0.0 || args.duration_s > kMaxDurationS)
    throw std::invalid_argument("--duration-s: expected a finite number in [0, " + bound_text(kMaxDurationS) +
                                "] s (0 = no limit)");
  if (!std::isfinite(args.expect_rate_hz) || args.expect_rate_hz < 0.0 || args.expect_rate_hz > 1e6)
    throw std::invalid_argument("--expect-rate: expected a finite rate in [0, 1e+06] Hz (0 = none)");
  if (!std::isfinite(args.rate_tolerance) || args.rate_tolerance <= 0.0 || args.rate_tolerance > 1.0)
    throw std::invalid_argument("--rate-tolerance: expected a fraction in (0, 1]");
  if (args.every == 0) throw std::invalid_argument("--every: expected >= 1");
  if (args.handshake && !drivers::handshake::make_client(args.protocol))
    throw std::invalid_argument("--handshake: " + args.protocol +
                                " has no start-up commands to send (the handshake knows mip, mavlink2, vectornav, sbg and xsens)");
  if (args.handshake_timeout_ms < 1 || args.handshake_timeout_ms > 60000)
    throw std::invalid_argument("--handshake-timeout-ms: expected 1..60000");
}


// The time left before --duration-s, as a poll timeout of at most 100 ms
// (the stop flag is checked that often).
std::chrono::milliseconds next_timeout(TimeNs now_ns, TimeNs end_ns) {
  const TimeNs left_ns = end_ns - now_ns;
  const TimeNs capped = std::clamp<TimeNs>(left_ns, 0, 100'000'000);
  return std::chrono::milliseconds((capped + 999'999) / 1'000'000);
}

// --handshake: each step's request written, then the replies read until the
// step's answer is complete or its timeout; stream packets read meanwhile
// are skipped (not decoded: the listening starts after the handshake).
void run_handshake(const ListenArgs& args, drivers::ByteStreamReader& reader, std::ostream& out,
                   const std::atomic<bool>& stop, std::vector<drivers::handshake::StepResult>& results) {
  const std::unique_ptr<drivers::handshake::Client> client = drivers::handshake::make_client(args.protocol);
  std::vector<std::uint8_t> buffer(4096);
  for (std::size_t step = 0; step < client->step_count() && !stop.load(); ++step) {
    drivers::handshake::StepResult r;
    r.step = client->step_name(step);
    const std::vector<std::uint8_t> request = client->request(step);
    const TimeNs start_ns = monotonic_now_ns();
    const TimeNs end_ns = start_ns + static_cast<TimeNs>(args.handshake_timeout_ms) * 1'000'000;
    reader.write_all(request, std::chrono::milliseconds(args.handshake_timeout_ms));
    bool complete = false;
    while (!complete && !stop.load()) {
      const TimeNs now = monotonic_now_ns();
      if (now >= end_ns) break;
      const drivers::ReadResult got = reader.read_some(buffer, next_timeout(now, end_ns));
      if (got.bytes > 0)
        complete = client->feed(step, std::span<const std::uint8_t>(buffer.data(), got.bytes), r);
      if (got.end_of_stream) break;
    }
    r.latency_ms = static_cast<double>(monotonic_now_ns() - start_ns) / 1e6;
    if (!complete) {
      client->timed_out(step, r);
      if (r.reply.empty()) r.reply = "no reply in " + std::to_string(args.handshake_timeout_ms) + " ms";
    }
    if (args.json) {
      out << nlohmann::json{{"type", "handshake"}, {"step", r.step}, {"answered", r.answered},
                            {"accepted", r.accepted}, {"reply", r.reply}, {"latency_ms", r.latency_ms}}
                 .dump()
          << "\n";
    } else {
      char ms[32];
      std::snprintf(ms, sizeof ms, "%.1f ms", r.latency_ms);
      out << "handshake: " << r.step << ": " << r.reply << (complete ? std::string(" (") + ms + ")" : "") << "\n";
    }
    out.flush();
    results.push_back(std::move(r));
  }
}

}  // namespace

ListenSummary listen(const ListenArgs& args, std::ostream& out, const std::atomic<bool>& stop,
                     const ListenSampleHook& on_sample) {
  validate(args);
  ListenSummary summary;
  summary.protocol = args.protocol;
  summary.device = args.device;
  const bool can = is_can_protocol(args.protocol);
  // Decoder first: wrong options are a usage error before any device is touched.
  std::unique_ptr<drivers::StreamDecoder> stream_decoder;
  std::unique_ptr<drivers::CanDecoder> can_decoder;
  if (can) {
    can_decoder = drivers::make_can_decoder(args.protocol, args.can_options);
  } else {
    stream_decoder = drivers::make_stream_decoder(args.protocol, args.stream_options);
  }
  const auto counters = [&]() -> const drivers::DecoderCounters& {
    return can ? can_decoder->counters() : stream_decoder->counters();
  };

  const TimeNs start_ns = monotonic_now_ns();
  const TimeNs end_ns = args.duration_s > 0.0 ? saturating_add_ns(start_ns, option_ns("--duration-s", args.duration_s))
                                              : std::numeric_limits<TimeNs>::max();
  Session session(args, out, on_sample);
  TimeNs arrival_ns = 0;
  const drivers::SampleCallback callback = [&](const drivers::DecodedSample& s) {
    session.on_sample(s, arrival_ns, counters().frames);
  };

  // Why the loop ends, checked before every read.
  const auto stop_reason = [&](TimeNs now_ns) -> std::string {
    if (session.done()) return "count";
    if (stop.load()) return "stopped";
    if (now_ns >= end_ns) return "duration";
    return "";
  };

  if (can) {
    const std::string interface = can_interface_of(args.device);
    drivers::CanReader reader(interface, true);  // throws TransportError naming the interface
    summary.device_description = reader.describe();
    try {
      for (;;) {
        const TimeNs now = monotonic_now_ns();
        summary.end_reason = stop_reason(now);
        if (!summary.end_reason.empty()) break;
        const std::optional<drivers::ReceivedCanFrame> frame = reader.receive(next_timeout(now, end_ns));
        if (!frame) continue;
        arrival_ns = monotonic_now_ns();
        ++summary.can_frames_received;
        if (args.can_source) {
          const std::uint32_t mask = args.protocol == "dronecan" ? 0x7Fu : 0xFFu;
          if (!frame->frame.extended || (frame->frame.id & mask) != *args.can_source) {
            ++summary.can_frames_other_source;
            continue;
          }
        }
        can_decoder->feed(frame->frame, callback);
        if (!args.quiet) out.flush();
      }
    } catch (const drivers::TransportError& e) {
      summary.end_reason = std::string("device error: ") + e.what();
    }
    summary.can_kernel_drops = reader.counters().kernel_drops;
  } else {
    drivers::ByteStreamReader reader(args.device, args.serial,  // throws TransportError naming the path
                                     args.handshake ? drivers::ByteStreamReader::Access::read_write
                                                    : drivers::ByteStreamReader::Access::read_only);
    summary.device_description = reader.describe();
    if (args.handshake) run_handshake(args, reader, out, stop, summary.handshake);
    std::vector<std::uint8_t> buffer(4096);
    try {
      for (;;) {
        const TimeNs now = monotonic_now_ns();
        summary.end_reason = stop_reason(now);
        if (!summary.end_reason.empty()) break;
        const drivers::ReadResult r = reader.read_some(buffer, next_timeout(now, end_ns));
        arrival_ns = monotonic_now_ns();
        summary.bytes_received += r.bytes;
        if (r.bytes > 0) {
          stream_decoder->feed(std::span<const std::uint8_t>(buffer.data(), r.bytes), callback);
          if (!args.quiet) out.flush();  // lines reach a pipe as they are decoded, not in 4 KiB blocks
        }
        if (r.end_of_stream) {
          summary.end_reason = session.done() ? "count" : "end of stream";
          break;
        }
      }
    } catch (const drivers::TransportError& e) {
      summary.end_reason = std::string("device error: ") + e.what();
    }
  }
  summary.wall_time_s = seconds_between(start_ns, monotonic_now_ns());
  session.finish(summary, counters());
  return summary;
}

nlohmann::json summary_json(const ListenSummary& s) {
  const auto opt = [](const auto& value) { return value ? nlohmann::json(*value) : nlohmann::json(nullptr); };
  nlohmann::json j{{"type", "summary"},
                   {"protocol", s.protocol},
                   {"device", s.device},
                   {"device_description", s.device_description},
                   {"end_reason", s.end_reason},
                   {"wall_time_s", s.wall_time_s},
                   {"samples", s.samples},
                   {"frames", s.frames},
                   {"checksum_errors", s.checksum_errors},
                   {"resync_bytes", s.resync_bytes},
                   {"sequence_gaps", s.sequence_gaps},
                   {"own_sequence_gaps", opt(s.own_sequence_gaps)},
                   {"sequence_backward_steps", s.sequence_backward_steps},
                   {"other_errors", s.other_errors},
                   {"first_sample_t_ns", opt(s.first_sample_t_ns)},
                   {"last_sample_t_ns", opt(s.last_sample_t_ns)},
                   {"rate_from_sample_time_hz", opt(s.rate_from_sample_time_hz)},
                   {"rate_from_arrival_hz", opt(s.rate_from_arrival_hz)},
                   {"arrival_jitter_us",
                    {{"p50", opt(s.jitter_p50_us)}, {"p99", opt(s.jitter_p99_us)}, {"max", opt(s.jitter_max_us)}}},
                   {"expected_rate_hz", opt(s.expected_rate_hz)},
                   {"rate_of_sample_time_grid_hz", opt(s.rate_of_sample_time_grid_hz)},
                   {"missing_samples", opt(s.missing_samples)},
                   {"rate_ok", opt(s.rate_ok)}};
  if (!s.handshake.empty()) {
    nlohmann::json steps = nlohmann::json::array();
    for (const auto& r : s.handshake)
      steps.push_back({{"step", r.step}, {"answered", r.answered}, {"accepted", r.accepted}, {"reply", r.reply},
                       {"latency_ms", r.latency_ms}});
    j["handshake"] = steps;
  }
  if (is_can_protocol(s.protocol)) {
    j["can_frames_received"] = s.can_frames_received;
    j["can_frames_other_source"] = s.can_frames_other_source;
    j["can_kernel_drops"] = s.can_kernel_drops;
  } else {
    j["bytes_received"] = s.bytes_received;
  }
  return j;
}

std::string summary_text(const ListenSummary& s) {
  std::ostringstream o;
  const auto hz = [](const std::optional<double>& v) {
    if (!v) return std::string("n/a");
    char b[64];
    std::snprintf(b, sizeof b, "%.6f Hz", *v);
    return std::string(b);
  };
  const auto us = [](const std::optional<double>& v) {
    if (!v) return std::string("n/a");
    char b[64];
    std::snprintf(b, sizeof b, "%.1f us", *v);
    return std::string(b);
  };
  o << "listen " << s.protocol << " on " << (s.device_description.empty() ? s.device : s.device_description)
    << ": ended (" << s.end_reason << ") after " << s.wall_time_s << " s\n";
  if (!s.handshake.empty()) {
    std::size_t answered = 0, accepted = 0;
    for (const auto& r : s.handshake) {
      answered += r.answered ? 1 : 0;
      accepted += r.accepted ? 1 : 0;
    }
    o << "  handshake: " << s.handshake.size() << " steps, " << answered << " answered, " << accepted
      << " accepted\n";
  }
  o << "  samples " << s.samples << ", frames " << s.frames << ", checksum errors " << s.checksum_errors
    << ", resync bytes " << s.resync_bytes << ", other errors " << s.other_errors << "\n";
  o << "  sequence gaps " << s.sequence_gaps << " (decoder), "
    << (s.own_sequence_gaps ? std::to_string(*s.own_sequence_gaps) : std::string("n/a")) << " (own check), "
    << s.sequence_backward_steps << " backward steps\n";
  if (is_can_protocol(s.protocol)) {
    o << "  CAN frames " << s.can_frames_received << " (other sources " << s.can_frames_other_source
      << ", kernel drops " << s.can_kernel_drops << ")\n";
  } else {
    o << "  bytes " << s.bytes_received << "\n";
  }
  o << "  first sample t "
    << (s.first_sample_t_ns ? format_seconds(*s.first_sample_t_ns) + " s" : std::string("n/a")) << ", last "
    << (s.last_sample_t_ns ? format_seconds(*s.last_sample_t_ns) + " s" : std::string("n/a")) << "\n";
  o << "  rate " << hz(s.rate_from_sample_time_hz) << " (sample times), " << hz(s.rate_from_arrival_hz)
    << " (arrival)\n";
  o << "  arrival jitter p50 " << us(s.jitter_p50_us) << ", p99 " << us(s.jitter_p99_us) << ", max "
    << us(s.jitter_max_us) << "\n";
  if (s.expected_rate_hz) {
    o << "  expected " << hz(s.expected_rate_hz) << ": " << (s.rate_ok.value_or(false) ? "matches" : "DOES NOT MATCH");
    if (s.rate_of_sample_time_grid_hz) o << " (sample-time grid " << hz(s.rate_of_sample_time_grid_hz) << ")";
    o << "\n";
    if (s.missing_samples && *s.missing_samples > 0) {
      const double share = 100.0 * static_cast<double>(*s.missing_samples) /
                           static_cast<double>(*s.missing_samples + s.samples);
      char b[64];
      std::snprintf(b, sizeof b, "%llu (%.2f %%)", static_cast<unsigned long long>(*s.missing_samples), share);
      o << "  missing samples " << b
        << ": sample time stepped by two or more periods (the sender skipped them; imuemud counts these as "
           "dropped_late or not_sent)\n";
    }
  }
  return o.str();
}

namespace {
std::atomic<bool> g_listen_stop{false};
extern "C" void on_listen_signal(int) { g_listen_stop = true; }
}  // namespace

int run_listen(const ListenArgs& args) {
  struct sigaction sa {};
  sa.sa_handler = on_listen_signal;
  sigemptyset(&sa.sa_mask);
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
  g_listen_stop = false;
  try {
    const ListenSummary summary = listen(args, std::cout, g_listen_stop);
    if (args.json) {
      std::cout << summary_json(summary).dump() << std::endl;
    } else {
      std::cout << summary_text(summary) << std::flush;
    }
    return kOk;
  } catch (const drivers::TransportError& e) {
    std::cerr << "imuemu listen: cannot open device '" << args.device << "': " << e.what() << "\n";
    return kCannotProcess;
  } catch (const std::invalid_argument& e) {
    std::cerr << "imuemu listen: " << e.what() << "\n";
    return kUsageError;
  } catch (const std::runtime_error& e) {
    std::cerr << "imuemu listen: " << e.what() << "\n";
    return kOutputError;
  }
}

void add_listen_command(CLI::App& app, int& exit_code) {
  struct Options {
    ListenArgs args;
    std::string parity = "none", flow_control = "none", mavlink_message = "hil_sensor", j1939_axes = "j1939da", mip_time_base;
    int dronecan_node_id = -1, j1939_source_address = -1;
    std::int64_t mip_gps_time_at_t0_ns = 0, dronecan_timestamp_offset_ns = 0;
  };
  auto options = std::make_shared<Options>();
  ListenArgs& a = options->args;
  std::vector<std::string> protocols = drivers::stream_protocol_names();
  for (const auto& n : drivers::can_protocol_names()) protocols.push_back(n);

  auto* c = app.add_subcommand("listen", "Decode a live IMU stream (pty, serial port, FIFO, SocketCAN) and report samples, errors and timing");
  c->add_option("--protocol", a.protocol, "Wire protocol")->required()->check(CLI::IsMember(protocols));
  c->add_option("--device", a.device, "Byte streams: pty/symlink, serial port, FIFO or file; CAN: can:IFACE or IFACE")->required();
  c->add_option("--baud", a.serial.baud, "Serial port: baud rate")->capture_default_str()->check(CLI::PositiveNumber);
  c->add_option("--data-bits", a.serial.data_bits, "Serial port: data bits")->capture_default_str()->check(CLI::Range(5, 8));
  c->add_option("--parity", options->parity, "Serial port: none|odd|even|mark|space")->capture_default_str()
      ->check(CLI::IsMember({"none", "odd", "even", "mark", "space"}));
  c->add_option("--stop-bits", a.serial.stop_bits, "Serial port: 1 or 2")->capture_default_str()->check(CLI::IsMember({1, 2}));
  c->add_option("--flow-control", options->flow_control, "Serial port: none|rtscts|xonxoff")->capture_default_str()
      ->check(CLI::IsMember({"none", "rtscts", "xonxoff"}));
  c->add_option("--duration-s", a.duration_s, "Stop after this many seconds of wall time (0: no limit)")->check(seconds_in(0.0, kMaxDurationS));
  c->add_option("--count", a.count, "Stop after this many samples (0: no limit)");
  c->add_flag("--handshake", a.handshake,
              "Act as the driver first: send the start-up sequence a common driver sends (mip: mip_sdk's; mavlink2: a "
              "ground station's; vectornav: the SDK's and PX4's register reads; sbg: sbgEComExample's GET /api/v1/info and CMD_INFO; "
              "xsens: xspublic's GotoConfig ... GotoMeasurement) and report each reply, then listen");
  c->add_option("--handshake-timeout-ms", a.handshake_timeout_ms, "--handshake: how long to wait for each reply")
      ->capture_default_str()
      ->check(CLI::Range(1, 60000));
  c->add_flag("--json", a.json, "NDJSON: one object per sample line and a final summary object");
  c->add_flag("--quiet", a.quiet, "Print the summary only");
  c->add_option("--every", a.every, "Print every Nth sample")->capture_default_str()->check(CLI::PositiveNumber);
  c->add_option("--out", a.out_path, "CSV of every decoded sample (sequence, t_ns, gyro, accel, dtheta, dv, status)");
  c->add_option("--expect-rate", a.expect_rate_hz, "Expected sample rate (Hz): the summary says whether the rate of the sample-time grid matches, and counts samples missing from that grid apart")->check(finite_in(0.0, 1e6));
  c->add_option("--rate-tolerance", a.rate_tolerance, "Relative tolerance of --expect-rate")->capture_default_str()->check(finite_in(0.0, 1.0, true));
  c->add_option("--mavlink-sample-message", options->mavlink_message, "mavlink2: samples from hil_sensor (#107) or highres_imu (#105)")
      ->capture_default_str()->check(CLI::IsMember({"hil_sensor", "highres_imu"}));
  c->add_option("--mip-gps-time-at-t0-ns", options->mip_gps_time_at_t0_ns, "mip: GPS time (ns since 1980-01-06) of trajectory time 0, as the encoder was given")
      ->capture_default_str();
  c->add_option("--mip-time-base", options->mip_time_base,
                "mip: the encoder's time_base: unknown (internal clock), gps or utc (default gps with "
                "--mip-gps-time-at-t0-ns, else unknown)")
      ->check(CLI::IsMember({"unknown", "gps", "utc"}));
  c->add_option("--dronecan-node-id", options->dronecan_node_id, "dronecan: only frames from this node id (1..127)")->check(CLI::Range(1, 127));
  c->add_option("--dronecan-timestamp-offset-ns", options->dronecan_timestamp_offset_ns, "dronecan: the encoder's timestamp offset")->capture_default_str();
  c->add_option("--j1939-source-address", options->j1939_source_address, "j1939: only frames from this source address (0..253)")->check(CLI::Range(0, 253));
  c->add_option("--j1939-axes", options->j1939_axes,
                "j1939: vehicle axes the encoder used: j1939da (the SPN definitions), iso8855 (all z up) or sae-j670e "
                "(all z down)")
      ->capture_default_str()->check(CLI::IsMember({"j1939da", "iso8855", "sae-j670e"}));

  c->callback([options, &exit_code] {
    ListenArgs args = options->args;
    try {
      args.serial.parity = drivers::parse_parity(options->parity);
      args.serial.flow_control = drivers::parse_flow_control(options->flow_control);
    } catch (const drivers::TransportError& e) {
      std::cerr << "imuemu listen: " << e.what() << "\n";
      exit_code = kUsageError;
      return;
    }
    args.stream_options.mavlink_hil_sensor = options->mavlink_message == "hil_sensor";
    args.stream_options.mavlink_highres_imu = !args.stream_options.mavlink_hil_sensor;
    args.stream_options.mip_gps_time_at_t0_ns = options->mip_gps_time_at_t0_ns;
    const std::string& base =
        options->mip_time_base.empty() ? (options->mip_gps_time_at_t0_ns != 0 ? "gps" : "unknown") : options->mip_time_base;
    args.stream_options.mip_time_base = base == "gps"   ? drivers::MipTimeBase::gps
                                        : base == "utc" ? drivers::MipTimeBase::utc
                                                        : drivers::MipTimeBase::unknown;
    args.can_options.dronecan.timestamp_offset_ns = options->dronecan_timestamp_offset_ns;
    args.can_options.j1939.axes = options->j1939_axes == "iso8855"     ? drivers::j1939::VehicleAxes::kIso8855ZUp
                                  : options->j1939_axes == "sae-j670e" ? drivers::j1939::VehicleAxes::kSaeJ670eZDown
                                                                       : drivers::j1939::VehicleAxes::kJ1939da;
    if (args.protocol == "dronecan" && options->dronecan_node_id >= 0) {
      args.can_options.dronecan.node_id = static_cast<std::uint8_t>(options->dronecan_node_id);
      args.can_source = args.can_options.dronecan.node_id;
    }
    if (args.protocol == "j1939" && options->j1939_source_address >= 0) {
      args.can_options.j1939.source_address = static_cast<std::uint8_t>(options->j1939_source_address);
      args.can_source = args.can_options.j1939.source_address;
    }
    exit_code = run_listen(args);
  });
}

}  // namespace imuemu::cli
