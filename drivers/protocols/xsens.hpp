// Xsens MTi (MTi-3 / MTi-7 / MTi-630 / MTi-680G / MTi-G-710) over a byte
// stream (issue 29): the Xbus frames the device sends (MTData2, WakeUp), the
// wire formats of the data identifiers, and the decoder `imuemu listen` runs.
// The command side (GotoConfig, ReqDID, SetOutputConfiguration, ...) is
// drivers/protocols/xsens_device.hpp; docs/xsens-device.md says what is
// answered and how.
//
// Source (read, nothing copied): [L] Xsens "MT Low Level Communication
// Protocol Documentation" (document MT0101P):
//  [L 2.2] a message is the preamble 0xFA, the bus identifier (0xFF: the
//      master device), the message identifier (MID), the length of the data
//      (one byte; 0xFF: an extended length, two bytes big-endian follow),
//      the data, and a checksum chosen so that the sum of every byte after
//      the preamble, checksum included, is 0 modulo 256. All multi-byte
//      values are big-endian.
//  [L 5.2 MTData2] the data are a sequence of packets: data identifier
//      (uint16), size (uint8), data. The identifier's bits 15..4 name the
//      quantity (group and type), bits 3..2 the coordinate system (0 ENU,
//      1 NED, 2 NWU) and bits 1..0 the precision (0 float32, 1 fp12.20,
//      2 fp16.32, 3 float64) of the quantities that have them.
//      fp12.20: int32 = value * 2^20; fp16.32: the 48-bit value * 2^32 sent
//      as its 32-bit fraction then its 16-bit integer part.
//  [L 4.1.4 / 5.2] SampleTimeFine counts 10 kHz ticks since power-up;
//      PacketCounter is a wrapping uint16.
//
// Units and axes ([L] "MTi sensor frame"; docs/xsens-device.md): the sensor
// frame S is x forward, y left, z up (when the unit sits on its base), so
// with the emulated body FRD: x_S = x_B, y_S = -y_B, z_S = -z_B. The local
// frame L is ENU by default (x east, y north, z up; yaw 0 with x_S to the
// east, +90 deg to the north), NED or NWU when the identifier's coordinate
// bits ask. The alignment rotations ([L] SetAlignmentRotation) turn S into
// the object frame O (RotSensor, q_OS) and L into L' (RotLocal, q_L'L):
// sensor-frame data (acceleration, rate of turn, magnetic field, ΔQ, Δv)
// are given in O, orientation is q_L'O, free acceleration and velocity are
// in L'. Acceleration m/s^2 (specific force: at rest level +9.8 on z),
// rate of turn rad/s, ΔQ unitless, Δv m/s, magnetic field a.u. (1 = the
// reference field's magnitude), Euler angles deg (roll, pitch, yaw),
// latitude / longitude deg, altitude m above the WGS84 ellipsoid, velocity
// m/s, temperature degC, pressure Pa.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/device_encoder_base.hpp"
#include "drivers/protocols/frame_resync.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::xsens {

inline constexpr std::uint8_t kPreamble = 0xFA;
inline constexpr std::uint8_t kMasterBusId = 0xFF;
inline constexpr std::uint8_t kExtendedLength = 0xFF;
inline constexpr std::size_t kMaxPayloadBytes = 2048;  // [L 2.2] the longest data a device takes

