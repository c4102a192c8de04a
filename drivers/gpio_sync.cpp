#include "drivers/gpio_sync.hpp"

#include <gpiod.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>
#include <sys/eventfd.h>
#include <sys/timerfd.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <ctime>
#include <filesystem>
#include <vector>

#include "drivers/queued_writer.hpp"
#include "drivers/transport.hpp"

namespace imuemu::drivers {
namespace {

TimeNs monotonic_ns() noexcept {
  timespec now{};
  ::clock_gettime(CLOCK_MONOTONIC, &now);
  return static_cast<TimeNs>(now.tv_sec) * kNsPerSecond + now.tv_nsec;
}

TimeNs floor_seconds(TimeNs t_ns) noexcept {
  TimeNs q = t_ns / kNsPerSecond;
  if (t_ns % kNsPerSecond != 0 && t_ns < 0) --q;
  return q;
}

std::string chips_present() {
  std::vector<std::string> names;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/dev", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind("gpiochip", 0) == 0) names.push_back(name);
  }
  if (names.empty()) return "this machine has no GPIO chips (no /dev/gpiochip*)";
  std::sort(names.begin(), names.end());
  std::string list = "chips here:";
  for (const auto& n : names) list += " " + n;
  return list;
}

gpiod_chip* open_chip(const std::string& descriptor) {
  if (descriptor.empty()) throw TransportError("GPIO sync: no chip given (e.g. gpiochip0)");
  gpiod_chip* chip = ::gpiod_chip_open_lookup(descriptor.c_str());
  if (chip == nullptr) {
    const int error = errno;
    const std::string why = error == ENOENT || error == ENODEV || error == 0 ? "not found (looked up as name, path, "
                                                                                "number and label)"
                                                                              : errno_message(error);
    throw TransportError("GPIO chip '" + descriptor + "': " + why + "; " + chips_present());
  }
  return chip;
}

std::string chip_text(gpiod_chip* chip) {
  return std::string("GPIO chip '") + ::gpiod_chip_name(chip) + "' [" + ::gpiod_chip_label(chip) + "]";
}

}  // namespace

struct GpioSyncOutput::Output {
  LineWriter write;
  gpiod_line* line = nullptr;  // when the writer is a requested gpiod line (released on close)
  int timer_fd = -1;
  TimeNs width_ns = 0;
  std::string name;            // "GPIO chip 'gpiochip0' [label] line 5"
  std::atomic<int> active{0};  // 1 from the leading edge until the helper has ended the pulse
  std::atomic<TimeNs> trailing_due_ns{0};
  // The device asked for the other polarity than the line was requested
  // with: its levels are swapped (idle = the request's active level).
  std::atomic<bool> inverted{false};
};

namespace {
// Drives the pulse level (on: the leading edge) whatever the polarity.
bool drive(const GpioSyncOutput::LineWriter& write, const std::atomic<bool>& inverted, bool on) {
  return write(on != inverted.load(std::memory_order_acquire));
}
}  // namespace

