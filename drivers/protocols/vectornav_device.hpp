// The VectorNav device's command side (issue 29): what a VN-100 / VN-200 /
// VN-300 answers on its serial port, written from the user manuals' "Serial
// ASCII" and "System / configuration registers" chapters (no SDK code):
//
//  [A] A command is "$VN" + a three-letter name, comma-separated parameters,
//      "*" and a checksum, then CR LF: two hex digits (XOR of the bytes
//      between $ and *), four hex digits (CRC-16/CCITT over the same bytes),
//      or "XX" (checksum not checked). The reply repeats the command's name
//      and register id with the register's contents; an error is
//      "$VNERR,XX" with the code in hex (vectornav.hpp ErrorCode). Replies
//      and async ASCII outputs carry the checksum register 30 selects
//      (8-bit by default, CRC-16).
//  [C] Commands: RRG (read register), WRG (write register), ASY (pause /
//      resume every async output: 0 / 1), WNV (save settings), RFS (restore
//      factory settings), RST (reset: back to the saved settings), BOM
//      (poll one binary output: the packet is the reply).
//  [R] Registers: 0 user tag (20 chars), 1 model number, 2 hardware
//      revision, 3 serial number, 4 firmware version (1-4 read only), 5
//      serial baud rate [, port] (the new rate after the reply), 6 async data
//      output type [, port], 7 async output frequency [, port], 8 yaw pitch
//      roll, 9 quaternion, 17 magnetic, 18 acceleration, 19 angular rate, 27
//      YMR (8.. read only), 30 communication protocol control (7 fields: the
//      serial checksum (1 8-bit, 2 CRC-16) and the error mode act; the
//      count / status appends must be 0), 32 synchronisation control (9
//      fields, kept and read back: the sync lines are not emulated), 35 VPE
//      basic control (4 fields, kept), 75 / 76 / 77 binary outputs 1-3
//      (async mode, rate divisor, group byte, one field mask per group, hex).
//
// Threads: as mip::Device. on_input() runs on the transport's io thread;
// the encoder reads what to stream through a wait-free triple buffer and
// hands back its latest measurements (register 8 reads, BOM) the same way.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/mip_device.hpp"  // mip::TripleBuffer
#include "drivers/protocols/responder_status.hpp"
#include "drivers/protocols/stream_protocols.hpp"
#include "drivers/protocols/vectornav.hpp"

namespace imuemu::drivers::vectornav {

// The model's preset identity strings (registers 1 and 4) when the config leaves them empty.
std::string model_number_of(const VectorNavDeviceConfig& config);
std::string firmware_version_of(const VectorNavDeviceConfig& config);

// The first saved register write of config.saved_registers the device
// refuses (the write and its VNERR code); nothing when it takes them all.
std::optional<std::string> saved_registers_problem(const VectorNavDeviceConfig& config);

class Device final : public CommandResponder {
 public:
  // Throws std::invalid_argument naming the saved register write
  // (config.saved_registers) the device refuses, and its VNERR code.
  Device(const VectorNavDeviceConfig& config, const ModelTraits& traits);

  // --- io thread ---
  void on_input(std::span<const std::uint8_t> bytes, ReplySink& replies) override;
  // --- any thread but the emission thread ---
  CommandCounters command_counters() const override;
  void set_log(std::function<void(std::string_view)> log) override;
  // --- emission thread ---
  const EmitConfig& emit_config() noexcept { return published_.read(); }
  void note_restart() noexcept { restarts_.fetch_add(1, std::memory_order_release); }
  // The sample the device measured last (for register reads and BOM polls).
  void publish_measurements(const Measurements& m) noexcept { latest_.publish(m); }

 private:
  struct PortSettings {
    std::uint32_t baud = 115200;
    std::uint8_t ador = kAdorYmr;
    std::uint16_t adof_hz = 40;
  };
  struct Settings {
    std::string user_tag;
    std::array<PortSettings, 2> ports{};
    std::array<std::uint32_t, 7> protocol_control{0, 0, 0, 0, 1, 0, 1};
    std::array<std::uint32_t, 9> sync_control{3, 0, 0, 0, 0, 0, 0, 100000000, 0};
    std::array<std::uint32_t, 4> vpe_basic{1, 1, 1, 1};
    std::array<BinaryOutput, 3> binary{};
  };
  // One whole sentence (from '$' up to, not including, CR LF).
  void sentence(std::string_view text, ReplySink& replies);
  // A command's reply body (after "$", before "*"), or an error code.
  struct Outcome {
    std::string body;
    std::optional<ErrorCode> error;
    std::vector<std::uint8_t> binary;  // BOM: a binary packet instead of a sentence
    std::optional<std::uint32_t> baud_after;  // the port's new rate, after this reply
  };
  Outcome command(const std::vector<std::string_view>& tokens);
  Outcome read_register(const std::vector<std::string_view>& tokens);
  Outcome write_register(const std::vector<std::string_view>& tokens);
  // config_.saved_registers, each as $VNWRG then $VNWNV (constructor only).
  void apply_saved_registers();
  // The register's contents as the reply lists them ("14" / "14,1"); empty
  // optional: not a register this device has.
  std::optional<std::string> register_text(int id, std::optional<int> port) const;
  void reply_text(const std::string& body, ReplySink& replies);
  void publish();
  void take_restarts();
  void log(const std::string& line) const { status_.log(line); }
  std::string format_text() const;
  PortSettings& own_port() { return current_.ports[static_cast<std::size_t>(config_.port - 1)]; }
  const PortSettings& own_port() const { return current_.ports[static_cast<std::size_t>(config_.port - 1)]; }

  VectorNavDeviceConfig config_;
  ModelTraits traits_;
  std::string model_number_, firmware_;
  Settings current_, saved_, defaults_;
  bool async_enabled_ = true;
  std::string pending_;  // bytes of a sentence not complete yet (io thread)
  mip::TripleBuffer<EmitConfig> published_;
  mutable mip::TripleBuffer<Measurements> latest_;  // read by the io thread only

  std::atomic<std::uint64_t> restarts_{0};
  std::uint64_t restarts_handled_ = 0;
  ResponderStatus status_{"vectornav: "};
};

}  // namespace imuemu::drivers::vectornav
