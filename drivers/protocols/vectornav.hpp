// VectorNav VN-100 / VN-200 / VN-300 over a byte stream (issue 29): the
// binary output packets and the asynchronous ASCII outputs the device streams,
// and the decoder `imuemu listen` runs. The command side (registers, $VN...
// commands) is drivers/protocols/vectornav_device.hpp; docs/vectornav-device.md
// says what is answered and how.
//
// Sources (read, nothing copied):
//  [U] VN-100 / VN-200 / VN-300 user manuals, "Binary Output Protocol" and
//      "Serial ASCII" chapters: a binary packet is the sync byte 0xFA, the
//      group byte (bit 0 Common, 1 Time, 2 IMU, 3 GNSS1, 4 Attitude, 5 INS,
//      6 GNSS2), one 16-bit field mask per group present (little-endian, in
//      group order), the fields of each group in bit order (little-endian
//      IEEE-754 floats / doubles, unsigned integers), then a CRC-16 (CCITT,
//      polynomial 0x1021, initial value 0) over everything after the sync
//      byte, sent most significant byte first so that the CRC over the packet
//      with its CRC is 0. Rates: the output rate is the IMU rate (800 Hz for
//      the VN-100 and VN-200, 400 Hz for the VN-300) over the rate divisor.
//  [S] VectorNav SDK v0.99 (dotysan/vectornav-sdk add7bddaf6bcd773ad4acd497fd7df31263e7865),
//      cpp/include/vectornav/Implementation/BinaryMeasurementDefinitions.hpp:
//      the size of every field and the Common group's composition (Imu =
//      UncompAccel then UncompGyro; MagPres = Mag, Temperature, Pressure;
//      Deltas = DeltaTheta (dtime + 3) then DeltaVel), which the manual's
//      tables also give.
//
// Units and axes ([U] "Sensor coordinate system"): the sensor frame is x
// forward, y right, z down when the unit sits on its base, so the emulated
// device mounted that way has body FRD = sensor axes. Acceleration m/s^2
// (specific force: level at rest z = -9.8), angular rate rad/s, magnetic
// field gauss, temperature degC, pressure kPa, yaw/pitch/roll and delta
// theta in degrees, quaternion (x, y, z, w) of the sensor-to-NED rotation
// (scalar last, w >= 0), position latitude/longitude deg and height above
// the ellipsoid m, velocity NED m/s, times in ns.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/device_encoder_base.hpp"
#include "drivers/protocols/frame_resync.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::vectornav {

inline constexpr std::uint8_t kSync = 0xFA;
inline constexpr int kGroupCount = 7;  // Common .. GNSS2 (no extension groups)
enum Group : int { kCommon = 0, kTime = 1, kImu = 2, kGnss1 = 3, kAttitude = 4, kIns = 5, kGnss2 = 6 };
inline constexpr std::size_t kCrcBytes = 2;

// [U] the error codes of $VNERR,XX (two hex digits).
enum class ErrorCode : std::uint8_t {
  hard_fault = 0x01,
  serial_buffer_overflow = 0x02,
  invalid_checksum = 0x03,
  invalid_command = 0x04,
  not_enough_parameters = 0x05,
  too_many_parameters = 0x06,
  invalid_parameter = 0x07,
  invalid_register = 0x08,
  unauthorized_access = 0x09,
  watchdog_reset = 0x0A,
  output_buffer_overflow = 0x0B,
  insufficient_baud_rate = 0x0C,
};

// CRC-16/CCITT as [U] defines it (poly 0x1021, init 0, no reflection).
std::uint16_t crc16(std::span<const std::uint8_t> bytes) noexcept;
// [U] 8-bit checksum of an ASCII message: XOR of the bytes between $ and *.
std::uint8_t checksum8(std::string_view body) noexcept;

// What a model has: its IMU rate (the rate divisors' base) and the binary
// groups its firmware sends (VN-100: no GNSS or INS groups; VN-300: both
// receivers).
struct ModelTraits {
  std::uint16_t imu_rate_hz = 800;
  std::uint8_t groups = 0;  // bit per Group
  bool ins = false;
};
ModelTraits traits_of(VectorNavModel model) noexcept;

// The bytes of field `bit` of group `group` ([U], [S]); 0: a field this
// device does not send (reserved, extension, or variable-length: SatInfo,
// RawMeas).
std::size_t field_bytes(int group, int bit) noexcept;

