// The SBG device's command side (issue 29): what an ELLIPSE-A / -N / -D
// (firmware 3.x) answers on its main serial port, from the sbgECom manual and
// library ([F], [L] in sbg.hpp; no code copied):
//
//  [C] Commands are frames of class CMD_0 (0x10). A command with an answer
//      (CMD_INFO, OUTPUT_CONF get, API_GET / API_POST) is answered by a frame
//      of the same class and id; a setting command (OUTPUT_CONF set,
//      SETTINGS_ACTION) by CMD_ACK (id 0): the acknowledged id and class and
//      a uint16 error code (sbg.hpp ErrorCode, 0 = done). A command refused
//      (unknown id, a payload of the wrong size, a value out of range) gets
//      CMD_ACK with its error code and changes nothing; sbgECom's
//      sbgEComReceiveCmd2 turns that ACK into the caller's error.
//  [I] CMD_INFO (4), empty request: product code (32 bytes, NUL padded),
//      serial number u32, calibration revision u32, calibration year u16,
//      month u8, day u8, hardware revision u32, firmware revision u32
//      (sbgVersion.h: basic scheme major.minor.rev.build in bytes 3..0;
//      software scheme bit 31, qualifier bits 28-30, major 22-27, minor
//      16-21, build 0-15).
//  [O] OUTPUT_CONF (30): request port u8, message id u8, class u8 (get:
//      answered with the same three bytes and the mode u16) or with the mode
//      u16 (set: ACK). Ports A (0) and C (2) keep their own settings; the
//      emulated line is port A.
//  [S] SETTINGS_ACTION (1), one byte: 0 reboot, 1 save then reboot, 2
//      restore the factory settings, save and reboot (ACK first).
//  [R] REST API (sbgEComCmdApi.c): API_GET (48) carries path\0query\0,
//      API_POST (47) path\0query\0body\0; the reply, same class and id, is a
//      uint16 HTTP status code and a NUL-terminated JSON body. Answered:
//      GET /api/v1/info; GET /api/v1/settings/output/comA/messages[/NAME];
//      POST /api/v1/settings/output/comA/messages/NAME with a rate string
//      ("100ms", "disabled", "newData"; {"needReboot":false}); POST
//      /api/v1/settings with a JSON object (its output.comA.messages are
//      applied, other keys accepted and ignored); POST /api/v1/settings/save,
//      /api/v1/settings/default and /api/v1/system/reboot. Errors: 400 (bad
//      body), 404 (unknown path), 405 (method), with {"status", "title",
//      "detail"} as restApiHelperPrintErrorDetails reads them.
//  [A] Logs written to the device (class 0x00): AIR_DATA (36) and MAG (4),
//      as ArduPilot and PX4 send them, are taken as aiding input (counted,
//      kept for the status), never answered.
//
// Threads: as vectornav::Device. on_input() runs on the transport's io
// thread; the encoder reads what to stream through a wait-free triple buffer
// and hands back its latest measurements the same way.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/mip_device.hpp"  // mip::TripleBuffer
#include "drivers/protocols/responder_status.hpp"
#include "drivers/protocols/sbg.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::sbg {

// The model's preset product code when the config leaves it empty.
std::string product_code_of(const SbgDeviceConfig& config);
// [I] the identity's encoded versions and their text.
inline constexpr std::uint32_t kFirmwareRevision = (1u << 31) | (4u << 28) | (3u << 22) | (2u << 16) | 2406u;  // 3.2.2406-stable
inline constexpr std::uint32_t kHardwareRevision = (3u << 24) | (1u << 16);   // 3.1.0.0
inline constexpr std::uint32_t kCalibrationRevision = (1u << 24) | (2u << 16);  // 1.2.0.0
inline constexpr const char* kFirmwareText = "3.2.2406-stable";
inline constexpr const char* kHardwareText = "3.1.0.0";
inline constexpr const char* kCalibrationText = "1.2.0.0";
inline constexpr const char* kBootloaderText = "2.1.120-stable";

// The last aiding logs written to the device ([A]).
struct AidingInputs {
  std::uint64_t air_data_frames = 0;
  std::uint64_t mag_frames = 0;
  std::uint16_t air_data_status = 0;
  float pressure_abs_pa = 0, altitude_m = 0, pressure_diff_pa = 0, true_airspeed_m_s = 0, air_temperature_c = 0;
  float mag[3]{};
};

class Device final : public CommandResponder {
 public:
  explicit Device(const SbgDeviceConfig& config);

  // --- io thread ---
  void on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) override;
  // --- any thread but the emission thread ---
  CommandCounters command_counters() const override;
  void set_log(std::function<void(std::string_view)> log) override;
  AidingInputs aiding_inputs() const;
  // --- emission thread ---
  const EmitConfig& emit_config() noexcept { return published_.read(); }
  void note_restart() noexcept { restarts_.fetch_add(1, std::memory_order_release); }
  void publish_measurements(const Measurements& m) noexcept { latest_.publish(m); }

 private:
  struct Settings {
    std::array<StreamConfig, 2> ports{};  // A, C
    bool operator==(const Settings&) const = default;
  };
  void frame(std::uint8_t msg, std::uint8_t cls, std::span<const std::uint8_t> payload, ReplySink& replies);
  void command(std::uint8_t msg, std::span<const std::uint8_t> payload, ReplySink& replies);
  void aiding_input(std::uint8_t msg, std::span<const std::uint8_t> payload);
  void send(std::uint8_t msg, std::span<const std::uint8_t> payload, ReplySink& replies);
  void ack(std::uint8_t msg, ErrorCode code, ReplySink& replies);
  // [R] the status code and JSON body of a request.
  std::pair<std::uint16_t, std::string> rest(bool post, std::string_view path, std::string_view body);
  std::pair<std::uint16_t, std::string> rest_messages(bool post, int port, std::string_view rest_of_path,
                                                      std::string_view body);
  void reboot();
  void publish();
  void take_restarts();
  std::string format_text() const;
  void log(const std::string& line) const { status_.log(line); }

  SbgDeviceConfig config_;
  std::string product_code_;
  Settings current_, saved_, defaults_;
  std::vector<std::uint8_t> pending_;  // input bytes not framed yet (io thread)
  mip::TripleBuffer<EmitConfig> published_;
  mutable mip::TripleBuffer<Measurements> latest_;
  mutable std::mutex aiding_mutex_;
  AidingInputs aiding_;

  std::atomic<std::uint64_t> restarts_{0};
  std::uint64_t restarts_handled_ = 0;
  ResponderStatus status_{"sbg: "};
};

}  // namespace imuemu::drivers::sbg
