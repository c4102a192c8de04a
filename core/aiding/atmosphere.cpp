// ISA / US Standard Atmosphere 1976; see atmosphere.hpp.
#include "core/aiding/atmosphere.hpp"

#include <array>
#include <cmath>
#include <stdexcept>
#include <string>

#include "core/setting_error.hpp"

namespace imuemu::aiding {

namespace {

struct Layer {
  double base_m, base_k, lapse_k_m, base_pa;
};

// g0' M0 / R* (K/m): 0.0341632 (US 1976: 34.1632 K/km).
constexpr double kHydrostatic_k_m = kIsaStandardGravity_m_s2 * kIsaMolarMass_kg_mol / kIsaGasConstant_j_mol_k;

double layer_pressure(double base_pa, double base_k, double lapse_k_m, double dh_m) {
  if (lapse_k_m == 0.0) return base_pa * std::exp(-kHydrostatic_k_m * dh_m / base_k);
  return base_pa * std::pow(base_k / (base_k + lapse_k_m * dh_m), kHydrostatic_k_m / lapse_k_m);
}

// The table with each base pressure from the layer below (continuity).
std::array<Layer, 7> make_layers() {
  std::array<Layer, 7> l{{{0.0, 288.15, -0.0065, kIsaSeaLevelPressure_pa},
                          {11000.0, 216.65, 0.0, 0.0},
                          {20000.0, 216.65, 0.001, 0.0},
                          {32000.0, 228.65, 0.0028, 0.0},
                          {47000.0, 270.65, 0.0, 0.0},
                          {51000.0, 270.65, -0.0028, 0.0},
                          {71000.0, 214.65, -0.002, 0.0}}};
  for (std::size_t i = 1; i < l.size(); ++i)
    l[i].base_pa = layer_pressure(l[i - 1].base_pa, l[i - 1].base_k, l[i - 1].lapse_k_m, l[i].base_m - l[i - 1].base_m);
  return l;
}

const std::array<Layer, 7>& layers() {
  static const std::array<Layer, 7> l = make_layers();
  return l;
}

const SettingBound kGeopotentialBound{kIsaMinGeopotential_m, kIsaMaxGeopotential_m, "m",
                                      "the standard atmosphere's range: ICAO Doc 7488 from -5 km, US 1976 to 84.852 km"};

}  // namespace

double geopotential_from_geometric_m(double geometric_m) {
  if (!std::isfinite(geometric_m) || geometric_m <= -kIsaEarthRadius_m / 2.0)
    require_within("altitude", "geometric altitude", geometric_m, kGeopotentialBound);
  const double h = kIsaEarthRadius_m * geometric_m / (kIsaEarthRadius_m + geometric_m);
  require_within("altitude", "geopotential altitude", h, kGeopotentialBound);
  return h;
}

double geometric_from_geopotential_m(double geopotential_m) {
  require_within("altitude", "geopotential altitude", geopotential_m, kGeopotentialBound);
  return kIsaEarthRadius_m * geopotential_m / (kIsaEarthRadius_m - geopotential_m);
}

IsaState isa_at_geopotential(double geopotential_m) {
  require_within("altitude", "geopotential altitude", geopotential_m, kGeopotentialBound);
  const auto& l = layers();
  std::size_t b = 0;
  while (b + 1 < l.size() && geopotential_m >= l[b + 1].base_m) ++b;
  const double dh = geopotential_m - l[b].base_m;
  IsaState s;
  s.temperature_k = l[b].base_k + l[b].lapse_k_m * dh;
  s.pressure_pa = layer_pressure(l[b].base_pa, l[b].base_k, l[b].lapse_k_m, dh);
  s.density_kg_m3 = s.pressure_pa * kIsaMolarMass_kg_mol / (kIsaGasConstant_j_mol_k * s.temperature_k);
  return s;
}

IsaState isa_at_ellipsoidal_height(double ellipsoidal_height_m, double geoid_undulation_m) {
  require_within("geoid_undulation_m", "geoid undulation", geoid_undulation_m,
                 {-kMaxGeoidUndulation_m, kMaxGeoidUndulation_m, "m", "the Earth's geoid lies within 110 m of WGS84"});
  if (!std::isfinite(ellipsoidal_height_m))
    require_within("altitude", "ellipsoidal height", ellipsoidal_height_m, kGeopotentialBound);
  return isa_at_geopotential(geopotential_from_geometric_m(ellipsoidal_height_m - geoid_undulation_m));
}

double pressure_altitude_m(double pressure_pa) {
  const auto& l = layers();
  const double p_top = isa_at_geopotential(kIsaMaxGeopotential_m).pressure_pa;
  const double p_bottom = isa_at_geopotential(kIsaMinGeopotential_m).pressure_pa;
  require_within("pressure_pa", "pressure", pressure_pa,
                 {p_top, p_bottom, "Pa", "the standard atmosphere's pressures from 84.852 km down to -5 km"});
  std::size_t b = 0;
  while (b + 1 < l.size() && pressure_pa <= l[b + 1].base_pa) ++b;
  const Layer& y = l[b];
  // Inverse of layer_pressure within layer b.
  if (y.lapse_k_m == 0.0) return y.base_m - y.base_k / kHydrostatic_k_m * std::log(pressure_pa / y.base_pa);
  return y.base_m + y.base_k / y.lapse_k_m * (std::pow(pressure_pa / y.base_pa, -y.lapse_k_m / kHydrostatic_k_m) - 1.0);
}

}  // namespace imuemu::aiding
