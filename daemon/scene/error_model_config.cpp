// Error-model tables from TOML (daemon/scene/error_model_config.hpp).
#include "daemon/scene/error_model_config.hpp"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <stdexcept>

#include "core/sensor/datasheet.hpp"

namespace imuemu::scene {
namespace {

struct Where {
  const std::string& file;
  [[noreturn]] void fail(const toml::source_region& at, const std::string& key, const std::string& what) const {
    throw SceneError(file, at.begin.line, at.begin.column, key, what);
  }
};

std::string dotted(const std::string& path, std::string_view key) {
  return path.empty() ? std::string(key) : path + "." + std::string(key);
}

// The scene's key of a core field where the scene writes it in other units
// (core/signal_chain/vibration.hpp holds SI; the tables take degrees, g, ms
// and rpm): the names to try, in order.
std::vector<std::string> scene_keys_of(const std::string& field) {
  static const std::vector<std::pair<std::string, std::vector<std::string>>> renamed = {
      {"angular_rad_s", {"angular_deg_s"}},
      {"phase_rad", {"phase_deg"}},
      {"peak_m_s2", {"peak_g"}},
      {"angular_peak_rad_s2", {"angular_peak_deg_s2"}},
      {"duration_s", {"duration_ms"}},
      {"return_s", {"return_ms"}},
      {"speed", {"speed_rpm"}},
      {"psd", {"psd_g2_per_hz", "psd_rad2_s4_per_hz"}},
  };
  for (const auto& [core, scene] : renamed)
    if (core == field) return scene;
  return {field};
}

std::vector<double> numbers_of(const Where& w, const toml::node& n, const std::string& key) {
  auto number = [&](const toml::node& e) {
    if (e.is_integer()) return static_cast<double>(e.as_integer()->get());
    if (e.is_floating_point()) return e.as_floating_point()->get();
    w.fail(e.source(), key, "expected a number or an array of numbers");
  };
  std::vector<double> out;
  if (const toml::array* a = n.as_array()) {
    for (const toml::node& e : *a) out.push_back(number(e));
  } else {
    out.push_back(number(n));
  }
  for (double v : out)
    if (!std::isfinite(v)) w.fail(n.source(), key, "expected finite numbers");
  return out;
}

void parse_triad(const Where& w, const toml::table& t, const std::string& path, sensor::Triad triad,
                 sensor::SensorModelSpec& spec) {
  std::map<std::string, std::string> term_set_by;  // term -> key: two keys of one term are ambiguous
  std::vector<std::pair<const toml::key*, const toml::node*>> entries;
  for (auto&& [key, value] : t) entries.emplace_back(&key, &value);
  std::sort(entries.begin(), entries.end(),
            [](const auto& a, const auto& b) { return a.first->source().begin < b.first->source().begin; });
  for (const auto& [key, value] : entries) {
    const std::string k(key->str());
    const std::string full = dotted(path, k);
    const std::string term = sensor::term_of(triad, k);
    if (!term.empty()) {
      const auto it = term_set_by.find(term);
      if (it != term_set_by.end())
        w.fail(key->source(), full, "ambiguous: '" + it->second + "' already sets the " + term + "; give one of them");
      term_set_by.emplace(term, k);
    }
    try {
      sensor::apply_key(spec, triad, k, numbers_of(w, *value, full));
    } catch (const std::invalid_argument& e) {
      w.fail(key->source(), full, e.what());
    }
  }
}

// [signal_chain] (core/signal_chain/signal_chain.hpp):
//   preset = "icm42688p"          # ideal | icm42688p | adis16470 | stim300 | mip
//   oversampling = 8              # internal rate = oversampling x rate_hz
//   compensate_delay = false      # stamp samples t_k - group delay
//   [[...signal_chain.stage]]     # replaces the preset's stages
//   kind = "butterworth"          # low-pass | anti-alias | butterworth | notch | average | bartlett
//   frequency_hz = 100
//   order = 4                     # low-pass 1..3, butterworth 1..16
//   q = 5                         # anti-alias (default 0.7071), notch
//   length = 8                    # average, bartlett
Vec3 vec3_of(const Where& w, const toml::node& n, const std::string& key, double scale) {
  const std::vector<double> v = numbers_of(w, n, key);
  if (v.size() != 3) w.fail(n.source(), key, "expected three numbers [x, y, z] (body axes)");
  return Vec3(v[0], v[1], v[2]) * scale;
}

void only_keys(const Where& w, const toml::table& t, const std::string& path, const std::vector<std::string>& allowed) {
  for (auto&& [key, value] : t) {
    (void)value;
    if (std::find(allowed.begin(), allowed.end(), key.str()) != allowed.end()) continue;
    std::string list;
    for (const std::string& a : allowed) list += (list.empty() ? "" : ", ") + a;
    w.fail(key.source(), dotted(path, key.str()), "unknown key '" + std::string(key.str()) + "'; allowed: " + list);
  }
}

// [signal_chain.vibration] (core/signal_chain/vibration.hpp), body axes:
//   [[...vibration.sinusoid]]  frequency_hz, linear_m_s2 = [x, y, z],
//                              angular_deg_s = [x, y, z], phase_deg = [x, y, z]
//   [...vibration.random]      psd_g2_per_hz = [[f_hz, g2_per_hz], ...],
//                              axis_scale = [x, y, z], resolution_hz, seed,
//                              amplitude_scale = [[time_s, scale], ...]
//   [[...vibration.rotor]]     speed_rpm = 6000 or [[time_s, rpm], ...],
//                              jitter_rpm, jitter_bandwidth_hz, seed,
//     [[...rotor.harmonic]]    order, linear_m_s2, angular_deg_s, phase_deg
//   [...vibration.random_angular] psd_rad2_s4_per_hz = [[f_hz, (rad/s^2)^2/Hz], ...]
//                              (angular acceleration), and the same
//                              axis_scale, resolution_hz, seed, amplitude_scale
//   [[...vibration.shock]]     time_s, shape = "half_sine" | "sawtooth",
//                              peak_g = [x, y, z] and/or
//                              angular_peak_deg_s2 = [x, y, z], duration_ms, return_ms
// The lever arm and axes are the device's [imu.mounting].
double one_number(const Where& w, const toml::node& n, const std::string& key, const char* expected) {
  const std::vector<double> v = numbers_of(w, n, key);
  if (v.size() != 1) w.fail(n.source(), key, expected);
  return v[0];
}

// A [[...sinusoid]] or [[...rotor.harmonic]] table: one number > 0 under key
// (frequency_hz, order), returned, and linear_m_s2, angular_deg_s, phase_deg.
double parse_oscillation(const Where& w, const toml::node& node, const std::string& path, const std::string& key,
                         Vec3& linear_m_s2, Vec3& angular_rad_s, Vec3& phase_rad) {
  const toml::table* t = node.as_table();
  if (t == nullptr) w.fail(node.source(), path, "expected a table");
  only_keys(w, *t, path, {key, "linear_m_s2", "angular_deg_s", "phase_deg"});
  const toml::node* n = t->get(key);
  if (n == nullptr) w.fail(t->source(), path, "missing '" + key + "'");
  const double value = one_number(w, *n, dotted(path, key), "expected one number > 0");
  if (!(value > 0.0)) w.fail(n->source(), dotted(path, key), "expected one number > 0");
  constexpr double kDeg = std::numbers::pi / 180.0;
  if (const toml::node* x = t->get("linear_m_s2")) linear_m_s2 = vec3_of(w, *x, dotted(path, "linear_m_s2"), 1.0);
  if (const toml::node* x = t->get("angular_deg_s")) angular_rad_s = vec3_of(w, *x, dotted(path, "angular_deg_s"), kDeg);
  if (const toml::node* x = t->get("phase_deg")) phase_rad = vec3_of(w, *x, dotted(path, "phase_deg"), kDeg);
  return value;
}

signal_chain::Rotor parse_rotor(const Where& w, const toml::node& node, const std::string& rp) {
  const toml::table* rt = node.as_table();
  if (rt == nullptr) w.fail(node.source(), rp, "expected a table");
  only_keys(w, *rt, rp, {"speed_rpm", "jitter_rpm", "jitter_bandwidth_hz", "seed", "harmonic"});
  signal_chain::Rotor r;
  const toml::node* sp = rt->get("speed_rpm");
  if (sp == nullptr) w.fail(rt->source(), rp, "missing 'speed_rpm' (a number, or [[time_s, rpm], ...])");
  const std::string sk = dotted(rp, "speed_rpm");
  if (const toml::array* pa = sp->as_array()) {
    for (const toml::node& e : *pa) {
      const std::vector<double> pt = numbers_of(w, e, sk);
      if (pt.size() != 2) w.fail(e.source(), sk, "expected a pair [time_s, rpm]");
      r.speed.push_back({pt[0], pt[1]});
    }
  } else {
    r.speed.push_back({0.0, one_number(w, *sp, sk, "expected a number (rpm) or [[time_s, rpm], ...]")});
  }
  if (const toml::node* x = rt->get("jitter_rpm")) r.jitter_rpm = one_number(w, *x, dotted(rp, "jitter_rpm"), "expected one number");
  if (const toml::node* x = rt->get("jitter_bandwidth_hz"))
    r.jitter_bandwidth_hz = one_number(w, *x, dotted(rp, "jitter_bandwidth_hz"), "expected one number");
  if (const toml::node* x = rt->get("seed")) {
    if (!x->is_integer() || x->as_integer()->get() < 0) w.fail(x->source(), dotted(rp, "seed"), "expected an integer >= 0");
    r.seed = static_cast<std::uint64_t>(x->as_integer()->get());
  }
  const toml::node* hn = rt->get("harmonic");
  const toml::array* ha = hn != nullptr ? hn->as_array() : nullptr;
  if (ha == nullptr) w.fail(hn != nullptr ? hn->source() : rt->source(), dotted(rp, "harmonic"), "expected [[...harmonic]] tables");
  for (std::size_t i = 0; i < ha->size(); ++i) {
    signal_chain::RotorHarmonic h;
    h.order = parse_oscillation(w, (*ha)[i], dotted(rp, "harmonic[" + std::to_string(i) + "]"), "order", h.linear_m_s2,
                                h.angular_rad_s, h.phase_rad);
    r.harmonics.push_back(h);
  }
  return r;
}

signal_chain::Shock parse_shock(const Where& w, const toml::node& node, const std::string& sp) {
  const toml::table* st = node.as_table();
  if (st == nullptr) w.fail(node.source(), sp, "expected a table");
  only_keys(w, *st, sp, {"time_s", "shape", "peak_g", "angular_peak_deg_s2", "duration_ms", "return_ms"});
  signal_chain::Shock k;
  for (const char* required : {"time_s", "duration_ms"})
    if (st->get(required) == nullptr) w.fail(st->source(), sp, std::string("missing '") + required + "'");
  if (st->get("peak_g") == nullptr && st->get("angular_peak_deg_s2") == nullptr)
    w.fail(st->source(), sp, "missing 'peak_g' (linear) or 'angular_peak_deg_s2' (angular): a shock needs a peak");
  k.time_s = one_number(w, *st->get("time_s"), dotted(sp, "time_s"), "expected one number >= 0 (s since the start)");
  constexpr double kG = 9.80665;  // standard gravity: test standards give shock peaks in g
  if (const toml::node* x = st->get("peak_g")) k.peak_m_s2 = vec3_of(w, *x, dotted(sp, "peak_g"), kG);
  if (const toml::node* x = st->get("angular_peak_deg_s2"))
    k.angular_peak_rad_s2 = vec3_of(w, *x, dotted(sp, "angular_peak_deg_s2"), std::numbers::pi / 180.0);
  k.duration_s = one_number(w, *st->get("duration_ms"), dotted(sp, "duration_ms"), "expected one number > 0") * 1e-3;
  if (const toml::node* x = st->get("return_ms"))
    k.return_s = one_number(w, *x, dotted(sp, "return_ms"), "expected one number > 0") * 1e-3;
  if (const toml::node* x = st->get("shape")) {
    const std::optional<std::string> shape = x->value<std::string>();
    if (shape == "half_sine")
      k.shape = signal_chain::ShockShape::half_sine;
    else if (shape == "sawtooth")
      k.shape = signal_chain::ShockShape::sawtooth;
    else
      w.fail(x->source(), dotted(sp, "shape"), "expected \"half_sine\" or \"sawtooth\" (terminal peak)");
  }
  return k;
}

signal_chain::VibrationSpec parse_vibration_table(const Where& w, const toml::table& t, const std::string& path) {
  signal_chain::VibrationSpec v;
  only_keys(w, t, path, {"sinusoid", "random", "random_angular", "rotor", "shock"});
  if (const toml::node* n = t.get("shock")) {
    const toml::array* a = n->as_array();
    if (a == nullptr) w.fail(n->source(), dotted(path, "shock"), "expected an array of tables ([[...shock]])");
    for (std::size_t i = 0; i < a->size(); ++i) v.shocks.push_back(parse_shock(w, (*a)[i], dotted(path, "shock[" + std::to_string(i) + "]")));
  }
  if (const toml::node* n = t.get("sinusoid")) {
    const toml::array* a = n->as_array();
    if (a == nullptr) w.fail(n->source(), dotted(path, "sinusoid"), "expected an array of tables ([[...sinusoid]])");
    for (std::size_t i = 0; i < a->size(); ++i) {
      signal_chain::Sinusoid s;
      s.frequency_hz = parse_oscillation(w, (*a)[i], dotted(path, "sinusoid[" + std::to_string(i) + "]"), "frequency_hz",
                                         s.linear_m_s2, s.angular_rad_s, s.phase_rad);
      v.sinusoids.push_back(s);
    }
  }
  if (const toml::node* n = t.get("rotor")) {
    const toml::array* a = n->as_array();
    if (a == nullptr) w.fail(n->source(), dotted(path, "rotor"), "expected an array of tables ([[...rotor]])");
    for (std::size_t i = 0; i < a->size(); ++i) v.rotors.push_back(parse_rotor(w, (*a)[i], dotted(path, "rotor[" + std::to_string(i) + "]")));
  }
  // [random] (linear, g^2/Hz) and [random_angular] ((rad/s^2)^2/Hz): the
  // same table, scale and seed keys.
  auto parse_random = [&](const toml::node& n, const std::string& rp, const char* psd_key, const char* psd_pair,
                          std::vector<signal_chain::PsdPoint>& psd, Vec3& axis_scale, double& resolution_hz,
                          std::uint64_t& seed, std::vector<signal_chain::ScalePoint>& amplitude_scale) {
    const toml::table* rt = n.as_table();
    if (rt == nullptr) w.fail(n.source(), rp, "expected a table");
    only_keys(w, *rt, rp, {psd_key, "axis_scale", "resolution_hz", "seed", "amplitude_scale"});
    const toml::node* psd_node = rt->get(psd_key);
    const toml::array* pa = psd_node != nullptr ? psd_node->as_array() : nullptr;
    if (pa == nullptr) w.fail(rt->source(), dotted(rp, psd_key), std::string("expected [") + psd_pair + ", ...]");
    for (const toml::node& e : *pa) {
      const std::vector<double> pt = numbers_of(w, e, dotted(rp, psd_key));
      if (pt.size() != 2) w.fail(e.source(), dotted(rp, psd_key), std::string("expected a pair ") + psd_pair);
      psd.push_back({pt[0], pt[1]});
    }
    if (const toml::node* x = rt->get("amplitude_scale")) {
      const std::string ak = dotted(rp, "amplitude_scale");
      const toml::array* aa = x->as_array();
      if (aa == nullptr) w.fail(x->source(), ak, "expected [[time_s, scale], ...]");
      for (const toml::node& e : *aa) {
        const std::vector<double> pt = numbers_of(w, e, ak);
        if (pt.size() != 2) w.fail(e.source(), ak, "expected a pair [time_s, scale]");
        amplitude_scale.push_back({pt[0], pt[1]});
      }
    }
    if (const toml::node* x = rt->get("axis_scale")) axis_scale = vec3_of(w, *x, dotted(rp, "axis_scale"), 1.0);
    if (const toml::node* x = rt->get("resolution_hz")) {
      const std::vector<double> rv = numbers_of(w, *x, dotted(rp, "resolution_hz"));
      if (rv.size() != 1) w.fail(x->source(), dotted(rp, "resolution_hz"), "expected one number");
      resolution_hz = rv[0];
    }
    if (const toml::node* x = rt->get("seed")) {
      if (!x->is_integer() || x->as_integer()->get() < 0) w.fail(x->source(), dotted(rp, "seed"), "expected an integer >= 0");
      seed = static_cast<std::uint64_t>(x->as_integer()->get());
    }
  };
  if (const toml::node* n = t.get("random")) {
    signal_chain::RandomVibration r;
    parse_random(*n, dotted(path, "random"), "psd_g2_per_hz", "[frequency_hz, g2_per_hz]", r.psd, r.axis_scale,
                 r.resolution_hz, r.seed, r.amplitude_scale);
    v.random_linear = r;
  }
  if (const toml::node* n = t.get("random_angular")) {
    signal_chain::RandomAngularVibration r;
    std::vector<signal_chain::PsdPoint> psd;
    parse_random(*n, dotted(path, "random_angular"), "psd_rad2_s4_per_hz", "[frequency_hz, rad2_s4_per_hz]", psd,
                 r.axis_scale, r.resolution_hz, r.seed, r.amplitude_scale);
    for (const signal_chain::PsdPoint& p : psd) r.psd.push_back({p.frequency_hz, p.g2_per_hz});
    v.random_angular = r;
  }
  try {
    signal_chain::validate(v);
  } catch (const SettingError& e) {
    throw_at_setting(t, w.file, path, e);
  } catch (const std::invalid_argument& e) {
    w.fail(t.source(), path, e.what());
  }
  return v;
}

signal_chain::ChainSpec parse_chain_table(const Where& w, const toml::table& t, const std::string& path) {
  signal_chain::ChainSpec c;
  only_keys(w, t, path, {"preset", "oversampling", "compensate_delay", "stage", "vibration"});
  if (const toml::node* n = t.get("vibration")) {
    if (!n->is_table()) w.fail(n->source(), dotted(path, "vibration"), "expected a table");
    c.vibration = parse_vibration_table(w, *n->as_table(), dotted(path, "vibration"));
  }
  if (const toml::node* n = t.get("preset")) {
    if (!n->is_string()) w.fail(n->source(), dotted(path, "preset"), "expected a string (a chain preset or \"ideal\")");
    c.preset = n->as_string()->get();
    const std::vector<std::string> names = signal_chain::chain_presets();
    if (std::find(names.begin(), names.end(), c.preset) == names.end())
      w.fail(n->source(), dotted(path, "preset"),
             "unknown signal chain preset '" + c.preset + "'; expected ideal, icm42688p, adis16470, stim300 or mip");
  }
  if (const toml::node* n = t.get("oversampling")) {
    if (!n->is_integer() || n->as_integer()->get() < 1 || n->as_integer()->get() > signal_chain::kMaxOversampling)
      w.fail(n->source(), dotted(path, "oversampling"),
             "expected an integer in 1.." + std::to_string(signal_chain::kMaxOversampling) +
                 " (the internal rate as a multiple of the output rate)");
    c.oversampling = static_cast<int>(n->as_integer()->get());
  }
  if (const toml::node* n = t.get("compensate_delay")) {
    if (!n->is_boolean()) w.fail(n->source(), dotted(path, "compensate_delay"), "expected true or false");
    c.compensate_delay = n->as_boolean()->get();
  }
  if (const toml::node* n = t.get("stage")) {
    const toml::array* a = n->as_array();
    if (a == nullptr) w.fail(n->source(), dotted(path, "stage"), "expected an array of tables ([[...stage]])");
    std::vector<signal_chain::Stage> stages;
    for (std::size_t i = 0; i < a->size(); ++i) {
      const std::string sp = dotted(path, "stage[" + std::to_string(i) + "]");
      const toml::table* st = (*a)[i].as_table();
      if (st == nullptr) w.fail((*a)[i].source(), sp, "expected a table");
      signal_chain::Stage stage;
      for (auto&& [key, value] : *st) {
        const std::string k(key.str());
        const std::string full = dotted(sp, k);
        if (k == "kind") {
          if (!value.is_string()) w.fail(value.source(), full, "expected a string");
          try {
            stage.kind = signal_chain::stage_kind_from_string(value.as_string()->get());
          } catch (const std::invalid_argument& e) {
            w.fail(value.source(), full, e.what());
          }
        } else if (k == "frequency_hz" || k == "q") {
          const std::vector<double> v = numbers_of(w, value, full);
          if (v.size() != 1) w.fail(value.source(), full, "expected one number");
          (k == "q" ? stage.q : stage.frequency_hz) = v[0];
        } else if (k == "order" || k == "length") {
          if (!value.is_integer() || value.as_integer()->get() < 1 || value.as_integer()->get() > 1'000'000)
            w.fail(value.source(), full, "expected a positive integer");
          (k == "order" ? stage.order : stage.length) = static_cast<int>(value.as_integer()->get());
        } else {
          w.fail(key.source(), full, "unknown key '" + k + "'; allowed: kind, frequency_hz, order, q, length");
        }
      }
      if (!st->contains("kind")) w.fail(st->source(), sp, "missing 'kind'");
      stages.push_back(stage);
    }
    c.stages = stages;
  }
  return c;
}

}  // namespace

void throw_at_setting(const toml::table& table, const std::string& file, const std::string& key_path,
                      const SettingError& e, const std::string& suffix) {
  // Walk the key ("rotor[0].harmonic[1].order", "random.psd[3]") through the
  // table; the deepest entry found stands for the rest.
  const toml::node* node = &table;
  std::string path = key_path;
  std::string rest = e.key();
  while (!rest.empty()) {
    const std::size_t dot = rest.find('.');
    std::string part = rest.substr(0, dot);
    rest = dot == std::string::npos ? "" : rest.substr(dot + 1);
    std::optional<std::size_t> index;
    if (const std::size_t open = part.find('['); open != std::string::npos) {
      index = static_cast<std::size_t>(std::strtoull(part.c_str() + open + 1, nullptr, 10));
      part.resize(open);
    }
    const toml::table* t = node->as_table();
    const toml::node* next = nullptr;
    std::string name;
    for (const std::string& candidate : scene_keys_of(part))
      if (t != nullptr && (next = t->get(candidate)) != nullptr) {
        name = candidate;
        break;
      }
    if (next == nullptr) break;
    node = next;
    path = dotted(path, name);
    if (index) {
      const toml::array* a = node->as_array();
      if (a != nullptr && *index < a->size()) {
        node = &(*a)[*index];
        path.append(1, '[').append(std::to_string(*index)).append(1, ']');
      } else if (a != nullptr || *index != 0) {
        break;  // a one-number profile (speed_rpm = 6000) is its own point 0
      }
    }
  }
  throw SceneError(file, node->source().begin.line, node->source().begin.column, path, e.what() + suffix);
}

ErrorModelConfig parse_error_model_table(const toml::table& table, const std::string& file, const std::string& path) {
  const Where w{file};
  ErrorModelConfig out;
  static const std::vector<std::string> allowed = {"preset", "seed", "gyro", "accel", "temperature", "signal_chain"};
  // First unknown key in file order.
  const toml::key* first_unknown = nullptr;
  for (auto&& [key, value] : table) {
    (void)value;
    if (std::find(allowed.begin(), allowed.end(), key.str()) != allowed.end()) continue;
    if (first_unknown == nullptr || key.source().begin < first_unknown->source().begin) first_unknown = &key;
  }
  if (first_unknown != nullptr) {
    std::string hint;
    const std::string k(first_unknown->str());
    if (!sensor::term_of(sensor::Triad::gyro, k).empty() || !sensor::term_of(sensor::Triad::accel, k).empty())
      hint = " (per-sensor keys go in [" + dotted(path, "gyro") + "] or [" + dotted(path, "accel") + "])";
    w.fail(first_unknown->source(), dotted(path, k),
           "unknown key '" + k + "'" + hint + "; allowed: preset, seed, gyro, accel, temperature, signal_chain");
  }
  if (const toml::node* n = table.get("preset")) {
    if (!n->is_string()) w.fail(n->source(), dotted(path, "preset"), "expected a string (a preset name or \"ideal\")");
    out.preset = n->as_string()->get();
    if (out.preset != "ideal") {
      try {
        out.spec = sensor::preset_spec(out.preset);
      } catch (const std::invalid_argument& e) {
        w.fail(n->source(), dotted(path, "preset"), e.what());
      }
    }
  }
  if (const toml::node* n = table.get("seed")) {
    if (!n->is_integer() || n->as_integer()->get() < 0)
      w.fail(n->source(), dotted(path, "seed"), "expected an integer >= 0");
    out.spec.seed = static_cast<std::uint64_t>(n->as_integer()->get());
  }
  const struct {
    const char* name;
    sensor::Triad triad;
  } triads[] = {{"gyro", sensor::Triad::gyro}, {"accel", sensor::Triad::accel}};
  for (const auto& tr : triads) {
    if (const toml::node* n = table.get(tr.name)) {
      if (!n->is_table()) w.fail(n->source(), dotted(path, tr.name), "expected a table of datasheet keys");
      parse_triad(w, *n->as_table(), dotted(path, tr.name), tr.triad, out.spec);
    }
  }
  if (const toml::node* n = table.get("temperature")) {
    if (!n->is_table()) w.fail(n->source(), dotted(path, "temperature"), "expected a table");
    const toml::table& t = *n->as_table();
    if (t.contains("constant_c"))
      for (const char* k : {"start_c", "end_c", "warmup_tau_s"})
        if (const toml::node* other = t.get(k))
          w.fail(other->source(), dotted(dotted(path, "temperature"), k), "ambiguous next to constant_c: give a constant or a warm-up");
    for (auto&& [key, value] : t) {
      const std::string full = dotted(dotted(path, "temperature"), key.str());
      const std::vector<double> v = numbers_of(w, value, full);
      if (v.size() != 1) w.fail(value.source(), full, "expected one number");
      try {
        sensor::apply_temperature_key(out.spec, std::string(key.str()), v[0]);
      } catch (const std::invalid_argument& e) {
        w.fail(key.source(), full, e.what());
      }
    }
  }
  if (const toml::node* n = table.get("signal_chain")) {
    if (!n->is_table()) w.fail(n->source(), dotted(path, "signal_chain"), "expected a table");
    out.chain = parse_chain_table(w, *n->as_table(), dotted(path, "signal_chain"));
  }
  try {
    sensor::validate(out.spec);
  } catch (const std::invalid_argument& e) {
    w.fail(table.source(), path, e.what());
  }
  return out;
}

ErrorModelConfig parse_error_model_file(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SceneError(path, 0, 0, "", "cannot open the sensor model file");
  std::ostringstream text;
  text << in.rdbuf();
  toml::table root;
  try {
    root = toml::parse(text.str(), path);
  } catch (const toml::parse_error& e) {
    throw SceneError(path, e.source().begin.line, e.source().begin.column, "", "TOML syntax: " + std::string(e.description()));
  }
  return parse_error_model_table(root, path, "");
}

ErrorModelConfig error_model_from_option(const std::string& preset_or_file, std::int64_t seed) {
  ErrorModelConfig out;
  const bool looks_like_file = preset_or_file.find('/') != std::string::npos ||
                               (preset_or_file.size() > 5 && preset_or_file.ends_with(".toml"));
  if (looks_like_file) {
    out = parse_error_model_file(preset_or_file);
  } else {
    out.preset = preset_or_file;
    if (preset_or_file != "ideal") out.spec = sensor::preset_spec(preset_or_file);
  }
  if (seed >= 0) out.spec.seed = static_cast<std::uint64_t>(seed);
  return out;
}

std::vector<std::string> error_model_lines(const ErrorModelConfig& model, double rate_hz) {
  std::vector<std::string> out;
  if (model.ideal()) {
    out.push_back("ideal (no sensor errors)");
    return out;
  }
  const std::int64_t rate = static_cast<std::int64_t>(rate_hz);
  const signal_chain::ResolvedChain chain = signal_chain::resolve(model.chain, rate);
  // The sensor model runs at the chain's internal rate: its discrete values are the ones there.
  if (model.spec.is_ideal()) {
    out.push_back("no sensor errors");
  } else {
    out.push_back("preset " + model.preset + ", seed " + std::to_string(model.spec.seed) + ", terms at " +
                  std::to_string(static_cast<long long>(chain.internal_rate_hz)) + " Hz:");
    for (const sensor::TermReport& r : sensor::describe(model.spec, static_cast<double>(chain.internal_rate_hz)))
      out.push_back(r.sensor + " " + r.term + ": " + r.value + (r.discrete.empty() ? "" : " -> " + r.discrete));
  }
  for (const std::string& line : signal_chain::describe(chain, rate)) out.push_back(line);
  return out;
}

std::uint64_t grid_index(TimeNs t0_ns, TimeNs t_ns, std::int64_t rate_hz) {
  __extension__ typedef __int128 Int128;  // exact product of an int64 time and a rate
  const Int128 num = static_cast<Int128>(t_ns - t0_ns) * rate_hz;
  if (num <= 0) return 0;
  return static_cast<std::uint64_t>((num + kNsPerSecond - 1) / kNsPerSecond);
}

std::uint64_t apply_error_model(const ErrorModelConfig& model, const std::string& device, std::int64_t rate_hz,
                                TimeNs t0_ns, std::vector<ImuSample>& samples) {
  if (model.ideal()) return 0;  // the ideal sensor: no stage at all
  sensor::SensorModel m(model.spec, static_cast<double>(rate_hz), device);
  std::uint64_t saturated = 0;
  for (ImuSample& s : samples) {
    const sensor::Measurement r = m.measure(grid_index(t0_ns, s.t_ns, rate_hz), s.gyro_rad_s, s.accel_m_s2);
    s.gyro_rad_s = r.gyro_rad_s;
    s.accel_m_s2 = r.accel_m_s2;
    if (r.saturated_axes != 0) ++saturated;
  }
  return saturated;
}

}  // namespace imuemu::scene