// [L] message identifiers used here (a request's acknowledgement is MID + 1).
namespace mid {
inline constexpr std::uint8_t kReqDid = 0x00, kDeviceId = 0x01;
inline constexpr std::uint8_t kInitBus = 0x02, kInitBusResults = 0x03;
inline constexpr std::uint8_t kReqConfiguration = 0x0C, kConfiguration = 0x0D;
inline constexpr std::uint8_t kRestoreFactoryDef = 0x0E;
inline constexpr std::uint8_t kGotoMeasurement = 0x10;
inline constexpr std::uint8_t kReqFwRev = 0x12, kFirmwareRev = 0x13;
inline constexpr std::uint8_t kBaudrate = 0x18;          // Req (no data) / Set (one byte)
inline constexpr std::uint8_t kReqProductCode = 0x1C, kProductCode = 0x1D;
inline constexpr std::uint8_t kReqHardwareVersion = 0x1E, kHardwareVersion = 0x1F;
inline constexpr std::uint8_t kSetNoRotation = 0x22;
inline constexpr std::uint8_t kGotoConfig = 0x30;
inline constexpr std::uint8_t kReqData = 0x34;
inline constexpr std::uint8_t kMtData2 = 0x36;
inline constexpr std::uint8_t kWakeUp = 0x3E, kWakeUpAck = 0x3F;
inline constexpr std::uint8_t kReset = 0x40;
inline constexpr std::uint8_t kError = 0x42;
inline constexpr std::uint8_t kOptionFlags = 0x48;
inline constexpr std::uint8_t kAvailableFilterProfiles = 0x62;
inline constexpr std::uint8_t kFilterProfile = 0x64;
inline constexpr std::uint8_t kGnssLeverArm = 0x68;
inline constexpr std::uint8_t kGnssPlatform = 0x76;
inline constexpr std::uint8_t kLocationId = 0x84;
inline constexpr std::uint8_t kStringOutputType = 0x8E;  // Req (no data) / Set (u16)
inline constexpr std::uint8_t kOutputConfiguration = 0xC0;  // Req (no data) / Set (id, rate pairs)
inline constexpr std::uint8_t kAlignmentRotation = 0xEC;   // Req (parameter) / Set (parameter, q)
}  // namespace mid

// [L] "Error codes" of the Error message (MID 0x42).
enum class ErrorCode : std::uint8_t {
  invalid_period = 0x03,
  invalid_message = 0x04,
  timer_overflow = 0x1E,
  invalid_baudrate = 0x20,
  invalid_parameter = 0x21,
  device_error = 0x28,
};

// [L 5.2] data identifiers with the format bits cleared.
namespace xdi {
inline constexpr std::uint16_t kTemperature = 0x0810;
inline constexpr std::uint16_t kUtcTime = 0x1010;
inline constexpr std::uint16_t kPacketCounter = 0x1020;
inline constexpr std::uint16_t kSampleTimeFine = 0x1060;
inline constexpr std::uint16_t kQuaternion = 0x2010;
inline constexpr std::uint16_t kRotationMatrix = 0x2020;
inline constexpr std::uint16_t kEulerAngles = 0x2030;
inline constexpr std::uint16_t kBaroPressure = 0x3010;
inline constexpr std::uint16_t kDeltaV = 0x4010;
inline constexpr std::uint16_t kAcceleration = 0x4020;
inline constexpr std::uint16_t kFreeAcceleration = 0x4030;
inline constexpr std::uint16_t kAltitudeEllipsoid = 0x5020;
inline constexpr std::uint16_t kLatLon = 0x5040;
inline constexpr std::uint16_t kGnssPvtData = 0x7010;
inline constexpr std::uint16_t kRateOfTurn = 0x8020;
inline constexpr std::uint16_t kDeltaQ = 0x8030;
inline constexpr std::uint16_t kMagneticField = 0xC020;
inline constexpr std::uint16_t kVelocityXyz = 0xD010;
inline constexpr std::uint16_t kStatusWord = 0xE020;
inline constexpr std::uint16_t kPrecisionMask = 0x0003;  // 0 float32, 1 fp12.20, 2 fp16.32, 3 float64
inline constexpr std::uint16_t kCoordinateMask = 0x000C; // 0 ENU, 4 NED, 8 NWU
inline constexpr std::uint16_t kFormatMask = 0x000F;
// The rate meaning "with every packet / as fast as the device can" ([L] 0xFFFF).
inline constexpr std::uint16_t kEveryPacket = 0xFFFF;
}  // namespace xdi

// [L 5.2] StatusWord bits this device sets.
namespace status_bit {
inline constexpr std::uint32_t kSelfTest = 1u << 0;
inline constexpr std::uint32_t kFilterValid = 1u << 1;
inline constexpr std::uint32_t kGnssFix = 1u << 2;
inline constexpr std::uint32_t kClipAccX = 1u << 8;   // 8..10 accelerometer x, y, z
inline constexpr std::uint32_t kClipGyrX = 1u << 11;  // 11..13 gyroscope x, y, z
inline constexpr std::uint32_t kClipMagX = 1u << 14;  // 14..16 magnetometer x, y, z
inline constexpr std::uint32_t kClipping = 1u << 19;  // any clipping
}  // namespace status_bit

