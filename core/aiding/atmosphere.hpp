// The ISA standard atmosphere (ICAO Doc 7488/3, identical below 32 km to the
// U.S. Standard Atmosphere 1976, NOAA-S/T 76-1562, which extends it to
// 84.852 km geopotential): temperature and pressure from geopotential
// altitude, and the conversion from the height a trajectory carries (issue 28).
//
// Layers (US 1976 Table 4): base geopotential altitude H_b, base temperature
// T_b and lapse rate L_b = dT/dH,
//   b   H_b (m)   T_b (K)   L_b (K/m)
//   0        0    288.15    -0.0065   troposphere
//   1    11000    216.65     0        tropopause (isothermal)
//   2    20000    216.65    +0.001    stratosphere
//   3    32000    228.65    +0.0028
//   4    47000    270.65     0        stratopause
//   5    51000    270.65    -0.0028   mesosphere
//   6    71000    214.65    -0.002    up to 84852 m
// T(H) = T_b + L_b (H - H_b), and from the hydrostatic equation with the
// perfect gas law (US 1976 Eqs. 33a, 33b), with g0' = 9.80665 m2/(s2 m'),
// R* = 8.31432 J/(mol K), M0 = 0.0289644 kg/mol:
//   L_b != 0:  P = P_b (T_b / T(H))^(g0' M0 / (R* L_b))
//   L_b == 0:  P = P_b exp(-g0' M0 (H - H_b) / (R* T_b))
// P_0 = 101325 Pa; every further P_b is the layer below's P at H_b (not a
// rounded table value), so the profile is continuous.
// The troposphere's formula holds below sea level too: ICAO Doc 7488 tables
// start at -5000 m geopotential, which is this model's lower end.
//
// Which height. The atmosphere is layered on the geoid (mean sea level),
// and its formulas take geopotential altitude H. A trajectory carries the
// geodetic height h above the WGS84 ellipsoid (core/earth.hpp). So
//   Z = h - N                (orthometric height; N = geoid undulation at the
//                             site, stated by the caller: EGM2008 puts it in
//                             -107..+86 m, i.e. up to ~1.3 kPa at sea level,
//                             so it is not neglected silently; N = 0 takes
//                             the ellipsoid for sea level)
//   H = r0 Z / (r0 + Z)      (US 1976 Eq. 18, r0 = 6356766 m: the geometric
//                             height in a field of constant g0)
// Doc 7488 and the 1976 tables are built on that same r0 and g0, so the
// tables' geometric-altitude columns are reproduced by geometric_to_geopotential.
#pragma once

namespace imuemu::aiding {

inline constexpr double kIsaSeaLevelPressure_pa = 101325.0;
inline constexpr double kIsaSeaLevelTemperature_k = 288.15;
inline constexpr double kIsaStandardGravity_m_s2 = 9.80665;   // g0'
inline constexpr double kIsaGasConstant_j_mol_k = 8.31432;    // R* (US 1976 value)
inline constexpr double kIsaMolarMass_kg_mol = 0.0289644;     // M0
inline constexpr double kIsaEarthRadius_m = 6356766.0;        // r0 (US 1976 Eq. 18)
// The model's range in geopotential altitude.
inline constexpr double kIsaMinGeopotential_m = -5000.0;
inline constexpr double kIsaMaxGeopotential_m = 84852.0;
// Geoid undulation bound: |N| within 200 m (the Earth's is within 110 m).
inline constexpr double kMaxGeoidUndulation_m = 200.0;

struct IsaState {
  double temperature_k = kIsaSeaLevelTemperature_k;
  double pressure_pa = kIsaSeaLevelPressure_pa;
  double density_kg_m3 = 1.225;  // rho = P M0 / (R* T)
};

// H = r0 Z / (r0 + Z). Throws std::invalid_argument for a non-finite Z or
// one whose H lies outside [kIsaMinGeopotential_m, kIsaMaxGeopotential_m].
double geopotential_from_geometric_m(double geometric_m);
// Z = r0 H / (r0 - H) (inverse). Same refusals on H.
double geometric_from_geopotential_m(double geopotential_m);

// The standard atmosphere at geopotential altitude H (m). Throws
// std::invalid_argument outside [-5000, 84852] m or for NaN.
IsaState isa_at_geopotential(double geopotential_m);

// The standard atmosphere at a geodetic (ellipsoidal) height h with the
// geoid undulation N at the site: H from Z = h - N. Throws as above, and
// for |N| > kMaxGeoidUndulation_m.
IsaState isa_at_ellipsoidal_height(double ellipsoidal_height_m, double geoid_undulation_m = 0.0);

// Pressure altitude: the geopotential altitude at which the ISA pressure is
// p (the inverse of isa_at_geopotential's pressure; what an altimeter set
// to 1013.25 hPa reads). Throws for p outside the model's range or NaN.
double pressure_altitude_m(double pressure_pa);

}  // namespace imuemu::aiding
