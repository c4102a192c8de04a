// The Xsens MTi device's command side (issue 29): what an MTi answers on its
// serial port, written from [L] (xsens.hpp) chapters "Message overview" and
// "Messages" (no Xsens code):
//
//  [S] States: after power-up the device sends WakeUp (0x3E) and, unless
//      the host answers WakeUpAck (0x3F: config state), measures. Config
//      state: nothing is streamed; measurement state: MTData2 (0x36) as the
//      output configuration sets it. GotoConfig (0x30) / GotoMeasurement
//      (0x10) switch them (acknowledged with MID + 1).
//  [C] Requests answered in both states: ReqDID (0x00 -> DeviceID, 4 bytes,
//      8 for the MTi-600 series' 64-bit ids), ReqProductCode (0x1C -> 20 ASCII characters, space-padded),
//      InitBus (0x02 -> InitBusResults, the device id),
//      ReqHardwareVersion (0x1E -> major, minor), ReqFWRev (0x12 -> major,
//      minor, revision, build number u32, svn revision u32), Reset (0x40 ->
//      ResetAck, then WakeUp and measurement with the kept settings),
//      SetNoRotation (0x22, seconds u16 -> ack), ReqData (0x34 -> the last
//      MTData2), GotoConfig, GotoMeasurement.
//      Config state only (in measurement state: Error 0x04): ReqBaudrate /
//      SetBaudrate (0x18, one byte baud code; the new rate after the next
//      Reset), ReqOutputConfiguration / SetOutputConfiguration (0xC0: (data
//      id u16, rate u16) pairs; the acknowledgement 0xC1 lists what was
//      applied), ReqAlignmentRotation / SetAlignmentRotation (0xEC:
//      parameter 0 RotSensor / 1 RotLocal, quaternion w x y z float32),
//      RestoreFactoryDef (0x0E), ReqConfiguration (0x0C -> the 118-byte
//      legacy configuration), ReqOptionFlags (0x48), ReqLocationId (0x84),
//      ReqFilterProfile (0x64), ReqAvailableFilterProfiles (0x62),
//      ReqGnssPlatform (0x76), ReqGnssLeverArm (0x68), Req/SetStringOutputType
//      (0x8E: 0, no NMEA output), ReqEmts (0x90, not in [L]: xspublic's
//      readEmtsAndDeviceConfiguration; EmtsData 0x91 without pages).
//      Anything else, and a request whose data do not parse: Error (0x42)
//      with the code of [L] "Error codes"; a refused command changes nothing.
//  Settings are kept as the device keeps them (non-volatile: a Reset or a
//  power cycle keeps the output configuration, alignment and baud rate).
//
// Threads: as vectornav::Device.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/mip_device.hpp"  // mip::TripleBuffer
#include "drivers/protocols/responder_status.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/protocols/xsens.hpp"

namespace imuemu::drivers::xsens {

// The model's preset identity when the config leaves it empty / 0.
struct Identity {
  std::uint64_t device_id = 0;
  bool device_id_64bit = false;  // DeviceID sent as 8 bytes
  std::string product_code;
  std::uint8_t hardware_major = 0, hardware_minor = 0;
  std::uint8_t firmware_major = 0, firmware_minor = 0, firmware_revision = 0;
  std::uint32_t firmware_build = 0, firmware_svn = 0;
};
Identity identity_of(const XsensDeviceConfig& config);

// [L] SetBaudrate's baud codes; 0: not a code the device takes.
std::uint32_t baud_of_code(std::uint8_t code) noexcept;
std::optional<std::uint8_t> code_of_baud(std::uint32_t baud) noexcept;

class Device final : public CommandResponder {
 public:
  Device(const XsensDeviceConfig& config, const ModelTraits& traits);

  // --- io thread ---
  void on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) override;
  // --- any thread but the emission thread ---
  CommandCounters command_counters() const override;
  void set_log(std::function<void(std::string_view)> log) override;
  // --- emission thread ---
  const EmitConfig& emit_config() noexcept { return published_.read(); }
  void note_restart() noexcept { restarts_.fetch_add(1, std::memory_order_release); }
  void publish_measurements(const Measurements& m) noexcept { latest_.publish(m); }

 private:
  struct Settings {
    OutputConfiguration output;
    std::array<double, 4> rot_sensor_wxyz{1, 0, 0, 0};
    std::array<double, 4> rot_local_wxyz{1, 0, 0, 0};
    std::uint8_t baud_code = 0x02;
  };
  struct Outcome {
    std::uint8_t reply_mid = 0;
    std::vector<std::uint8_t> data;
    std::optional<ErrorCode> error;
    bool no_reply = false;             // WakeUpAck
    bool then_wake_up = false;         // Reset: WakeUp after the ack
    std::optional<std::uint32_t> baud_after;
  };
  void frame(std::uint8_t message_id, std::span<const std::uint8_t> data, ReplySink& replies);
  Outcome command(std::uint8_t message_id, std::span<const std::uint8_t> data);
  void publish();
  void take_restarts();
  void log(const std::string& line) const { status_.log(line); }
  std::string format_text() const;
  std::vector<std::uint8_t> output_configuration_data(const OutputConfiguration& c) const;

  XsensDeviceConfig config_;
  ModelTraits traits_;
  Identity identity_;
  Settings current_, defaults_;
  bool measurement_ = true;
  std::uint32_t line_baud_;       // the rate the port runs at now
  std::vector<std::uint8_t> pending_;  // bytes of a message not complete yet (io thread)
  mip::TripleBuffer<EmitConfig> published_;
  mutable mip::TripleBuffer<Measurements> latest_;
  bool have_measurements_ = false;

  std::atomic<std::uint64_t> restarts_{0};
  std::uint64_t restarts_handled_ = 0;
  ResponderStatus status_{"xsens: "};
};

}  // namespace imuemu::drivers::xsens