// [L 2.2] the checksum byte of everything after the preamble (without it).
std::uint8_t checksum(std::span<const std::uint8_t> after_preamble) noexcept;
// One whole message: preamble, bus id 0xFF, mid, (extended) length, data, checksum.
void append_message(std::uint8_t message_id, std::span<const std::uint8_t> data, std::vector<std::uint8_t>& out);
std::vector<std::uint8_t> message(std::uint8_t message_id, std::span<const std::uint8_t> data = {});

// What a model has ([L] per product: the outputs and rates it offers).
struct ModelTraits {
  std::uint16_t max_rate_hz = 400;  // the rate every output rate divides
  bool gnss = false;                // position, velocity, GNSS PVT, UTC from GNSS
  bool baro = false;                // barometric pressure
  bool orientation = true;          // a filter: quaternion, Euler angles, rotation matrix, free acceleration
};
ModelTraits traits_of(XsensModel model) noexcept;

// The wire size of the data of identifier `id` (format bits included); 0: an
// identifier (or format) this device does not send.
std::size_t data_bytes(std::uint16_t id) noexcept;
// Whether this model sends `id` (format bits ignored).
bool model_sends(const ModelTraits& traits, std::uint16_t id) noexcept;

// One entry of the output configuration: identifier (with format bits) and
// rate in Hz (0xFFFF: every packet).
struct OutputItem {
  std::uint16_t id = 0;
  std::uint16_t rate_hz = 0;
  bool operator==(const OutputItem&) const = default;
};
inline constexpr std::size_t kMaxOutputItems = 32;
struct OutputConfiguration {
  std::array<OutputItem, kMaxOutputItems> items{};
  std::size_t count = 0;
  bool operator==(const OutputConfiguration&) const = default;
};
// The configuration a device applies for the requested one ([L]
// SetOutputConfiguration: the acknowledgement lists what was applied):
// identifiers this model does not send are dropped, a rate becomes the
// largest rate at most the one asked that divides the model's maximum
// (at least max/65535... the lowest: 1 Hz), 0xFFFF stays "every packet"
// (PacketCounter and SampleTimeFine always go with every packet); nullopt:
// malformed (an identifier whose format bits are not valid, too many items).
std::optional<OutputConfiguration> apply_output_configuration(const ModelTraits& traits,
                                                              std::span<const OutputItem> requested);
// The model's power-up configuration.
OutputConfiguration default_output_configuration(const ModelTraits& traits);

// What the emission thread streams.
struct StreamConfig {
  bool measurement = true;  // false: config mode, nothing streamed
  OutputConfiguration output;
  std::array<double, 4> rot_sensor_wxyz{1, 0, 0, 0};  // q_OS
  std::array<double, 4> rot_local_wxyz{1, 0, 0, 0};   // q_L'L
};
struct EmitConfig : StreamConfig {
  // As vectornav::EmitConfig: after a power cycle the device streams its
  // saved settings in measurement mode until the io thread takes it in.
  std::uint64_t restarts_handled = 0;
};

// One sample in the device's units and axes, before the alignment and
// coordinate-frame choices: sensor frame S (FLU), local frame ENU.
struct Measurements {
  std::uint64_t since_power_up_ns = 0;
  double acc_s_m_s2[3]{};
  double gyr_s_rad_s[3]{};
  double mag_s_au[3]{};
  double free_acc_enu_m_s2[3]{};
  double r_enu_s[9]{1, 0, 0, 0, 1, 0, 0, 0, 1};  // R_{ENU<-S}, row-major
  double delta_q_wxyz[4]{1, 0, 0, 0};            // over the output's interval
  double delta_v_s_m_s[3]{};
  double temperature_c = 25.0;
  double pressure_pa = 101325.0;
  bool has_navigation = false;
  double latitude_deg = 0.0, longitude_deg = 0.0, altitude_m = 0.0;
  double vel_enu_m_s[3]{};
  std::uint32_t status_word = 0;
  // UTC ([L] UtcTime: flags bit 0 valid TOW, 1 valid WN, 2 valid UTC).
  std::uint32_t utc_ns = 0;
  std::uint16_t utc_year = 0;
  std::uint8_t utc_month = 0, utc_day = 0, utc_hour = 0, utc_minute = 0, utc_second = 0, utc_flags = 0;
  // GNSS PVT (u-blox NAV-PVT layout, [L] GnssPvtData).
  std::uint32_t gnss_itow_ms = 0;
  std::uint8_t gnss_fix_type = 0, gnss_num_sv = 0;
  double gnss_h_acc_m = 0.0, gnss_v_acc_m = 0.0, gnss_s_acc_m_s = 0.0, gnss_t_acc_ns = 0.0;
  double gnss_pdop = 0.0, gnss_hdop = 0.0, gnss_vdop = 0.0;
  double gnss_height_msl_m = 0.0;
  double gnss_vel_ned_m_s[3]{};
};

