// Datasheet keys and presets (core/sensor/datasheet.hpp).
#include "core/sensor/datasheet.hpp"

#include <cmath>
#include <numbers>
#include <stdexcept>

namespace imuemu::sensor {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;  // rad per degree
constexpr double kG = 9.80665;                     // m/s^2 per g (standard gravity, as datasheets use)
constexpr double kHour = 3600.0;

Vec3* vec_field(TriadSpec& s, const std::string& term) {
  if (term == "white noise") return &s.white_density;
  if (term == "bias instability") return &s.bias_instability;
  if (term == "random walk") return &s.random_walk;
  if (term == "ramp") return &s.ramp;
  if (term == "Gauss-Markov sigma") return &s.gauss_markov_sigma;
  if (term == "Gauss-Markov tau") return &s.gauss_markov_tau_s;
  if (term == "turn-on bias") return &s.turn_on_bias;
  if (term == "turn-on bias sigma") return &s.turn_on_bias_sigma;
  if (term == "scale factor") return &s.scale_factor;
  if (term == "scale factor asymmetry") return &s.scale_factor_asymmetry;
  if (term == "nonlinearity") return &s.nonlinearity;
  if (term == "misalignment") return &s.misalignment_rad;
  if (term == "non-orthogonality") return &s.non_orthogonality_rad;
  if (term == "bias temperature coefficient") return &s.bias_temperature_coeff;
  if (term == "scale factor temperature coefficient") return &s.scale_factor_temperature_coeff;
  return nullptr;
}

std::string join_keys(Triad t) {
  std::string out;
  for (const KeyInfo& k : datasheet_keys())
    if (k.triad == t) {
      if (!out.empty()) out += ", ";
      out += k.key;
    }
  return out;
}

}  // namespace