void GpioSyncOutput::raise(Output& output, std::atomic<std::uint64_t>& started, TimeNs width_ns) {
  int idle = 0;
  if (!output.active.compare_exchange_strong(idle, 1, std::memory_order_acq_rel)) {
    skipped_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (!drive(output.write, output.inverted, true)) {
    set_errors_.fetch_add(1, std::memory_order_relaxed);
    output.active.store(0, std::memory_order_release);
    return;
  }
  // The width counts from when the leading edge is on the line, not from before
  // the write: a write that is slow (a preempted ioctl, a slow guest) would
  // otherwise eat into the pulse and make it shorter than configured.
  const TimeNs due = monotonic_ns() + width_ns;
  output.trailing_due_ns.store(due, std::memory_order_relaxed);
  itimerspec when{};
  when.it_value.tv_sec = static_cast<time_t>(due / kNsPerSecond);
  when.it_value.tv_nsec = static_cast<long>(due % kNsPerSecond);
  if (::timerfd_settime(output.timer_fd, TFD_TIMER_ABSTIME, &when, nullptr) != 0) {
    // No timer, no trailing edge from the helper: end the pulse here (short).
    drive(output.write, output.inverted, false);
    set_errors_.fetch_add(1, std::memory_order_relaxed);
    output.active.store(0, std::memory_order_release);
    return;
  }
  started.fetch_add(1, std::memory_order_relaxed);
}

void GpioSyncOutput::pulse(std::uint64_t sample_counter, TimeNs t_ns) {
  if (down_.load(std::memory_order_acquire)) {
    // No thread ends pulses any more: a leading edge would stay on the line.
    if (sample_counter % options_.every_n_samples == 0) skipped_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  if (sample_counter % options_.every_n_samples == 0) raise(*sync_, pulses_, sync_->width_ns);
  pps_step(t_ns);
}

void GpioSyncOutput::pulse(std::uint64_t sample_counter, TimeNs t_ns, const DeviceSyncPulse& device) {
  (void)sample_counter;
  if (down_.load(std::memory_order_acquire)) {
    if (device.pulse) skipped_.fetch_add(1, std::memory_order_relaxed);
    return;
  }
  Output& sync = *sync_;
  const bool invert = device.active_low != options_.active_low;
  if (invert != sync.inverted.load(std::memory_order_relaxed) && sync.active.load(std::memory_order_acquire) == 0) {
    // Only this thread raises pulses and the line is idle: the helper thread
    // will not touch it until the next leading edge.
    sync.inverted.store(invert, std::memory_order_release);
    if (!drive(sync.write, sync.inverted, false)) set_errors_.fetch_add(1, std::memory_order_relaxed);
  }
  if (device.pulse && device.width_ns > 0) raise(sync, pulses_, device.width_ns);
  pps_step(t_ns);
}

void GpioSyncOutput::pps_step(TimeNs t_ns) {
  if (pps_) {
    const bool whole_second_reached = previous_t_ns_ ? floor_seconds(t_ns) > floor_seconds(*previous_t_ns_)
                                                     : t_ns % kNsPerSecond == 0;
    if (whole_second_reached) raise(*pps_, pps_pulses_, pps_->width_ns);
  }
  previous_t_ns_ = t_ns;
}

// No exception leaves the thread (a LineWriter may throw, a std::function
// may be empty): it is recorded, counted, logged, and the sync output marked
// down, instead of std::terminate taking the emission with it.
void GpioSyncOutput::run_helper() noexcept {
  pthread_setname_np(pthread_self(), "imuemu-gpio");
  run_thread_body([this] { end_pulses(); }, [this](const char* what) { helper_failed(what); });
}

void GpioSyncOutput::helper_failed(std::string_view what) noexcept {
  down_.store(true, std::memory_order_release);
  try {
    {
      const std::lock_guard lock(failure_mutex_);
      failure_ = what;
    }
    emit_log(options_.log, "GPIO sync: the trailing-edge thread failed: " + std::string(what) +
                               "; sync output down, later pulses skipped");
  } catch (...) {  // out of memory or a throwing log sink: the counters still say it
  }
  // Leave no line active: pulse() raises none once down_ is set, and an
  // output whose pulse did not end keeps its active flag, so raise() skips it.
  for (Output* output : {sync_.get(), pps_.get()}) {
    if (output == nullptr || !output->write) continue;
    try {
      drive(output->write, output->inverted, false);
    } catch (...) {
    }
  }
  // Counted last: once helper_faults says so, the failure is recorded and
  // logged and the lines are left inactive (a test, or a status reader,
  // waits for this, not for `down`, which is set first to stop new pulses).
  helper_faults_.fetch_add(1, std::memory_order_release);
}

std::string GpioSyncOutput::failure() const {
  const std::lock_guard lock(failure_mutex_);
  return failure_;
}

// The helper's loop: ends each pulse when its timer fires, until stop_fd_.
void GpioSyncOutput::end_pulses() {
  Output* outputs[2] = {sync_.get(), pps_.get()};
  pollfd fds[3] = {{stop_fd_, POLLIN, 0}, {sync_->timer_fd, POLLIN, 0}, {pps_ ? pps_->timer_fd : -1, POLLIN, 0}};
  const nfds_t count = pps_ ? 3 : 2;
  for (;;) {
    if (::poll(fds, count, -1) < 0) {
      if (errno == EINTR) continue;
      break;
    }
    if (fds[0].revents) break;
    for (int i = 0; i < 2; ++i) {
      if (fds[i + 1].fd < 0 || !(fds[i + 1].revents & POLLIN)) continue;
      Output& output = *outputs[i];
      std::uint64_t expirations = 0;
      if (::read(output.timer_fd, &expirations, sizeof expirations) != sizeof expirations) continue;
      if (!drive(output.write, output.inverted, false)) set_errors_.fetch_add(1, std::memory_order_relaxed);
      const TimeNs delay = monotonic_ns() - output.trailing_due_ns.load(std::memory_order_relaxed);
      TimeNs worst = max_delay_ns_.load(std::memory_order_relaxed);
      while (delay > worst && !max_delay_ns_.compare_exchange_weak(worst, delay, std::memory_order_relaxed)) {
      }
      // The line is inactive before the emission thread may raise it again.
      output.active.store(0, std::memory_order_release);
    }
  }
}

std::unique_ptr<GpioSyncOutput::Output> GpioSyncOutput::request_line(gpiod_chip* chip, unsigned offset,
                                                                     bool active_low, TimeNs width_ns) {
  auto output = std::make_unique<Output>();
  output->width_ns = width_ns;
  output->name = chip_text(chip) + " line " + std::to_string(offset);
  const unsigned lines = ::gpiod_chip_num_lines(chip);
  if (offset >= lines) {
    throw TransportError(chip_text(chip) + " has " + std::to_string(lines) + " lines (0.." +
                         std::to_string(lines == 0 ? 0 : lines - 1) + "); there is no line " + std::to_string(offset));
  }
  gpiod_line* line = ::gpiod_chip_get_line(chip, offset);
  if (line == nullptr) throw TransportError(output->name + ": " + errno_message(errno));
  // ACTIVE_LOW makes the kernel invert: logical 1 (active) drives the pin low.
  const int flags = active_low ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
  if (::gpiod_line_request_output_flags(line, options_.consumer.c_str(), flags, 0) != 0) {
    const int error = errno;
    if (error == EBUSY) {
      ::gpiod_line_update(line);
      const char* owner = ::gpiod_line_consumer(line);
      throw TransportError(output->name + " is already claimed by " +
                           (owner ? std::string("'") + owner + "'" : std::string("another user (a kernel driver?)")));
    }
    throw TransportError(output->name + ": cannot request it as an output: " + errno_message(error));
  }
  output->line = line;
  output->write = [line](bool active) { return ::gpiod_line_set_value(line, active ? 1 : 0) == 0; };
  return output;
}

void GpioSyncOutput::check_options() const {
  // Options first: their errors need no hardware.
  if (options_.every_n_samples == 0) throw TransportError("GPIO sync: every_n_samples must be at least 1");
  if (options_.pulse_width_ns <= 0) throw TransportError("GPIO sync: pulse width must be positive");
  if (options_.sample_period_ns > 0 &&
      options_.pulse_width_ns >= static_cast<TimeNs>(options_.every_n_samples) * options_.sample_period_ns) {
    throw TransportError("GPIO sync: a " + std::to_string(options_.pulse_width_ns) +
                         " ns pulse does not end before the next one (every " +
                         std::to_string(options_.every_n_samples) + " samples of " +
                         std::to_string(options_.sample_period_ns) + " ns)");
  }
  if (options_.pps_line && (options_.pps_width_ns <= 0 || options_.pps_width_ns >= kNsPerSecond)) {
    throw TransportError("GPIO sync: 1PPS pulse width must be between 0 and 1 s");
  }
}

void GpioSyncOutput::start_helper() {
  for (Output* output : {sync_.get(), pps_.get()}) {
    if (output == nullptr) continue;
    output->timer_fd = ::timerfd_create(CLOCK_MONOTONIC, TFD_NONBLOCK | TFD_CLOEXEC);
    if (output->timer_fd < 0) throw TransportError(output->name + ": timerfd: " + errno_message(errno));
  }
  stop_fd_ = ::eventfd(0, EFD_NONBLOCK | EFD_CLOEXEC);
  if (stop_fd_ < 0) throw TransportError("GPIO sync: eventfd: " + errno_message(errno));
  helper_ = std::thread([this] { run_helper(); });
  if (options_.trailing_edge_priority > 0) {
    sched_param param{};
    param.sched_priority = options_.trailing_edge_priority;
    const int error = ::pthread_setschedparam(helper_.native_handle(), SCHED_FIFO, &param);
    helper_realtime_ = error == 0;
    if (error != 0) {
      emit_log(options_.log, "GPIO sync: trailing edges run without SCHED_FIFO priority " +
                                 std::to_string(options_.trailing_edge_priority) + ": " + errno_message(error));
    }
  }
}

void GpioSyncOutput::release_all() noexcept {
  for (Output* output : {sync_.get(), pps_.get()}) {
    if (output == nullptr) continue;
    try {
      if (output->write) output->write(false);  // inactive, whatever the polarity
    } catch (...) {  // a LineWriter that throws: nothing leaves a noexcept release
    }
    if (output->line != nullptr) ::gpiod_line_release(output->line);
    if (output->timer_fd >= 0) ::close(output->timer_fd);
  }
  if (pps_chip_ != nullptr && pps_chip_ != chip_) ::gpiod_chip_close(pps_chip_);
  if (chip_ != nullptr) ::gpiod_chip_close(chip_);
  if (stop_fd_ >= 0) ::close(stop_fd_);
}

GpioSyncOutput::GpioSyncOutput(GpioSyncOptions options) : options_(std::move(options)) {
  check_options();
  try {
    chip_ = open_chip(options_.chip);
    sync_ = request_line(chip_, options_.line, options_.active_low, options_.pulse_width_ns);
    if (options_.pps_line) {
      const bool same_chip = options_.pps_chip.empty() || options_.pps_chip == options_.chip;
      pps_chip_ = same_chip ? chip_ : open_chip(options_.pps_chip);
      if (pps_chip_ == chip_ && *options_.pps_line == options_.line) {
        throw TransportError(sync_->name + ": the sync pulse and the 1PPS output cannot share a line");
      }
      pps_ = request_line(pps_chip_, *options_.pps_line, options_.pps_active_low, options_.pps_width_ns);
    }
    start_helper();
  } catch (...) {
    release_all();
    throw;
  }
}

GpioSyncOutput::GpioSyncOutput(GpioSyncOptions options, LineWriter sync_line, LineWriter pps_line)
    : options_(std::move(options)) {
  if (!pps_line) options_.pps_line.reset();
  else if (!options_.pps_line) options_.pps_line = 0;
  check_options();
  sync_ = std::make_unique<Output>();
  sync_->write = std::move(sync_line);
  sync_->width_ns = options_.pulse_width_ns;
  sync_->name = "sync line";
  if (pps_line) {
    pps_ = std::make_unique<Output>();
    pps_->write = std::move(pps_line);
    pps_->width_ns = options_.pps_width_ns;
    pps_->name = "1PPS line";
  }
  try {
    sync_->write(false);
    if (pps_) pps_->write(false);
    start_helper();
  } catch (...) {
    release_all();
    throw;
  }
}

GpioSyncOutput::~GpioSyncOutput() {
  const std::uint64_t one = 1;
  [[maybe_unused]] const auto written = ::write(stop_fd_, &one, sizeof one);
  helper_.join();
  release_all();
}

GpioSyncCounters GpioSyncOutput::counters() const {
  GpioSyncCounters c;
  c.pulses = pulses_.load(std::memory_order_relaxed);
  c.pps_pulses = pps_pulses_.load(std::memory_order_relaxed);
  c.skipped_pulses = skipped_.load(std::memory_order_relaxed);
  c.set_errors = set_errors_.load(std::memory_order_relaxed);
  c.max_trailing_edge_delay_ns = max_delay_ns_.load(std::memory_order_relaxed);
  c.helper_faults = helper_faults_.load(std::memory_order_acquire);
  c.down = down_.load(std::memory_order_acquire);
  for (const Output* output : {sync_.get(), pps_.get()}) {
    if (output != nullptr && output->active.load(std::memory_order_acquire) != 0) ++c.pulses_in_progress;
  }
  return c;
}

std::string GpioSyncOutput::describe() const {
  std::string text = "gpio sync " + sync_->name + ", every " + std::to_string(options_.every_n_samples) +
                     " samples, " + std::to_string(options_.pulse_width_ns) + " ns " +
                     (options_.active_low ? "active-low" : "active-high");
  if (pps_) text += "; 1PPS on " + pps_->name;
  return text;
}

}  // namespace imuemu::drivers
