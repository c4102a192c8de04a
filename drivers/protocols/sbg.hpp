// SBG Systems sbgECom over a byte stream (issue 29): the binary logs an
// ELLIPSE-A / -N / -D sends, their framing, and the decoder `imuemu listen`
// runs. The command side (CMD_INFO, OUTPUT_CONF, SETTINGS_ACTION, the REST
// API) is drivers/protocols/sbg_device.hpp; docs/sbg-device.md says what is
// answered and how.
//
// Sources (read, nothing copied):
//  [F] SBG Systems, "ELLIPSE Firmware Reference Manual" / sbgECom binary
//      protocol: a frame is SYNC 0xFF 0x5A, message id (1 byte), class (1
//      byte), payload length (uint16 LE, at most 4086), payload, CRC-16
//      (uint16 LE) over id, class, length and payload, then ETX 0x33. The
//      CRC is the reflected CCITT polynomial (0x8408), initial value 0, no
//      final XOR. Classes: 0x00 LOG_ECOM_0 (logs), 0x01 LOG_ECOM_1
//      (FAST_IMU_DATA), 0x10 CMD_0 (commands). A class with bit 7 set is an
//      extended multi-page frame (never sent here; the decoder skips it).
//  [L] sbgECom 5.2.590 (SBG-Systems/sbgECom 05c19cdd7c021a8474b2bffc8ca4ec274f6a9155),
//      src/sbgEComIds.h (message ids), src/logs/*.c and *.h (payload field
//      order, widths, units and status bits), common/crc/sbgCrc.c (the CRC),
//      src/protocol/sbgEComProtocol.c (framing, CRC byte order): the field
//      layouts below follow the ...ReadFromStream functions.
//
// Units and axes ([F] "Sensor coordinate frame"): the device frame is X
// forward, Y right, Z down when the unit sits on its base: body FRD = device
// axes. Accelerations m/s^2 (specific force: level at rest Z = -9.8), angular
// rates rad/s, Euler angles (roll, pitch, yaw) and their sigmas rad,
// quaternion (w, x, y, z) of the body-to-NED rotation, position latitude /
// longitude deg and altitude above mean sea level m (with the undulation),
// velocities NED m/s, magnetic field in the device's arbitrary units (here
// gauss), temperatures degC, time stamps microseconds since power-up (uint32,
// wraps after 71.6 min).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "drivers/protocol.hpp"
#include "drivers/protocols/device_encoder_base.hpp"
#include "drivers/protocols/frame_resync.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers::sbg {

inline constexpr std::uint8_t kSync1 = 0xFF, kSync2 = 0x5A, kEtx = 0x33;
inline constexpr std::size_t kMaxPayloadBytes = 4086;   // [F] a standard frame's payload
inline constexpr std::size_t kFrameOverheadBytes = 9;   // sync 2, id, class, length 2, CRC 2, ETX

// [L] sbgEComIds.h classes.
inline constexpr std::uint8_t kClassLog0 = 0x00, kClassLog1 = 0x01, kClassCmd0 = 0x10;
// [L] SbgEComLog (class 0x00) ids this device sends or accepts.
inline constexpr std::uint8_t kLogStatus = 1, kLogUtcTime = 2, kLogImuData = 3, kLogMag = 4, kLogEkfEuler = 6,
                              kLogEkfQuat = 7, kLogEkfNav = 8, kLogGps1Vel = 13, kLogGps1Pos = 14, kLogAirData = 36,
                              kLogImuShort = 44;
inline constexpr std::uint8_t kLog1FastImu = 0;  // class 0x01
// [L] SbgEComCmd (class 0x10).
inline constexpr std::uint8_t kCmdAck = 0, kCmdSettingsAction = 1, kCmdInfo = 4, kCmdOutputConf = 30,
                              kCmdApiPost = 47, kCmdApiGet = 48;
// [L] common/sbgErrorCodes.h: the error code an ACK carries (uint16).
enum class ErrorCode : std::uint16_t {
  no_error = 0,
  error = 1,
  null_pointer = 2,
  invalid_crc = 3,
  invalid_frame = 4,
  time_out = 5,
  write_error = 6,
  read_error = 7,
  buffer_overflow = 8,
  invalid_parameter = 9,
  not_ready = 10,
  malloc_failed = 11,
  incompatible_hardware = 19,
};
// [L] sbgEComCmdOutput.h SbgEComOutputMode: 0 disabled, N = every N main-loop
// ticks (the ELLIPSE's main loop is 200 Hz: 1, 2, 4, 5, 8, 10, 20, 40, 100,
// 200), 1001/1002/1004 every 1/2/4 ms, 10000 PPS, 10001 on new data, 20001
// the 1 kHz IMU loop (FAST_IMU_DATA).
inline constexpr std::uint16_t kModeDisabled = 0, kMode1Ms = 1001, kMode2Ms = 1002, kMode4Ms = 1004,
                               kModePps = 10000, kModeNewData = 10001, kModeHighFreqLoop = 20001;
