#include "drivers/protocols/stream_protocols.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>

#include "drivers/protocols/mavlink2.hpp"
#include "drivers/protocols/mip.hpp"
#include "drivers/protocols/native.hpp"
#include "drivers/protocols/nmea.hpp"
#include "drivers/protocols/ubx.hpp"
#include "drivers/protocols/vectornav.hpp"
#include "drivers/protocols/vectornav_device.hpp"
#include "drivers/protocols/sbg.hpp"
#include "drivers/protocols/xsens.hpp"

namespace imuemu::drivers {

namespace {

std::string joined_names() {
  std::string s;
  for (const std::string& n : stream_protocol_names()) s += (s.empty() ? "" : ", ") + n;
  return s;
}

void check_options(const std::string& protocol, const StreamEncoderOptions& o) {
  if (!std::isfinite(o.nominal_sample_rate_hz) || o.nominal_sample_rate_hz < 0.0) {
    throw std::invalid_argument("stream protocol '" + protocol +
                                "': nominal_sample_rate_hz must be finite and >= 0 (0 = unknown)");
  }
  if (protocol == "mip") {
    const MipDeviceConfig& d = o.mip_device;
    for (const auto& [key, value] : {std::pair<const char*, const std::string*>{"model_name", &d.model_name},
                                     {"model_number", &d.model_number},
                                     {"serial_number", &d.serial_number},
                                     {"lot_number", &d.lot_number},
                                     {"device_options", &d.device_options}}) {
      // Get Device Information (0x01,0x03) carries each as 16 characters.
      if (value->size() > 16)
        throw std::invalid_argument(std::string("stream protocol 'mip': device ") + key + " '" + *value +
                                    "' is longer than the 16 characters of its Get Device Information field");
    }
  }
  if (protocol == "vectornav") {
    const VectorNavDeviceConfig& v = o.vectornav;
    // The identity registers are comma-separated ASCII fields of one sentence.
    auto field_text = [](const std::string& key, const std::string& value, std::size_t max) {
      const bool printable = std::all_of(value.begin(), value.end(), [](char c) {
        return c >= ' ' && c <= '~' && c != ',' && c != '*' && c != '$';
      });
      if (value.size() > max || !printable)
        throw std::invalid_argument("stream protocol 'vectornav': " + key + " '" + value + "' must be at most " +
                                    std::to_string(max) + " printable characters without , * or $");
    };
    field_text("model_number", v.model_number, 24);
    field_text("firmware_version", v.firmware_version, 24);
    field_text("user_tag", v.user_tag, 20);
    if (v.port != 1 && v.port != 2)
      throw std::invalid_argument("stream protocol 'vectornav': port must be 1 or 2 (the device's serial ports)");
    const bool rate_ok = std::find(vectornav::kAdofRates.begin(), vectornav::kAdofRates.end(), v.power_up_adof_hz) !=
                         vectornav::kAdofRates.end();
    if (!rate_ok)
      throw std::invalid_argument("stream protocol 'vectornav': power_up_adof_hz " + std::to_string(v.power_up_adof_hz) +
                                  " is not one of register 7's rates (1, 2, 4, 5, 10, 20, 25, 40, 50, 100, 200)");
    if (v.power_up_ador > 255 ||
        (v.power_up_ador > 0 && vectornav::ador_header(static_cast<std::uint8_t>(v.power_up_ador)) == nullptr) ||
        (v.power_up_ador == vectornav::kAdorIns && v.model == VectorNavModel::vn100))
      throw std::invalid_argument("stream protocol 'vectornav': power_up_ador " + std::to_string(v.power_up_ador) +
                                  " is not an async output this model sends");
    for (const double g : v.mag_reference_ned_gauss)
      if (!std::isfinite(g) || std::fabs(g) > 10.0)
        throw std::invalid_argument("stream protocol 'vectornav': the magnetic reference must be finite, within 10 gauss");
    if (const std::optional<std::string> problem = vectornav::saved_registers_problem(v))
      throw std::invalid_argument("stream protocol 'vectornav': saved_registers: " + *problem);
  }
  if (protocol == "sbg") {
    const SbgDeviceConfig& c = o.sbg;
    // [I] the product code is a 32-byte NUL-terminated field (and a JSON string).
    const bool printable = std::all_of(c.product_code.begin(), c.product_code.end(),
                                       [](char ch) { return ch > ' ' && ch <= '~' && ch != '"' && ch != '\\'; });
    if (c.product_code.size() > 31 || !printable)
      throw std::invalid_argument("stream protocol 'sbg': product_code '" + c.product_code +
                                  "' must be at most 31 printable characters without spaces, \" or \\");
    for (const double g : c.mag_reference_ned_gauss)
      if (!std::isfinite(g) || std::fabs(g) > 10.0)
        throw std::invalid_argument("stream protocol 'sbg': the magnetic reference must be finite, within 10 gauss");
    if (const std::optional<std::string> problem = sbg::saved_outputs_problem(c))
      throw std::invalid_argument("stream protocol 'sbg': saved_outputs: " + *problem);
  }
  if (protocol == "xsens") {
    const XsensDeviceConfig& x = o.xsens;
    // ReqProductCode's answer: at most 20 printable characters ([L] ProductCode).
    const bool printable = std::all_of(x.product_code.begin(), x.product_code.end(), [](char c) { return c > ' ' && c <= '~'; });
    if (x.product_code.size() > 20 || !printable)
      throw std::invalid_argument("stream protocol 'xsens': product_code '" + x.product_code +
                                  "' must be at most 20 printable characters without spaces");
    unsigned a = 0, b = 0, c = 0;
    char rest = 0;
    if (!x.firmware_version.empty() &&
        (std::sscanf(x.firmware_version.c_str(), "%u.%u.%u%c", &a, &b, &c, &rest) != 3 || a > 255 || b > 255 || c > 255))
      throw std::invalid_argument("stream protocol 'xsens': firmware_version '" + x.firmware_version +
                                  "' must be major.minor.revision (each 0..255)");
    if (x.baud != 4800 && x.baud != 9600 && x.baud != 14400 && x.baud != 19200 && x.baud != 28800 && x.baud != 38400 &&
        x.baud != 57600 && x.baud != 76800 && x.baud != 115200 && x.baud != 230400 && x.baud != 460800 &&
        x.baud != 921600 && x.baud != 2000000)
      throw std::invalid_argument("stream protocol 'xsens': baud " + std::to_string(x.baud) +
                                  " is not one of SetBaudrate's rates");
    for (const double v : x.mag_reference_ned_au)
      if (!std::isfinite(v) || std::fabs(v) > 10.0)
        throw std::invalid_argument("stream protocol 'xsens': the magnetic reference must be finite, within 10 a.u.");
  }
  if (is_gnss_protocol(protocol)) {
    if (o.nmea_talker != "GP" && o.nmea_talker != "GN")
      throw std::invalid_argument("stream protocol '" + protocol + "': talker '" + o.nmea_talker +
                                  "' is not GP or GN");
  }
  if (protocol == "mavlink2") {
    // MAVLink guide, packet format: 0 is the broadcast address, never a
    // valid source system or component.
    if (o.mavlink_system_id == 0) {
      throw std::invalid_argument("stream protocol 'mavlink2': system id must be 1..255 (0 is broadcast)");
    }
    if (o.mavlink_component_id == 0) {
      throw std::invalid_argument(
          "stream protocol 'mavlink2': component id must be 1..255 (0 is MAV_COMP_ID_ALL)");
    }
    // The barometer and magnetometer models step once per sample at the
    // device's rate.
    if ((o.mavlink_baro || o.mavlink_mag) && !(o.nominal_sample_rate_hz > 0.0)) {
      throw std::invalid_argument(
          "stream protocol 'mavlink2': baro and mag need the device's rate (nominal_sample_rate_hz > 0)");
    }
    if (o.mavlink_hil_gps_rate_hz < 0 || o.mavlink_hil_gps_rate_hz > 50) {
      throw std::invalid_argument("stream protocol 'mavlink2': hil_gps_rate_hz must be 0..50");
    }
    if (!o.mavlink_hil_sensor && !o.mavlink_highres_imu) {
      throw std::invalid_argument(
          "stream protocol 'mavlink2': enable HIL_SENSOR or HIGHRES_IMU (or both); neither sends no samples");
    }
  }
}

}  // namespace

std::vector<std::string> stream_protocol_names() { return {"native", "mavlink2", "mip", "nmea", "ubx", "vectornav", "sbg", "xsens"}; }

bool is_gnss_protocol(const std::string& protocol) { return protocol == "nmea" || protocol == "ubx"; }

std::unique_ptr<StreamEncoder> make_stream_encoder(const std::string& protocol,
                                                   const StreamEncoderOptions& options) {
  check_options(protocol, options);
  if (protocol == "native") return std::make_unique<native::Encoder>(options.include_deltas);
  if (protocol == "mavlink2") return std::make_unique<mavlink2::Encoder>(options);
  if (protocol == "mip") return std::make_unique<mip::Encoder>(options);
  if (protocol == "nmea") return std::make_unique<nmea::Encoder>(options);
  if (protocol == "ubx") return std::make_unique<ubx::Encoder>(options);
  if (protocol == "vectornav") return std::make_unique<vectornav::Encoder>(options);
  if (protocol == "sbg") return std::make_unique<sbg::Encoder>(options);
  if (protocol == "xsens") return std::make_unique<xsens::Encoder>(options);
  throw std::invalid_argument("unknown stream protocol '" + protocol + "' (expected one of: " + joined_names() +
                              ")");
}

std::unique_ptr<StreamDecoder> make_stream_decoder(const std::string& protocol,
                                                   const StreamEncoderOptions& options) {
  check_options(protocol, options);
  if (protocol == "native") return std::make_unique<native::Decoder>();
  if (protocol == "mavlink2") return std::make_unique<mavlink2::Decoder>(options);
  if (protocol == "mip") return std::make_unique<mip::Decoder>(options);
  if (protocol == "nmea") return std::make_unique<nmea::Decoder>();
  if (protocol == "ubx") return std::make_unique<ubx::Decoder>();
  if (protocol == "vectornav") return std::make_unique<vectornav::Decoder>();
  if (protocol == "sbg") return std::make_unique<sbg::Decoder>();
  if (protocol == "xsens") return std::make_unique<xsens::Decoder>();
  throw std::invalid_argument("unknown stream protocol '" + protocol + "' (expected one of: " + joined_names() +
                              ")");
}

}  // namespace imuemu::drivers
