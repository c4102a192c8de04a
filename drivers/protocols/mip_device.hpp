// The MIP device's command side (issue 27): what a 3DM-CV7 / 3DM-GX5 answers
// when its driver talks to it, written from the MIP DCP manuals (no SDK code):
//
//  [P] 3DM-GX5-35 DCP manual 6 "MIP Packet Reference": a packet is 0x75 0x65,
//      descriptor set, payload length, fields (length incl. itself and the
//      descriptor, descriptor, data), Fletcher-16 checksum (6.3, 6.4). A reply
//      is one packet in the command's descriptor set: per command field an
//      ACK/NACK field 0xF1 (echoed command descriptor, error code: 0x00 ACK,
//      0x01 unknown command, 0x02 invalid checksum, 0x03 invalid parameter,
//      0x04 command failed, 0x05 command timeout), followed by the reply
//      data field when the command returns data.
//  [B] Base command set 0x01: Ping 0x01, Set To Idle 0x02, Get Device
//      Information 0x03 (-> 0x81: u16 firmware version, then model name,
//      model number, serial number, lot number, device options, 16 chars
//      each), Get Device Descriptors 0x04 (-> 0x82: u16 descriptors, set in
//      the high byte), Built-In Test 0x05 (-> 0x83: u32 result, 0 = pass),
//      Resume 0x06, Get Extended Descriptors 0x07 (-> 0x86), Comm Port Speed
//      0x09 (function, port, u32 baud; read -> 0x89: port, baud) [3DM-CV7 DCP].
//  [T] 3DM command set 0x0C: Get IMU Base Rate 0x06 (-> 0x83 u16 Hz), IMU
//      Message Format 0x08 (function, count, count x (descriptor, u16
//      decimation); read -> 0x80), Filter Message Format 0x0A (-> 0x82),
//      Get Filter Base Rate 0x0B (-> 0x8A), Get Base Rate 0x0E (descriptor set
//      -> 0x8E: set, u16 Hz), Message Format 0x0F (function, set, count,
//      list; read -> 0x8F: set, count, list), Datastream Control 0x11
//      (function, set (0: all), u8 enable; read -> 0x85: set, enabled), Device
//      Settings 0x30 (function 3 save, 4 load saved, 5 load default), UART
//      Baudrate 0x40 (function, u32 baud; read -> 0x87). Function selectors:
//      1 use new, 2 read, 3 save as startup, 4 load saved, 5 load default.
//  [F] Filter command set 0x0D: Reset Filter 0x01.
//  [N] With a GNSS receiver (issue 28, mip_nav.hpp): Get GNSS Base Rate
//      0x0C,0x07 (-> 0x84 u16 Hz), GNSS Message Format 0x0C,0x09 (-> 0x81),
//      and set 0x81 in Get Base Rate, Message Format and Datastream Control.
//
// Threads: on_input() runs on the transport's io thread (parsing, replies,
// settings); the encoder reads what it must stream (EmitConfig) on the
// emission thread through a wait-free triple buffer: no lock, no wait, no
// allocation there.
#pragma once

#include <array>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <mutex>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/responder_status.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::mip {

inline constexpr std::uint8_t kBaseCommandSet = 0x01;
inline constexpr std::uint8_t k3dmCommandSet = 0x0C;
inline constexpr std::uint8_t kFilterCommandSet = 0x0D;
inline constexpr std::uint8_t kFilterDataSet = 0x82;
inline constexpr std::uint8_t kGnssSet = 0x81;  // = mip_nav.hpp kGnssDataSet
inline constexpr std::uint8_t kAckNackField = 0xF1;

// [P] ACK/NACK error codes.
enum class AckCode : std::uint8_t {
  ok = 0x00,
  unknown_command = 0x01,
  invalid_checksum = 0x02,
  invalid_parameter = 0x03,
  command_failed = 0x04,
  command_timeout = 0x05,
};

// A data field and its decimation from the base rate.
struct FieldRate {
  std::uint8_t descriptor = 0;
  std::uint16_t decimation = 1;
  bool operator==(const FieldRate&) const = default;
};
inline constexpr std::size_t kMaxFormatFields = 8;