// One binary output register (75, 76, 77).
struct BinaryOutput {
  std::uint8_t async_mode = 0;     // 0 off, 1 serial port 1, 2 port 2, 3 both
  std::uint16_t rate_divisor = 0;  // of the IMU rate
  std::uint8_t groups = 0;         // the group byte
  std::array<std::uint16_t, kGroupCount> fields{};  // per group, 0 when the group is off
  bool operator==(const BinaryOutput&) const = default;
};
// The payload bytes of a packet of this configuration (fields only).
std::size_t payload_bytes(const BinaryOutput& o) noexcept;
// The whole packet: sync, group byte, masks, payload, CRC.
std::size_t packet_bytes(const BinaryOutput& o) noexcept;

// The asynchronous ASCII outputs implemented ([U] register 6 values).
inline constexpr std::uint8_t kAdorOff = 0, kAdorYpr = 1, kAdorQtn = 2, kAdorQmr = 8, kAdorMag = 10,
                              kAdorAcc = 11, kAdorGyr = 12, kAdorMar = 13, kAdorYmr = 14, kAdorImu = 19,
                              kAdorIns = 22, kAdorDtv = 30;
// The register 6 value's sentence header ("YMR"), nullptr when not implemented.
const char* ador_header(std::uint8_t ador) noexcept;
// [U] register 7: the asynchronous output frequencies (Hz).
inline constexpr std::array<std::uint16_t, 11> kAdofRates{1, 2, 4, 5, 10, 20, 25, 40, 50, 100, 200};

// What the emission thread streams on the emulated port.
struct StreamConfig {
  bool async_enabled = true;    // $VNASY,1 (power-up) / $VNASY,0
  std::uint8_t ador = kAdorYmr; // this port's register 6
  std::uint16_t adof_hz = 40;   // this port's register 7
  bool crc16_mode = false;      // register 30 serial checksum: CRC-16 ("*XXXX") instead of 8-bit
  std::array<BinaryOutput, 3> binary{};
  // [U] register 32, Synchronization Control: the SyncOut pin (the scene's
  // GPIO sync line) pulses on every (skip + 1)-th event of its mode.
  std::uint8_t sync_out_mode = 0;          // SyncOutMode: 0 none, 1 ItStart, 2 ImuReady, 3 Ins, 6 GpsPps
  bool sync_out_positive = false;          // SyncOutPolarity: 1 positive pulse, 0 negative
  std::uint16_t sync_out_skip = 0;         // SyncOutSkipFactor
  std::uint32_t sync_out_width_ns = 100'000'000;  // SyncOutPulseWidth
};
// SyncOutMode values ([U] register 32).
inline constexpr std::uint8_t kSyncOutNone = 0, kSyncOutItStart = 1, kSyncOutImuReady = 2, kSyncOutIns = 3,
                              kSyncOutGpsPps = 6;
struct EmitConfig : StreamConfig {
  // As mip::EmitConfig: what the device streams after a power cycle (its
  // saved settings), used alone after a restart fault until the io thread
  // has taken the restart in.
  StreamConfig startup;
  std::uint64_t restarts_handled = 0;
};

// One sample in the device's units and axes: every field any output can carry.
struct Measurements {
  std::uint64_t time_startup_ns = 0;
  std::uint64_t time_gps_ns = 0;  // 0: no GPS time (a VN-100, or none known)
  bool gps_time_valid = false;
  double ypr_deg[3]{};             // yaw, pitch, roll
  double quat_xyzw[4]{0, 0, 0, 1};
  double dcm[9]{1, 0, 0, 0, 1, 0, 0, 0, 1};  // [U] C_body<-NED = (R_s^n)^T, row-major
  double gyro_rad_s[3]{};
  double accel_m_s2[3]{};
  double mag_gauss[3]{};
  double temperature_c = 25.0;
  double pressure_kpa = 101.325;
  double dtime_s = 0.0;            // deltas over the output's interval
  double dtheta_deg[3]{};
  double dvel_m_s[3]{};
  bool has_navigation = false;
  double lla[3]{};                 // deg, deg, m
  double ecef_m[3]{};
  double vel_ned_m_s[3]{};
  double vel_ecef_m_s[3]{};
  double vel_body_m_s[3]{};
  double mag_ned_gauss[3]{};
  double mag_ecef_gauss[3]{};
  double accel_ned_m_s2[3]{};      // specific force in NED
  double accel_ecef_m_s2[3]{};
  double lin_accel_body_m_s2[3]{}; // gravity removed
  double lin_accel_ned_m_s2[3]{};
  double lin_accel_ecef_m_s2[3]{};
  double ypr_u_deg[3]{};
  double pos_u_m = 0.0, vel_u_m_s = 0.0;
  std::uint16_t ins_status = 0;
  std::uint16_t sens_sat = 0;      // IMU group SensSat bits
  // GNSS1 / GNSS2 (VN-200 / VN-300).
  std::uint8_t gnss_fix = 0;       // 0 none, 2 2D, 3 3D
  std::uint8_t gnss_sats = 0;
  std::uint64_t gnss_tow_ns = 0;
  std::uint16_t gnss_week = 0;
  std::int8_t utc[8]{};            // year-2000, month, day, hour, minute, second, ms (u16 LE)
  double gnss_pos_u_m[3]{};
  double gnss_vel_u_m_s = 0.0, gnss_time_u_s = 0.0;
  double gnss_dop[7]{};            // g, p, t, v, h, n, e
  std::uint8_t time_status = 0;
  std::int8_t leap_seconds = 18;
};