const std::vector<KeyInfo>& datasheet_keys() {
  using T = Triad;
  static const std::vector<KeyInfo> keys = {
      // ---- gyro (SI: rad/s)
      {T::gyro, "noise_density_dps_rt_hz", "white noise", "deg/s/sqrt(Hz)", kDeg},
      {T::gyro, "arw_deg_rt_h", "white noise", "deg/sqrt(h)", kDeg / 60.0},
      {T::gyro, "bias_instability_deg_h", "bias instability", "deg/h", kDeg / kHour},
      {T::gyro, "bias_instability_dps", "bias instability", "deg/s", kDeg},
      {T::gyro, "bias_instability_tau_min_s", "flicker tau min", "s", 1.0},
      {T::gyro, "bias_instability_tau_max_s", "flicker tau max", "s", 1.0},
      {T::gyro, "rrw_deg_h_rt_h", "random walk", "deg/h/sqrt(h)", kDeg / kHour / 60.0},
      {T::gyro, "rate_ramp_deg_h2", "ramp", "deg/h^2", kDeg / kHour / kHour},
      {T::gyro, "gauss_markov_sigma_deg_h", "Gauss-Markov sigma", "deg/h", kDeg / kHour},
      {T::gyro, "gauss_markov_sigma_dps", "Gauss-Markov sigma", "deg/s", kDeg},
      {T::gyro, "gauss_markov_tau_s", "Gauss-Markov tau", "s", 1.0},
      {T::gyro, "turn_on_bias_deg_h", "turn-on bias", "deg/h", kDeg / kHour},
      {T::gyro, "turn_on_bias_dps", "turn-on bias", "deg/s", kDeg},
      {T::gyro, "turn_on_bias_sigma_deg_h", "turn-on bias sigma", "deg/h", kDeg / kHour},
      {T::gyro, "turn_on_bias_sigma_dps", "turn-on bias sigma", "deg/s", kDeg},
      {T::gyro, "scale_factor_ppm", "scale factor", "ppm", 1e-6},
      {T::gyro, "scale_factor_asymmetry_ppm", "scale factor asymmetry", "ppm", 1e-6},
      {T::gyro, "nonlinearity_ppm_fs", "nonlinearity", "ppm of full scale", 1e-6},
      {T::gyro, "misalignment_mrad", "misalignment", "mrad", 1e-3},
      {T::gyro, "non_orthogonality_mrad", "non-orthogonality", "mrad", 1e-3},
      {T::gyro, "g_sensitivity_deg_s_g", "g-sensitivity", "deg/s/g", kDeg / kG},
      {T::gyro, "g_sensitivity_deg_h_g", "g-sensitivity", "deg/h/g", kDeg / kHour / kG},
      {T::gyro, "bias_temp_coeff_dps_per_c", "bias temperature coefficient", "deg/s/degC", kDeg},
      {T::gyro, "bias_temp_coeff_deg_h_per_c", "bias temperature coefficient", "deg/h/degC", kDeg / kHour},
      {T::gyro, "scale_factor_temp_coeff_ppm_per_c", "scale factor temperature coefficient", "ppm/degC", 1e-6},
      {T::gyro, "lsb_dps", "quantisation", "deg/s", kDeg},
      {T::gyro, "range_dps", "saturation", "deg/s", kDeg},
      // ---- accelerometer (SI: m/s^2)
      {T::accel, "noise_density_ug_rt_hz", "white noise", "ug/sqrt(Hz)", 1e-6 * kG},
      {T::accel, "vrw_m_s_rt_h", "white noise", "m/s/sqrt(h)", 1.0 / 60.0},
      {T::accel, "bias_instability_ug", "bias instability", "ug", 1e-6 * kG},
      {T::accel, "bias_instability_mg", "bias instability", "mg", 1e-3 * kG},
      {T::accel, "bias_instability_tau_min_s", "flicker tau min", "s", 1.0},
      {T::accel, "bias_instability_tau_max_s", "flicker tau max", "s", 1.0},
      {T::accel, "acceleration_random_walk_ug_rt_h", "random walk", "ug/sqrt(h)", 1e-6 * kG / 60.0},
      {T::accel, "acceleration_ramp_ug_h", "ramp", "ug/h", 1e-6 * kG / kHour},
      {T::accel, "gauss_markov_sigma_ug", "Gauss-Markov sigma", "ug", 1e-6 * kG},
      {T::accel, "gauss_markov_sigma_mg", "Gauss-Markov sigma", "mg", 1e-3 * kG},
      {T::accel, "gauss_markov_tau_s", "Gauss-Markov tau", "s", 1.0},
      {T::accel, "turn_on_bias_mg", "turn-on bias", "mg", 1e-3 * kG},
      {T::accel, "turn_on_bias_ug", "turn-on bias", "ug", 1e-6 * kG},
      {T::accel, "turn_on_bias_sigma_mg", "turn-on bias sigma", "mg", 1e-3 * kG},
      {T::accel, "turn_on_bias_sigma_ug", "turn-on bias sigma", "ug", 1e-6 * kG},
      {T::accel, "scale_factor_ppm", "scale factor", "ppm", 1e-6},
      {T::accel, "scale_factor_asymmetry_ppm", "scale factor asymmetry", "ppm", 1e-6},
      {T::accel, "nonlinearity_ppm_fs", "nonlinearity", "ppm of full scale", 1e-6},
      {T::accel, "misalignment_mrad", "misalignment", "mrad", 1e-3},
      {T::accel, "non_orthogonality_mrad", "non-orthogonality", "mrad", 1e-3},
      {T::accel, "bias_temp_coeff_mg_per_c", "bias temperature coefficient", "mg/degC", 1e-3 * kG},
      {T::accel, "bias_temp_coeff_ug_per_c", "bias temperature coefficient", "ug/degC", 1e-6 * kG},
      {T::accel, "scale_factor_temp_coeff_ppm_per_c", "scale factor temperature coefficient", "ppm/degC", 1e-6},
      {T::accel, "lsb_mg", "quantisation", "mg", 1e-3 * kG},
      {T::accel, "range_g", "saturation", "g", kG},
  };
  return keys;
}

const std::vector<TopKeyInfo>& temperature_keys() {
  static const std::vector<TopKeyInfo> keys = {
      {"reference_c", "degC"}, {"constant_c", "degC"}, {"start_c", "degC"}, {"end_c", "degC"}, {"warmup_tau_s", "s"}};
  return keys;
}

std::string term_of(Triad triad, const std::string& key) {
  for (const KeyInfo& k : datasheet_keys())
    if (k.triad == triad && k.key == key) return k.term;
  return "";
}

