// GPIO sync output through libgpiod's v1 API (the GPIO character device):
// a pulse on every Nth sample, edge at the sample instant, and optionally a
// 1PPS pulse aligned to whole trajectory seconds, for a data-ready / sync
// input on the system under test.
//
// The caller (the emission thread) calls pulse(sample_counter, t_ns) at each
// sample instant. The rising (leading) edge is set right there, so its timing
// is the emission thread's. The trailing edge `width` later is the job of a
// small helper thread: the emission thread arms a timerfd (CLOCK_MONOTONIC,
// absolute) and returns; the helper, woken by the kernel timer, ends the
// pulse. Why not end the pulse at the next pulse() call: the width would then
// be a whole sample period, not the configured one. Why not wait inside
// pulse(): that would block the emission thread for `width`. The threads share
// no lock: a per-line atomic state hands the line over (a pulse due while the
// previous one on that line has not ended is skipped and counted, never
// merged or cut short). The trailing edge is late by the helper's wake-up
// latency (tens of microseconds without real-time scheduling), reported as
// max_trailing_edge_delay_ns.
//
// 1PPS: the leading edge goes out with the first sample at or after each
// whole trajectory second (floor(t_ns / 1 s) changes). It is exact when the
// output period divides one second (100, 200, 400, 1000 Hz, ...); otherwise
// it lags the whole second by less than one output period.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>

#include "core/types.hpp"
#include "drivers/sync_pulse.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace imuemu::drivers {

struct GpioSyncOptions {
  // Found with gpiod_chip_open_lookup: "gpiochip0", "/dev/gpiochip0", "0" or the chip's label.
  std::string chip;
  unsigned line = 0;                    // line offset on the chip
  std::uint64_t every_n_samples = 1;    // pulse on samples 0, N, 2N, ...
  TimeNs pulse_width_ns = 100'000;
  bool active_low = false;              // polarity: the pulse drives the line low
  TimeNs sample_period_ns = 0;          // > 0: checks width < N x period (pulses must not overlap)
  std::optional<unsigned> pps_line;     // 1PPS output on this line
  std::string pps_chip;                 // chip of the 1PPS line; empty: `chip`
  TimeNs pps_width_ns = 100'000'000;
  bool pps_active_low = false;
  std::string consumer = "imuemu";      // the owner name others see (gpioinfo)
  // SCHED_FIFO priority for the thread that ends the pulses (1..99), so that
  // other jobs cannot delay trailing edges; 0: normal scheduling. If the
  // system refuses, a log line says so and the thread runs normally.
  int trailing_edge_priority = 0;
  // Receives each log line; empty: stderr.
  std::function<void(std::string_view)> log;
};

struct GpioSyncCounters {
  std::uint64_t pulses = 0;          // sync pulses started
  std::uint64_t pps_pulses = 0;      // 1PPS pulses started
  std::uint64_t skipped_pulses = 0;  // due while the previous pulse on the same line had not ended
  std::uint64_t set_errors = 0;      // failed line writes
  TimeNs max_trailing_edge_delay_ns = 0;  // worst lateness of a trailing edge after its due time
  // Lines between their leading edge and the trailing-edge thread's end of the
  // pulse. The line goes inactive a moment before the line is free for the
  // next pulse, so a caller that must not have its next pulse skipped waits
  // for this to be 0, not for the line's level.
  std::uint64_t pulses_in_progress = 0;
  // The trailing-edge thread ended with an exception (caught there, never
  // leaving the thread): counted, logged, and the sync output is down; later
  // pulses are not raised (counted skipped_pulses). Counted once the failure
  // is recorded and logged and the lines are inactive; `down` is set first.
  std::uint64_t helper_faults = 0;
  bool down = false;
};

class GpioSyncOutput {
 public:
  // Writes a line's logical level (true = active, whatever the polarity);
  // false when the write failed.
  using LineWriter = std::function<bool(bool active)>;

  // Requests the line(s) as outputs, inactive. Throws TransportError naming
  // the chip and line: bad options, chip not found (listing the chips there
  // are), no such line, line already claimed (naming its consumer).
  explicit GpioSyncOutput(GpioSyncOptions options);
  // The same pulse timing on other outputs (the tests' recording lines):
  // options.chip, line, polarity and consumer are not used; 1PPS is on when
  // `pps_line` is given.
  GpioSyncOutput(GpioSyncOptions options, LineWriter sync_line, LineWriter pps_line);
  ~GpioSyncOutput();  // ends a pulse in progress, releases the lines
  GpioSyncOutput(const GpioSyncOutput&) = delete;
  GpioSyncOutput& operator=(const GpioSyncOutput&) = delete;

  // At the sample instant; never blocks (one line write and one timer arm
  // per pulse). Called from one thread (the emission thread).
  void pulse(std::uint64_t sample_counter, TimeNs t_ns);
  // As pulse(), with the sync line driven by the device personality's own
  // sync-out setting (drivers/sync_pulse.hpp): its pulse, width and
  // polarity. A polarity change moves the line to the new idle level when no
  // pulse is in progress (at the next sample otherwise).
  void pulse(std::uint64_t sample_counter, TimeNs t_ns, const DeviceSyncPulse& device);

  GpioSyncCounters counters() const;
  std::string describe() const;
  // Whether the trailing-edge thread got SCHED_FIFO (trailing_edge_priority).
  bool trailing_edges_realtime() const noexcept { return helper_realtime_; }
  // What the trailing-edge thread's exception said; empty while it runs.
  std::string failure() const;

 private:
  struct Output;
  void check_options() const;
  std::unique_ptr<Output> request_line(gpiod_chip* chip, unsigned offset, bool active_low, TimeNs width_ns);
  void start_helper();
  void release_all() noexcept;
  void raise(Output& output, std::atomic<std::uint64_t>& started, TimeNs width_ns);
  void pps_step(TimeNs t_ns);
  void run_helper() noexcept;
  void end_pulses();
  void helper_failed(std::string_view what) noexcept;

  GpioSyncOptions options_;
  gpiod_chip* chip_ = nullptr;
  gpiod_chip* pps_chip_ = nullptr;  // == chip_ when the same
  std::unique_ptr<Output> sync_;
  std::unique_ptr<Output> pps_;
  std::optional<TimeNs> previous_t_ns_;
  int stop_fd_ = -1;
  bool helper_realtime_ = false;
  std::thread helper_;
  std::atomic<std::uint64_t> pulses_{0}, pps_pulses_{0}, skipped_{0}, set_errors_{0};
  std::atomic<TimeNs> max_delay_ns_{0};
  std::atomic<std::uint64_t> helper_faults_{0};
  std::atomic<bool> down_{false};
  mutable std::mutex failure_mutex_;
  std::string failure_;
};

}  // namespace imuemu::drivers