// Appends one binary packet of output `o` with `m`; returns the status bits
// of values clamped on the way (wire::to_wire_float: non-finite -> flagged).
void append_binary_packet(const BinaryOutput& o, const Measurements& m, std::vector<std::uint8_t>& out);
// One ASCII sentence "$VN<hdr>,<fields>*<checksum>\r\n" (for async outputs and
// register reads) into buf; returns its length (0: ador not implemented).
std::size_t format_ascii_output(std::uint8_t ador, const Measurements& m, bool crc16_mode, char* buf,
                                std::size_t capacity) noexcept;
// The fields only ("+006.380,+000.023,...") of an output, for register reads.
std::size_t format_ascii_fields(std::uint8_t ador, const Measurements& m, char* buf, std::size_t capacity) noexcept;
// "*XX\r\n" or "*XXXX\r\n" for the message body between $ and * (buf holds
// the whole message from '$'): appends at buf[len], returns the new length.
std::size_t finish_sentence(char* buf, std::size_t len, std::size_t capacity, bool crc16_mode) noexcept;

class Device;

class Encoder final : public DeviceEncoderBase<Device, StreamConfig, 4> {  // 3 binary outputs, ASCII
 public:
  explicit Encoder(const StreamEncoderOptions& options);
  Encoder(const Encoder& other) : Encoder(other.options_) {}
  Encoder& operator=(const Encoder& other);
  Encoder& operator=(Encoder&& other);
  ~Encoder() override;
  std::string name() const override { return "vectornav"; }
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  // Three binary outputs of every field and a sentence on every sample (the
  // emission buffers' size).
  std::size_t max_bytes_per_sample() const override;
  // The outputs on at this port now (docs/vectornav-device.md "Link budget").
  double configured_bytes_per_second(double sample_rate_hz) const override;
  // The SyncOut pin as register 32 sets it, for the sample encode() took
  // last; nothing while SyncOutMode is none (the scene's [imu.sync] applies).
  std::optional<DeviceSyncPulse> device_sync_pulse() const noexcept override { return sync_pulse_; }
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;

  // The quantities of one sample as the device reports them (tests; the
  // encoder's own deltas are the sample's increments).
  Measurements measurements_of(const ImuFrameInput& sample) const;
  const ModelTraits& traits() const noexcept { return traits_; }
  // The power-up streams (a device without command side keeps them).
  static StreamConfig power_up_config(const VectorNavDeviceConfig& config);

 private:
  ModelTraits traits_;
  std::optional<DeviceSyncPulse> sync_pulse_;
  std::int64_t last_gps_second_ = -1;  // GpsPps: the GPS second of the last sample
  // The SyncOut decision for sample k (register 32 in `c`).
  std::optional<DeviceSyncPulse> sync_out_for(const StreamConfig& c, std::uint64_t k, const Measurements& m) noexcept;
};

// Binary packets and ASCII sentences from a byte stream (`imuemu listen`):
// binary packets of any configuration decode their IMU fields (Common or IMU
// group: angular rate, acceleration, delta theta / velocity, TimeStartup);
// ASCII sentences are checked and counted as frames.
class Decoder final : public ResyncingDecoder {
 private:
  std::size_t decode_buffer(const SampleCallback& on_sample) override;
};

}  // namespace imuemu::drivers::vectornav