inline constexpr std::uint32_t kMainLoopHz = 200;
bool valid_output_mode(std::uint16_t mode) noexcept;
// [L] sbgEComCmdSettings.h SbgEComSettingsAction.
inline constexpr std::uint8_t kActionRebootOnly = 0, kActionSaveSettings = 1, kActionRestoreDefaults = 2;
// [L] sbgEComCmdOutput.h SbgEComOutputPort.
inline constexpr std::uint8_t kPortA = 0, kPortC = 2, kPortE = 4;

// [L] sbgEComLogImu.h IMU status bits, and the IMU_SHORT scale factors
// (sbgEComLogImu.c): velocity 1048576 LSB per m/s^2, angle 67108864 LSB per
// rad/s (standard) or 12304174 (high range, status bit 10, used when any
// axis exceeds INT32_MAX / 67108864 = 32 rad/s), temperature 256 LSB per degC.
inline constexpr std::uint16_t kImuComOk = 1u << 0, kImuStatusBit = 1u << 1, kImuAccelXyzBits = 0x7u << 2,
                               kImuGyroXyzBits = 0x7u << 5, kImuAccelsInRange = 1u << 8, kImuGyrosInRange = 1u << 9,
                               kImuGyrosUseHighScale = 1u << 10;
inline constexpr double kImuShortAccelScale = 1048576.0, kImuShortGyroScaleStd = 67108864.0,
                        kImuShortGyroScaleHigh = 12304174.0, kImuShortTempScale = 256.0;
// [L] sbgEComLogEkf.h solution status: mode in bits 0-3, then flags.
inline constexpr std::uint32_t kSolModeAhrs = 2, kSolModeNavPosition = 4, kSolAttitudeValid = 1u << 4,
                               kSolHeadingValid = 1u << 5, kSolVelocityValid = 1u << 6, kSolPositionValid = 1u << 7,
                               kSolVertRefUsed = 1u << 8, kSolMagRefUsed = 1u << 9, kSolGps1VelUsed = 1u << 10,
                               kSolGps1PosUsed = 1u << 11, kSolAlignValid = 1u << 27;
// [L] sbgEComLogAirData.h status bits.
inline constexpr std::uint16_t kAirTimeIsDelay = 1u << 0, kAirPressureAbsValid = 1u << 1, kAirAltitudeValid = 1u << 2,
                               kAirPressureDiffValid = 1u << 3, kAirAirspeedValid = 1u << 4,
                               kAirTemperatureValid = 1u << 5;

// CRC-16 of [F]/[L]: reflected polynomial 0x8408, initial value 0.
std::uint16_t crc16(std::span<const std::uint8_t> bytes) noexcept;
// Appends one whole frame (payload at most kMaxPayloadBytes).
void append_frame(std::uint8_t msg, std::uint8_t cls, std::span<const std::uint8_t> payload,
                  std::vector<std::uint8_t>& out);

// The logs this device sends: index into the output table.
enum Output : int {
  kOutStatus = 0,
  kOutUtcTime,
  kOutImuData,
  kOutImuShort,
  kOutFastImu,
  kOutMag,
  kOutEkfEuler,
  kOutEkfQuat,
  kOutEkfNav,
  kOutGps1Vel,
  kOutGps1Pos,
  kOutputCount
};
struct OutputInfo {
  std::uint8_t cls;
  std::uint8_t msg;
  const char* rest_name;     // the REST API's name (/api/v1/settings/output/comA/messages/<name>)
  std::size_t payload_bytes;
  bool ins_only;             // ELLIPSE-N / -D only (GNSS, EKF_NAV)
};
const OutputInfo& output_info(int output) noexcept;
// The output a (class, message) selects, -1 if none.
int output_of(std::uint8_t cls, std::uint8_t msg) noexcept;
// The REST API's output names, e.g. "100ms" for mode 20, "newData", "disabled";
// nullptr for a mode the REST API has no name for.
const char* rest_rate_name(std::uint16_t mode) noexcept;
// The mode of a REST rate name; -1 if none.
int rest_rate_mode(std::string_view name) noexcept;
// The output of a REST name ("imuShort"), -1 if none.
int output_named(std::string_view name) noexcept;
// The REST rate of an output's mode: FAST_IMU_DATA's 1 kHz loop (20001) is
// "1ms" there; nullptr when the REST API has no name for the mode.
const char* rest_rate_of(int output, std::uint16_t mode) noexcept;
// The mode a REST rate sets for an output; -1 if the output cannot take it
// (FAST_IMU_DATA: "1ms" or "disabled" only).
int rest_mode_of(int output, std::string_view rate) noexcept;

// What a model has.
struct ModelTraits {
  bool ins = false;            // GNSS receiver and navigation filter
  double gyro_range_rad_s = 0; // the "in range" limits of the status bits
  double accel_range_m_s2 = 0;
};
ModelTraits traits_of(SbgModel model) noexcept;
bool model_has(SbgModel model, int output) noexcept;