// Appends one MTData2 message carrying `items` (in the order given) with the
// packet counter `packet_counter`; returns the StatusWord clipping bits of
// values clamped on the way (fixed-point saturation, non-finite values).
// Never allocates when `out` has the room (Encoder::max_bytes_per_sample).
std::uint32_t append_mtdata2(std::span<const OutputItem> items, const StreamConfig& frames, const Measurements& m,
                             std::uint16_t packet_counter, std::vector<std::uint8_t>& out);
// The data bytes of one identifier's packet (after id and size).
void append_item_data(std::uint16_t id, const StreamConfig& frames, const Measurements& m, std::uint16_t packet_counter,
                      std::vector<std::uint8_t>& out, std::uint32_t& clipped);

class Device;

class Encoder final : public DeviceEncoderBase<Device, StreamConfig, 1> {  // one MTData2 stream
 public:
  explicit Encoder(const StreamEncoderOptions& options);
  Encoder(const Encoder& other) : Encoder(other.options_) {}
  Encoder& operator=(const Encoder& other);
  Encoder& operator=(Encoder&& other);
  ~Encoder() override;
  std::string name() const override { return "xsens"; }
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  // The widest MTData2 any configuration makes (the emission buffers' size).
  std::size_t max_bytes_per_sample() const override;
  // The MTData2 packets of the output configuration now
  // (docs/xsens-device.md "Link budget").
  double configured_bytes_per_second(double sample_rate_hz) const override;
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;
  bool has_sequence_counter() const override { return true; }
  void sequence_step(std::int64_t step) override { packet_counter_ = static_cast<std::uint16_t>(packet_counter_ + step); }
  void sequence_reset() override { packet_counter_ = 0; }
  // [L] power-up: the device sends WakeUp, then measures with its saved settings.
  void restart(TimeNs now_ns, std::vector<std::uint8_t>& out) override;

  Measurements measurements_of(const ImuFrameInput& sample) const;
  const ModelTraits& traits() const noexcept { return traits_; }
  static StreamConfig power_up_config(const XsensDeviceConfig& config);

 private:
  // What streams now; after_restart: the room for a configuration made here.
  const StreamConfig& streamed_config(StreamConfig& after_restart) const;
  static bool packet_due(std::uint64_t k, std::uint64_t scene_rate_hz, const OutputConfiguration& c,
                         std::span<OutputItem> due_items, std::size_t& n) noexcept;
  ModelTraits traits_;
  std::uint16_t packet_counter_ = 0;
  std::array<OutputItem, kMaxOutputItems> due_items_{};  // scratch, no allocation
};

// MTData2 and every other Xbus message from a byte stream (`imuemu listen`):
// MTData2 with RateOfTurn or Acceleration (any precision) is a sample, in the
// body FRD axes of an unrotated device (x, -y, -z of S); PacketCounter is its
// sequence, SampleTimeFine its time.
class Decoder final : public ResyncingDecoder {
 private:
  std::size_t decode_buffer(const SampleCallback& on_sample) override;
  bool have_counter_ = false;
  std::uint16_t last_counter_ = 0;
};

// Reads one value of a quantity of precision `precision` (0..3) at `p`.
double read_value(const std::uint8_t* p, unsigned precision) noexcept;

}  // namespace imuemu::drivers::xsens