namespace {

// Sets the term of one key (values finite, the key known).
void set_term(TriadSpec& s, const KeyInfo* info, const std::string& key, const std::vector<double>& values) {
  const double f = info->to_si;
  auto one = [&]() {
    if (values.size() != 1) throw std::invalid_argument(key + ": expected one number (" + info->unit + ")");
    return values[0] * f;
  };
  if (info->term == "flicker tau min") { s.flicker_tau_min_s = one(); return; }
  if (info->term == "flicker tau max") { s.flicker_tau_max_s = one(); return; }
  if (info->term == "quantisation") { s.lsb = one(); return; }
  if (info->term == "saturation") { s.range = one(); return; }
  if (info->term == "g-sensitivity") {
    Mat3 g = Mat3::Zero();
    if (values.size() == 1) g.diagonal().setConstant(values[0] * f);
    else if (values.size() == 3) g.diagonal() = Vec3(values[0], values[1], values[2]) * f;
    else if (values.size() == 9) {
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) g(r, c) = values[static_cast<std::size_t>(3 * r + c)] * f;
    } else {
      throw std::invalid_argument(key + ": expected 1 or 3 numbers (diagonal) or 9 (row-major 3x3), " + info->unit);
    }
    s.g_sensitivity = g;
    return;
  }
  Vec3* v = vec_field(s, info->term);
  if (v == nullptr) throw std::logic_error("datasheet key without a field: " + key);
  if (values.size() == 1) v->setConstant(values[0] * f);
  else if (values.size() == 3) *v = Vec3(values[0], values[1], values[2]) * f;
  else throw std::invalid_argument(key + ": expected one number (all axes) or three (x, y, z), " + info->unit);
}

}  // namespace

void apply_key(SensorModelSpec& spec, Triad triad, const std::string& key, const std::vector<double>& values) {
  const KeyInfo* info = nullptr;
  for (const KeyInfo& k : datasheet_keys())
    if (k.triad == triad && k.key == key) info = &k;
  if (info == nullptr) {
    // A key naming a term without its unit ("noise_density", "bias_instability")
    // is refused with the keys that carry one: a number without a unit is ambiguous.
    std::string with_units;
    for (const KeyInfo& k : datasheet_keys())
      if (k.triad == triad && k.key.rfind(key + "_", 0) == 0) {
        if (!with_units.empty()) with_units += ", ";
        with_units += k.key;
      }
    if (!with_units.empty())
      throw std::invalid_argument("'" + key + "' has no unit; write one of " + with_units);
    throw std::invalid_argument("unknown key '" + key + "'; allowed: " + join_keys(triad));
  }
  for (double v : values)
    if (!std::isfinite(v)) throw std::invalid_argument(key + ": expected finite numbers");
  TriadSpec& s = triad == Triad::gyro ? spec.gyro : spec.accel;
  // The term set, then checked against its bounds (validate_term: the check
  // validate() makes, reported here at the key that set it). A refused value
  // leaves the spec as it was.
  const TriadSpec before = s;
  try {
    set_term(s, info, key, values);
    validate_term(s, triad == Triad::gyro, info->term);
  } catch (...) {
    s = before;
    throw;
  }
}

void apply_temperature_key(SensorModelSpec& spec, const std::string& key, double value) {
  if (!std::isfinite(value)) throw std::invalid_argument(key + ": expected a finite number");
  TemperatureSpec& t = spec.temperature;
  const TemperatureSpec before = t;
  if (key == "reference_c") t.reference_c = value;
  else if (key == "constant_c") t.start_c = t.end_c = value, t.warmup_tau_s = 0.0;
  else if (key == "start_c") t.start_c = value;
  else if (key == "end_c") t.end_c = value;
  else if (key == "warmup_tau_s") {
    if (value < 0.0) throw std::invalid_argument("warmup_tau_s: expected a number >= 0 s");
    t.warmup_tau_s = value;
  } else {
    throw std::invalid_argument("unknown key '" + key + "'; allowed: reference_c, constant_c, start_c, end_c, warmup_tau_s");
  }
  try {
    validate_temperature(t);  // the bounds validate() checks
  } catch (...) {
    t = before;
    throw;
  }
}