// The GNSS (0x81) or filter (0x82) stream as the encoder sends it.
struct SetFormat {
  bool send = false;  // streaming, the set's stream enabled and a field in its format
  std::uint8_t count = 0;
  std::array<FieldRate, kMaxFormatFields> fields{};
};

// One 0x80 stream as the encoder sends it, and the 0x81 / 0x82 ones.
struct StreamConfig {
  bool send = true;             // streaming (not idle) and the 0x80 stream enabled
  bool scene_format = true;     // the power-up format: the encoder's own field list at decimation 1
  std::uint8_t count = 0;       // otherwise these fields, in this order
  std::array<FieldRate, kMaxFormatFields> fields{};
  SetFormat gnss, filter;
};

// The 0x81 / 0x82 fields a device can send and its power-up formats (issue
// 28, mip_nav.hpp); all empty: a device without GNSS receiver and filter
// output, which lists, accepts and answers exactly as before.
struct NavFields {
  std::vector<std::uint8_t> gnss, filter;
  std::vector<FieldRate> gnss_power_up, filter_power_up;
};

// What the emission thread streams (set 0x80), as the io thread published it.
struct EmitConfig : StreamConfig {
  // What the device streams after a power cycle (its saved startup settings
  // and power-up mode): the emission thread uses it alone after a restart
  // fault until the io thread has taken the restart in (restarts_handled).
  StreamConfig startup;
  std::uint64_t restarts_handled = 0;
};

// Wait-free single-producer / single-consumer hand-over of the newest value
// (triple buffering): publish() never waits for the reader, read() never for
// the writer, and a value is never torn.
template <class T>
class TripleBuffer {
 public:
  explicit TripleBuffer(const T& initial) : slots_{initial, initial, initial} {}
  // Producer thread only.
  void publish(const T& value) {
    slots_[back_] = value;
    back_ = middle_.exchange(static_cast<std::uint8_t>(back_ | kFresh), std::memory_order_acq_rel) & kIndex;
  }
  // Consumer thread only.
  const T& read() noexcept {
    if ((middle_.load(std::memory_order_relaxed) & kFresh) != 0)
      front_ = middle_.exchange(front_, std::memory_order_acq_rel) & kIndex;
    return slots_[front_];
  }

 private:
  static constexpr std::uint8_t kFresh = 0x4;
  static constexpr std::uint8_t kIndex = 0x3;
  std::array<T, 3> slots_;
  std::atomic<std::uint8_t> middle_{1};
  std::uint8_t front_ = 0;  // consumer's
  std::uint8_t back_ = 2;   // producer's
};

// MIP framing of the bytes a driver writes [P 6.3, 6.4]: finds 0x75 0x65,
// waits for the whole packet (commands split across reads), checks the
// Fletcher checksum; a bad candidate costs one byte and the scan goes on
// (resync on garbage). A partial candidate older than kStaleAfter when more
// bytes arrive is given up the same way (a stray 0x75 0x65 with a large
// length byte would otherwise hold real commands behind it).
class CommandParser {
 public:
  static constexpr std::chrono::milliseconds kStaleAfter{100};
  // on_packet(descriptor_set, payload) per valid packet.
  void feed(std::span<const std::uint8_t> bytes, std::chrono::steady_clock::time_point now,
            const std::function<void(std::uint8_t, std::span<const std::uint8_t>)>& on_packet);
  std::uint64_t packets() const noexcept { return packets_; }
  std::uint64_t not_command_bytes() const noexcept { return not_command_bytes_; }
  // Counts payload bytes of a packet whose fields did not tile it.
  void count_not_command(std::size_t bytes) noexcept { not_command_bytes_ += bytes; }

 private:
  std::vector<std::uint8_t> buffer_;
  std::chrono::steady_clock::time_point candidate_since_{};
  std::uint64_t packets_ = 0;
  std::uint64_t not_command_bytes_ = 0;
};

// One MIP packet built field by field (replies; tests' commands).
std::vector<std::uint8_t> make_packet(std::uint8_t descriptor_set,
                                      std::span<const std::vector<std::uint8_t>> fields);

