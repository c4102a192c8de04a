#include "daemon/service/status_report.hpp"

#include <sstream>

#include "daemon/service/service_notify.hpp"
#include "log/log.hpp"

namespace imuemu::service {

namespace {

constexpr auto kSummaryLogPeriod = std::chrono::seconds(60);
constexpr auto kRefusalLogPeriod = std::chrono::seconds(10);
constexpr auto kBehindLogPeriod = std::chrono::seconds(10);

std::string us_text(TimeNs ns) { return std::to_string(ns / 1000) + " us"; }

}  // namespace

std::string summary_line(const std::string& scene_name, const emission::EngineStats& s, bool alive) {
  std::ostringstream out;
  out << "scene " << scene_name << ":";
  bool first = true;
  for (const auto& d : s.devices) {
    out << (first ? " " : "; ") << d.name << " " << d.emitted << " samples";
    if (d.extrapolated > 0 || d.blending > 0) out << " (" << d.extrapolated << " extrapolated, " << d.blending << " blending)";
    if (d.producer_late > 0) out << ", " << d.producer_late << " underruns";
    if (d.deadline_misses > 0) out << ", " << d.deadline_misses << " late";
    if (d.write_errors > 0) out << ", " << d.write_errors << " not written";
    if (d.dropped_link_down > 0) out << ", " << d.dropped_link_down << " dropped (no reader/link down)";
    if (d.faults.active > 0) out << ", " << d.faults.active << " fault" << (d.faults.active == 1 ? "" : "s") << " acting";
    if (d.faults.silenced > 0) out << ", " << d.faults.silenced << " silenced by faults";
    first = false;
  }
  out << "; lateness p99 " << us_text(s.lateness.p99_ns) << ", max " << us_text(s.lateness.max_ns);
  if (s.pose_source) {
    out << "; input " << s.pose_source->accepted << " poses";
    if (s.pose_source->lost > 0) out << ", " << s.pose_source->lost << " lost";
    if (s.pose_source->rejected > 0) out << ", " << s.pose_source->rejected << " rejected";
    if (s.pose_source->accepted == 0) out << " (waiting for the first pose)";
  }
  if (s.poses_refused > 0) out << "; " << s.poses_refused << " poses refused by the method";
  if (!alive) out << "; EMITTER STALLED";
  return out.str();
}

nlohmann::json status_json(const DaemonStatus& d) {
  nlohmann::json status{
      {"scene", d.scene_name},
      {"scene_file", d.scene_file},
      {"pid", d.pid},
      {"uptime_s", static_cast<double>(d.uptime_ns) / 1e9},
      {"imus", d.imus},
      {"waiting_for_device", d.waiting_for_device},
      {"fault_log", d.fault_log_path.empty() ? nlohmann::json(nullptr) : nlohmann::json(d.fault_log_path)},
      {"fault_log_output", d.fault_log_output ? to_json(*d.fault_log_output) : nlohmann::json(nullptr)},
      {"log_lines_lost", d.log_lines_lost},
  };
  if (d.building) {
    status["building"] = {{"what", d.building->start ? "start" : "reload"},
                          {"elapsed_s", static_cast<double>(d.building->elapsed_ns) / 1e9}};
  } else {
    status["building"] = nullptr;
  }
  if (d.engine) {
    status["samples_emitted"] = d.engine->emitted;
    status["emitter_progressing"] = d.emitter_progressing;
    status["engine"] = emission::to_json(*d.engine);
  } else {
    status["samples_emitted"] = 0;
    status["emitter_progressing"] = false;
    status["engine"] = nullptr;
  }
  if (d.watchdog) {
    status["watchdog"] = {{"interval_s", static_cast<double>(d.watchdog->interval.count()) / 1e6},
                          {"pets_sent", d.watchdog->pets_sent},
                          {"pets_withheld", d.watchdog->pets_withheld}};
  } else {
    status["watchdog"] = nullptr;
  }
  return status;
}

void StatusReport::log_new_refusals(const emission::EngineStats& s, Clock::time_point now) {
  if (s.poses_refused < refusals_logged_) refusals_logged_ = 0;  // a new engine (restart, reload)
  if (s.poses_refused <= refusals_logged_) return;
  if (refusals_logged_ > 0 && now - last_refusal_log_ < kRefusalLogPeriod) return;
  log_warning(std::to_string(s.poses_refused - refusals_logged_) + " poses refused by the method (" +
              std::to_string(s.poses_refused) + " in all); the newest: " +
              (s.last_pose_refusal.empty() ? std::string("no reason recorded") : s.last_pose_refusal));
  refusals_logged_ = s.poses_refused;
  last_refusal_log_ = now;
}

void StatusReport::log_falling_behind(const emission::EngineStats& s, Clock::time_point now) {
  if (behind_logged_.size() != s.devices.size()) behind_logged_.assign(s.devices.size(), {});
  for (std::size_t i = 0; i < s.devices.size(); ++i) {
    const emission::DeviceStats& d = s.devices[i];
    if (d.producer_late < behind_logged_[i].underruns || d.deadline_misses < behind_logged_[i].deadline_misses)
      behind_logged_[i] = {};  // a new engine (restart, reload)
  }
  if (behind_logged_once_ && now - last_behind_log_ < kBehindLogPeriod) return;
  std::string text;
  for (std::size_t i = 0; i < s.devices.size(); ++i) {
    const emission::DeviceStats& d = s.devices[i];
    const std::uint64_t under = d.producer_late - behind_logged_[i].underruns;
    const std::uint64_t missed = d.deadline_misses - behind_logged_[i].deadline_misses;
    if (under == 0 && missed == 0) continue;
    text += (text.empty() ? "" : "; ") + d.name + " is falling behind: " + std::to_string(under) +
            " underruns (no sample ready when due) and " + std::to_string(missed) +
            " deadline misses (woken more than a period late) since the last report (" +
            std::to_string(d.producer_late) + " and " + std::to_string(d.deadline_misses) + " in all)";
    behind_logged_[i] = {d.producer_late, d.deadline_misses};
  }
  if (text.empty()) return;
  log_warning(text);
  last_behind_log_ = now;
  behind_logged_once_ = true;
}

void StatusReport::publish(const std::string& scene_name, const emission::EngineStats& s, bool alive,
                           Clock::time_point now, std::chrono::nanoseconds status_period) {
  if (now - last_status_ < status_period) return;
  last_status_ = now;
  const std::string line = summary_line(scene_name, s, alive);
  notify_status(line);
  if (now - last_summary_ >= kSummaryLogPeriod) {
    last_summary_ = now;
    log_info(line);
  } else {
    log_debug(line);
  }
}

}  // namespace imuemu::service