// What the emission thread streams: one mode per output.
struct StreamConfig {
  std::array<std::uint16_t, kOutputCount> modes{};
  bool operator==(const StreamConfig&) const = default;
};
struct EmitConfig : StreamConfig {
  // As vectornav::EmitConfig: the saved settings, streamed alone after a
  // restart fault until the io thread has taken the restart in.
  StreamConfig startup;
  std::uint64_t restarts_handled = 0;
};

// One sample in the device's units and axes.
struct Measurements {
  std::uint32_t time_stamp_us = 0;
  std::uint32_t uptime_s = 0;
  std::uint16_t imu_status = 0;
  double accel_m_s2[3]{};
  double gyro_rad_s[3]{};
  double temperature_c = 25.0;
  // Mean rates over the output's interval (IMU_DATA's delta fields, IMU_SHORT).
  double dvel_rate_m_s2[3]{};
  double dtheta_rate_rad_s[3]{};
  double mag[3]{};
  std::uint16_t mag_status = 0;
  double euler_rad[3]{};           // roll, pitch, yaw
  double euler_sigma_rad[3]{};
  double quat_wxyz[4]{1, 0, 0, 0};
  double mag_declination_rad = 0.0, mag_inclination_rad = 0.0;
  std::uint32_t solution_status = 0;
  double vel_ned_m_s[3]{};
  double vel_sigma_m_s[3]{};
  double lat_deg = 0.0, lon_deg = 0.0, alt_msl_m = 0.0;
  double undulation_m = 0.0;
  double pos_sigma_m[3]{};
  // GNSS / UTC.
  bool gnss_fix = false;
  bool time_valid = false;
  std::uint32_t gps_tow_ms = 0;
  std::uint16_t utc_year = 0;
  std::int8_t utc_month = 0, utc_day = 0, utc_hour = 0, utc_minute = 0, utc_second = 0;
  std::int32_t utc_nanosecond = 0;
  std::uint8_t gnss_sats = 0;
  double gnss_vel_acc_m_s[3]{};
  double gnss_course_deg = 0.0, gnss_course_acc_deg = 0.0;
  double gnss_pos_acc_m[3]{};
  std::uint32_t aiding_status = 0;
};

// Appends the frame of output `output` with `m` (no allocation when `out`
// has the capacity).
void append_log(int output, const Measurements& m, std::vector<std::uint8_t>& out);
// The payload alone into buf (at least 128 bytes); returns its size.
std::size_t write_log_payload(int output, const Measurements& m, std::uint8_t* buf) noexcept;

// The factory outputs of a model (docs/sbg-device.md), none when
// !config.outputs_at_power_up: what restoring the factory settings gives.
StreamConfig factory_config(const SbgDeviceConfig& config);
// The factory outputs with config.saved_outputs over them: what the device
// sends after power-up and after a reboot. Throws std::invalid_argument
// naming the saved pair that is not valid for the model.
StreamConfig power_up_config(const SbgDeviceConfig& config);
// power_up_config's refusal, if any.
std::optional<std::string> saved_outputs_problem(const SbgDeviceConfig& config);

class Device;

class Encoder final : public DeviceEncoderBase<Device, StreamConfig, kOutputCount> {
 public:
  explicit Encoder(const StreamEncoderOptions& options);
  Encoder(const Encoder& other) : Encoder(other.options_) {}
  Encoder& operator=(const Encoder& other);
  Encoder& operator=(Encoder&& other);
  ~Encoder() override;
  std::string name() const override { return "sbg"; }
  void encode(const ImuFrameInput& sample, std::vector<std::uint8_t>& out) override;
  // Every log at once on every sample (the emission buffers' size).
  std::size_t max_bytes_per_sample() const override;
  // The logs in their modes now (docs/sbg-device.md "Link budget").
  double configured_bytes_per_second(double sample_rate_hz) const override;
  StreamFrameLayout frame_layout(std::span<const std::uint8_t> frame) const override;

  Measurements measurements_of(const ImuFrameInput& sample) const;
  const ModelTraits& traits() const noexcept { return traits_; }
  // The device's command side (tests); nullptr when it answers none.
  Device* device() noexcept { return device_.get(); }

 private:
  // An output goes out at rate_per_s / divisor Hz on the scene's grid, or
  // on every sample.
  struct Schedule {
    std::uint64_t rate_per_s = 0;
    std::uint64_t divisor = 0;
    bool every_sample = false;
  };
  static Schedule schedule_of(int output, std::uint16_t mode) noexcept;
  bool due(std::uint64_t k, int output, std::uint16_t mode) const noexcept;
  ModelTraits traits_;
};

// Frames from a byte stream (`imuemu listen`): IMU_DATA, IMU_SHORT and
// FAST_IMU_DATA decode as samples; every other valid frame counts.
class Decoder final : public ResyncingDecoder {
 private:
  std::size_t decode_buffer(const SampleCallback& on_sample) override;
};

}  // namespace imuemu::drivers::sbg