// The emulated device's command side and settings.
class Device final : public CommandResponder {
 public:
  // sensor_fields: the 0x80 fields the encoder can send, in its order (the
  // power-up format at decimation 1); base_rate_hz: the scene's rate.
  // nav: the GNSS and filter fields (none: the device of issue 27).
  Device(const MipDeviceConfig& config, std::vector<std::uint8_t> sensor_fields, std::uint16_t base_rate_hz,
         NavFields nav = {});

  // --- io thread ---
  void on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) override;
  // --- any thread but the emission thread ---
  CommandCounters command_counters() const override;
  void set_log(std::function<void(std::string_view)> log) override;
  // --- emission thread ---
  const EmitConfig& emit_config() noexcept { return published_.read(); }
  // A restart fault (the device powered up again): counted without a wait;
  // the io thread resets the settings to the startup ones at its next turn.
  void note_restart() noexcept { restarts_.fetch_add(1, std::memory_order_release); }

  // The descriptors Get Device Descriptors reports (set << 8 | field).
  const std::vector<std::uint16_t>& descriptors() const noexcept { return descriptors_; }
  std::uint16_t base_rate_hz() const noexcept { return base_rate_hz_; }

 private:
  struct Settings {
    std::vector<FieldRate> sensor_format;  // set 0x80
    std::vector<FieldRate> filter_format;  // set 0x82
    std::vector<FieldRate> gnss_format;    // set 0x81
    bool sensor_stream = true;             // Datastream Control
    bool filter_stream = true;
    bool gnss_stream = true;
    std::uint32_t baud = 115200;
  };
  // One command field: appends the reply fields (ACK/NACK first) to `out`.
  void handle(std::uint8_t set, std::uint8_t descriptor, std::span<const std::uint8_t> data,
              std::vector<std::vector<std::uint8_t>>& out, ReplySink& replies);
  AckCode base_command(std::uint8_t descriptor, std::span<const std::uint8_t> data,
                       std::vector<std::vector<std::uint8_t>>& out, ReplySink& replies);
  AckCode three_dm_command(std::uint8_t descriptor, std::span<const std::uint8_t> data,
                           std::vector<std::vector<std::uint8_t>>& out, ReplySink& replies);
  AckCode filter_command(std::uint8_t descriptor, std::span<const std::uint8_t> data);
  // Message format commands (0x08, 0x0A, 0x0F) for one descriptor set.
  AckCode message_format(std::uint8_t set, std::uint8_t function, std::span<const std::uint8_t> list,
                         std::uint8_t reply_descriptor, bool reply_has_set,
                         std::vector<std::vector<std::uint8_t>>& out);
  // Baud changes (Comm Port Speed, UART Baudrate, Device Settings).
  AckCode baud_setting(std::uint8_t function, std::uint32_t baud, ReplySink& replies);
  void apply_baud(std::uint32_t baud, ReplySink& replies);
  void publish();
  // A restart the emission thread noted: settings back to the saved startup
  // ones, mode to the power-up mode (io thread, before any command).
  void take_restarts();
  void log(const std::string& line) const { status_.log(line); }
  std::string format_text() const;
  bool has_gnss() const noexcept { return !nav_.gnss.empty(); }
  // The data sets the Get Base Rate / Message Format / Datastream Control
  // commands take: 0x80, 0x82, and 0x81 with a GNSS receiver.
  bool known_set(std::uint8_t set) const noexcept {
    return set == 0x80 || set == kFilterDataSet || (set == kGnssSet && has_gnss());
  }

  MipDeviceConfig config_;
  std::vector<std::uint8_t> sensor_fields_;
  std::uint16_t base_rate_hz_;
  NavFields nav_;
  std::vector<std::uint16_t> descriptors_;
  CommandParser parser_;
  Settings current_, saved_, defaults_;
  bool streaming_ = true;
  TripleBuffer<EmitConfig> published_;

  std::atomic<std::uint64_t> restarts_{0};
  std::uint64_t restarts_handled_ = 0;
  ResponderStatus status_{"mip device: "};
};

}  // namespace imuemu::drivers::mip