const std::vector<Preset>& presets() {
  using T = Triad;
  // Figures as the datasheets state them (docs/sensor-models.md cites each).
  static const std::vector<Preset> p = {
      {"icm42688p", "consumer MEMS: TDK InvenSense ICM-42688-P, +-2000 deg/s, +-16 g, 16-bit",
       "TDK InvenSense ICM-42688-P datasheet DS-000347 v1.7: gyro noise 2.8 mdps/sqrt(Hz), accel noise 70 ug/sqrt(Hz), "
       "full scale +-2000 dps (16.4 LSB/dps) and +-16 g (2048 LSB/g)",
       {{T::gyro, "noise_density_dps_rt_hz", {0.0028}},
        {T::gyro, "range_dps", {2000.0}},
        {T::gyro, "lsb_dps", {2000.0 / 32768.0}},
        {T::accel, "noise_density_ug_rt_hz", {70.0}},
        {T::accel, "range_g", {16.0}},
        {T::accel, "lsb_mg", {16000.0 / 32768.0}}}},
      {"adis16470", "industrial MEMS: Analog Devices ADIS16470, +-2000 deg/s, +-40 g",
       "Analog Devices ADIS16470 datasheet (Rev. C), Table 1: gyro in-run bias stability 8 deg/h, rate noise density "
       "0.008 deg/s/sqrt(Hz) rms, +-2000 deg/s; accel in-run bias stability 13 ug, velocity random walk 0.037 m/s/sqrt(h), +-40 g "
       "(UNVERIFIED: quoted second-hand; no copy of the datasheet was found to check against)",
       {{T::gyro, "noise_density_dps_rt_hz", {0.008}},
        {T::gyro, "bias_instability_deg_h", {8.0}},
        {T::gyro, "range_dps", {2000.0}},
        {T::accel, "vrw_m_s_rt_h", {0.037}},
        {T::accel, "bias_instability_ug", {13.0}},
        {T::accel, "range_g", {40.0}}}},
      {"stim300", "tactical MEMS IMU: Safran Sensonor STIM300 (10 g accelerometers)",
       "Safran Sensonor STIM300 datasheet TS1524 (rev. 24 / r9): gyro bias instability 0.5 deg/h, ARW 0.15 deg/sqrt(h), "
       "scale factor accuracy 500 ppm, bias due to acceleration 1 deg/h/g (g-compensated), misalignment 1 mrad, +-400 deg/s; "
       "accel bias instability 0.05 mg, VRW 0.06 m/s/sqrt(h), scale factor 300 ppm, misalignment 1 mrad, "
       "bias on/off repeatability 0.75 mg, +-10 g",
       {{T::gyro, "arw_deg_rt_h", {0.15}},
        {T::gyro, "bias_instability_deg_h", {0.5}},
        {T::gyro, "bias_instability_tau_min_s", {10.0}},
        {T::gyro, "bias_instability_tau_max_s", {10000.0}},
        {T::gyro, "scale_factor_ppm", {500.0}},
        {T::gyro, "g_sensitivity_deg_h_g", {1.0}},
        {T::gyro, "misalignment_mrad", {1.0}},
        {T::gyro, "range_dps", {400.0}},
        {T::accel, "vrw_m_s_rt_h", {0.06}},
        {T::accel, "bias_instability_mg", {0.05}},
        {T::accel, "bias_instability_tau_min_s", {1.0}},
        {T::accel, "bias_instability_tau_max_s", {10000.0}},
        {T::accel, "scale_factor_ppm", {300.0}},
        {T::accel, "misalignment_mrad", {1.0}},
        {T::accel, "turn_on_bias_sigma_mg", {0.75}},
        {T::accel, "range_g", {10.0}}}},
      {"hg9900", "navigation-grade ring-laser-gyro IMU: Honeywell HG9900",
       "Honeywell HG9900 IMU brochure N61-1638-000-000: gyro bias stability 0.0035 deg/h, ARW 0.002 deg/sqrt(h), "
       "scale factor 5 ppm; accel bias 25 ug, scale factor 100 ppm (1 sigma)",
       {{T::gyro, "arw_deg_rt_h", {0.002}},
        {T::gyro, "bias_instability_deg_h", {0.0035}},
        {T::gyro, "bias_instability_tau_min_s", {100.0}},
        {T::gyro, "bias_instability_tau_max_s", {100000.0}},
        {T::gyro, "scale_factor_ppm", {5.0}},
        {T::accel, "bias_instability_ug", {25.0}},
        {T::accel, "bias_instability_tau_min_s", {100.0}},
        {T::accel, "bias_instability_tau_max_s", {100000.0}},
        {T::accel, "scale_factor_ppm", {100.0}}}},
  };
  return p;
}

const Preset* find_preset(const std::string& name) {
  for (const Preset& p : presets())
    if (p.name == name) return &p;
  return nullptr;
}

SensorModelSpec preset_spec(const std::string& name) {
  const Preset* p = find_preset(name);
  if (p == nullptr) {
    std::string names;
    for (const Preset& q : presets()) {
      if (!names.empty()) names += ", ";
      names += q.name;
    }
    throw std::invalid_argument("unknown sensor preset '" + name + "'; presets: " + names + " (or ideal)");
  }
  SensorModelSpec spec;
  for (const PresetEntry& e : p->entries) apply_key(spec, e.triad, e.key, e.values);
  return spec;
}

}  // namespace imuemu::sensor
