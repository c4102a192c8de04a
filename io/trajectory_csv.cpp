#include "io/trajectory_csv.hpp"

#include "core/limits.hpp"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <cstring>
#include <limits>
#include <system_error>
#include <utility>

#include "io/atomic_file.hpp"
#include "io/decimal_time.hpp"

namespace imuemu::io {

// ---------------------------------------------------------------- errors

namespace {

std::string compose_message(const CsvLocation& where, const std::string& detail) {
  std::string message = where.file.empty() ? std::string("<input>") : where.file;
  // Appends one piece at a time: GCC 12 gives a false -Wrestrict for
  // `":" + std::to_string(n)`.
  if (where.line != 0) {
    message += ':';
    message += std::to_string(where.line);
  }
  if (where.column_index != 0) {
    message += ": column '";
    message += detail::printable(where.column);
    message += "' (";
    message += std::to_string(where.column_index);
    message += ')';
  }
  message += ": ";
  message += detail;
  return message;
}

}  // namespace

CsvFormatError::CsvFormatError(CsvLocation where, std::string expected, std::string detail)
    : std::runtime_error(compose_message(where, detail)),
      where_(std::move(where)),
      expected_(std::move(expected)),
      detail_(std::move(detail)) {}

std::string_view to_string(PositionKind kind) noexcept {
  switch (kind) {
    case PositionKind::geodetic: return "geodetic (lat_deg, lon_deg, h_m)";
    case PositionKind::ecef: return "ECEF (x_m, y_m, z_m)";
    case PositionKind::local_ned: return "local NED (north_m, east_m, down_m)";
  }
  return "unknown";
}

std::string_view to_string(AttitudeKind kind) noexcept {
  switch (kind) {
    case AttitudeKind::heading_pitch_roll: return "heading-pitch-roll (heading_deg, pitch_deg, roll_deg)";
    case AttitudeKind::quaternion: return "quaternion q_b^l (qw, qx, qy, qz)";
    case AttitudeKind::quaternion_ecef: return "quaternion q_b^e (qw_ecef, qx_ecef, qy_ecef, qz_ecef)";
  }
  return "unknown";
}

// ---------------------------------------------------------------- tokenizer

namespace detail {

namespace {
constexpr bool is_blank(char c) noexcept { return c == ' ' || c == '\t' || c == '\r'; }

std::string_view trim(std::string_view s) noexcept {
  std::size_t b = 0;
  std::size_t e = s.size();
  while (b < e && is_blank(s[b])) ++b;
  while (e > b && is_blank(s[e - 1])) --e;
  return s.substr(b, e - b);
}
}  // namespace

CsvLineReader::CsvLineReader(std::string_view text) noexcept : text_(text) {
  // Spreadsheet exports often start with a UTF-8 byte order mark.
  if (text_.size() >= 3 && std::memcmp(text_.data(), "\xEF\xBB\xBF", 3) == 0) pos_ = 3;
}

bool split_csv_line(std::string_view raw_line, std::vector<std::string_view>& fields) {
  const std::string_view line = trim(raw_line);
  if (line.empty() || line.front() == '#') return false;
  fields.clear();
  std::size_t field_begin = 0;
  for (;;) {
    const std::size_t comma = line.find(',', field_begin);
    if (comma == std::string_view::npos) {
      fields.push_back(trim(line.substr(field_begin)));
      break;
    }
    fields.push_back(trim(line.substr(field_begin, comma - field_begin)));
    field_begin = comma + 1;
  }
  return true;
}

bool CsvLineReader::next() {
  while (pos_ < text_.size()) {
    const std::size_t begin = pos_;
    const void* newline = std::memchr(text_.data() + begin, '\n', text_.size() - begin);
    const std::size_t end =
        newline != nullptr ? static_cast<std::size_t>(static_cast<const char*>(newline) - text_.data())
                           : text_.size();
    pos_ = end + 1;
    unterminated_ = newline == nullptr;
    ++line_number_;
    if (split_csv_line(text_.substr(begin, end - begin), fields_)) return true;
  }
  return false;
}

std::string printable(std::string_view field) {
  static constexpr std::size_t kMaxShown = 40;
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out;
  out.reserve(std::min(field.size(), kMaxShown) + 8);
  std::size_t shown = 0;
  for (const char c : field) {
    if (shown == kMaxShown) {
      out += "...";
      break;
    }
    const auto byte = static_cast<unsigned char>(c);
    if (byte >= 0x20 && byte < 0x7f && byte != '\\') {
      out += c;
    } else {
      out += "\\x";
      out += kHex[byte >> 4];
      out += kHex[byte & 0xf];
    }
    ++shown;
  }
  return out;
}

std::string format_double(double value) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, value);
  return std::string(buffer, result.ptr);
}

std::size_t count_lines(std::string_view text) noexcept {
  // Lines with data only: a file of blank lines or comments must not reserve
  // a record per line (200 MB of newlines asked for 20 GB).
  std::size_t count = 0;
  std::size_t pos = 0;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string_view::npos) end = text.size();
    const std::string_view line = trim(text.substr(pos, end - pos));
    if (!line.empty() && line.front() != '#') ++count;
    pos = end + 1;
  }
  return count;
}

}  // namespace detail

// ---------------------------------------------------------------- columns

namespace {

enum class Group { time, geodetic, ecef, local_ned, hpr, quaternion, quaternion_ecef, extra };

// A column of the format: its rule, and where its value goes in a record.
struct ColumnSpec : ColumnRule {
  Group group;
  int slot;  // index within the group's vector
};

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kMaxM = limits::kMaxPositionM;  // core/limits.hpp

constexpr std::array<ColumnSpec, 21> kColumns{{
    {{"time_s", "a time in decimal seconds (digits, optional sign and '.', no exponent)", 0, 0}, Group::time, 0},
    {{"lat_deg", "a latitude in [-90, 90] degrees", -90.0, 90.0}, Group::geodetic, 0},
    {{"lon_deg", "a finite longitude in degrees", -kInf, kInf}, Group::geodetic, 1},
    {{"h_m", "an ellipsoidal height in [-1e9, 1e9] metres", -kMaxM, kMaxM}, Group::geodetic, 2},
    {{"x_m", "an ECEF coordinate in [-1e9, 1e9] metres", -kMaxM, kMaxM}, Group::ecef, 0},
    {{"y_m", "an ECEF coordinate in [-1e9, 1e9] metres", -kMaxM, kMaxM}, Group::ecef, 1},
    {{"z_m", "an ECEF coordinate in [-1e9, 1e9] metres", -kMaxM, kMaxM}, Group::ecef, 2},
    {{"north_m", "a coordinate in [-1e9, 1e9] metres", -kMaxM, kMaxM}, Group::local_ned, 0},
    {{"east_m", "a coordinate in [-1e9, 1e9] metres", -kMaxM, kMaxM}, Group::local_ned, 1},
    {{"down_m", "a coordinate in [-1e9, 1e9] metres", -kMaxM, kMaxM}, Group::local_ned, 2},
    {{"heading_deg", "a finite heading in degrees", -kInf, kInf}, Group::hpr, 0},
    {{"pitch_deg", "a pitch in [-90, 90] degrees", -90.0, 90.0}, Group::hpr, 1},
    {{"roll_deg", "a finite roll in degrees", -kInf, kInf}, Group::hpr, 2},
    {{"qw", "a finite quaternion component", -kInf, kInf}, Group::quaternion, 0},
    {{"qx", "a finite quaternion component", -kInf, kInf}, Group::quaternion, 1},
    {{"qy", "a finite quaternion component", -kInf, kInf}, Group::quaternion, 2},
    {{"qz", "a finite quaternion component", -kInf, kInf}, Group::quaternion, 3},
    {{"qw_ecef", "a finite quaternion component", -kInf, kInf}, Group::quaternion_ecef, 0},
    {{"qx_ecef", "a finite quaternion component", -kInf, kInf}, Group::quaternion_ecef, 1},
    {{"qy_ecef", "a finite quaternion component", -kInf, kInf}, Group::quaternion_ecef, 2},
    {{"qz_ecef", "a finite quaternion component", -kInf, kInf}, Group::quaternion_ecef, 3},
}};

// First kColumns index of each group, for the rule look-ups below.
constexpr std::size_t kGeodeticFirst = 1, kEcefFirst = 4, kLocalNedFirst = 7, kHprFirst = 10,
                      kQuaternionFirst = 13, kQuaternionEcefFirst = 17;
static_assert(kColumns[kGeodeticFirst].group == Group::geodetic && kColumns[kEcefFirst].group == Group::ecef &&
              kColumns[kLocalNedFirst].group == Group::local_ned && kColumns[kHprFirst].group == Group::hpr &&
              kColumns[kQuaternionFirst].group == Group::quaternion &&
              kColumns[kQuaternionEcefFirst].group == Group::quaternion_ecef &&
              kColumns[kQuaternionEcefFirst + 3].slot == 3);

const ColumnSpec* find_column(std::string_view name) noexcept {
  for (const ColumnSpec& spec : kColumns) {
    if (spec.name == name) return &spec;
  }
  return nullptr;
}

struct GroupInfo {
  Group group;
  std::string_view label;
  std::array<std::string_view, 4> names;
  int size;
};

constexpr std::array<GroupInfo, 3> kPositionGroups{{
    {Group::geodetic, "geodetic position", {"lat_deg", "lon_deg", "h_m", ""}, 3},
    {Group::ecef, "ECEF position", {"x_m", "y_m", "z_m", ""}, 3},
    {Group::local_ned, "local NED position", {"north_m", "east_m", "down_m", ""}, 3},
}};
constexpr std::array<GroupInfo, 3> kAttitudeGroups{{
    {Group::hpr, "heading-pitch-roll attitude", {"heading_deg", "pitch_deg", "roll_deg", ""}, 3},
    {Group::quaternion, "quaternion attitude", {"qw", "qx", "qy", "qz"}, 4},
    {Group::quaternion_ecef, "ECEF quaternion attitude", {"qw_ecef", "qx_ecef", "qy_ecef", "qz_ecef"}, 4},
}};

std::string group_columns(const GroupInfo& g) {
  std::string out;
  for (int k = 0; k < g.size; ++k) {
    if (k != 0) out += ",";
    out += g.names[static_cast<std::size_t>(k)];
  }
  return out;
}

std::string all_column_names() {
  std::string out;
  for (const ColumnSpec& spec : kColumns) {
    if (!out.empty()) out += ", ";
    out += spec.name;
  }
  return out;
}

// One header column: its spec (nullptr for an ignored extra column) and name.
struct HeaderColumn {
  const ColumnSpec* spec = nullptr;
  std::string name;
};

struct HeaderLayout {
  std::vector<HeaderColumn> columns;
  std::size_t header_line = 0;
  PositionKind position_kind = PositionKind::geodetic;
  AttitudeKind attitude_kind = AttitudeKind::heading_pitch_roll;
  std::size_t quaternion_w_column = 0;  // 0-based index of qw / qw_ecef (for messages)
  std::size_t time_column = 0;          // 0-based index of time_s
};

[[noreturn]] void fail_trajectory_csv(const std::string& file, std::size_t line, std::string column,
                       std::size_t column_index, std::string expected, std::string detail) {
  throw TrajectoryFormatError(CsvLocation{file, line, std::move(column), column_index},
                              std::move(expected), std::move(detail));
}

// Picks the single complete group among `groups` present in the header.
template <std::size_t N>
Group resolve_group(const std::array<GroupInfo, N>& groups, const std::vector<HeaderColumn>& columns,
                    const std::string& file, std::size_t header_line, std::string_view what) {
  std::array<int, N> present{};
  for (const HeaderColumn& c : columns) {
    if (c.spec == nullptr) continue;
    for (std::size_t g = 0; g < N; ++g) {
      if (c.spec->group == groups[g].group) ++present[g];
    }
  }
  std::string options;
  for (std::size_t g = 0; g < N; ++g) {
    if (g != 0) options += " or ";
    options += group_columns(groups[g]);
  }
  const std::string expected = "exactly one complete " + std::string(what) + " group: " + options;
  std::size_t chosen = N;
  for (std::size_t g = 0; g < N; ++g) {
    if (present[g] == 0) continue;
    if (chosen != N) {
      fail_trajectory_csv(file, header_line, "", 0, expected,
           "ambiguous " + std::string(what) + ": the header has columns of both the " +
               std::string(groups[chosen].label) + " (" + group_columns(groups[chosen]) +
               ") and the " + std::string(groups[g].label) + " (" + group_columns(groups[g]) +
               ") groups; expected " + expected);
    }
    chosen = g;
  }
  if (chosen == N) {
    fail_trajectory_csv(file, header_line, "", 0, expected,
         "missing " + std::string(what) + " columns: expected " + expected);
  }
  if (present[chosen] != groups[chosen].size) {
    std::string missing;
    for (int k = 0; k < groups[chosen].size; ++k) {
      const std::string_view name = groups[chosen].names[static_cast<std::size_t>(k)];
      const bool found = std::any_of(columns.begin(), columns.end(), [&](const HeaderColumn& c) {
        return c.spec != nullptr && c.spec->name == name;
      });
      if (!found) missing += (missing.empty() ? "'" : ", '") + std::string(name) + "'";
    }
    fail_trajectory_csv(file, header_line, "", 0, expected,
         "incomplete " + std::string(groups[chosen].label) + ": missing column(s) " + missing +
             "; expected all of " + group_columns(groups[chosen]));
  }
  return groups[chosen].group;
}

void parse_header(const std::vector<std::string_view>& fields, std::size_t line, const std::string& file,
                  const TrajectoryReadOptions& options, HeaderLayout& layout) {
  layout.header_line = line;
  layout.columns.reserve(fields.size());
  for (std::size_t i = 0; i < fields.size(); ++i) {
    const std::string_view name = fields[i];
    if (name.empty()) {
      fail_trajectory_csv(file, line, "", i + 1, "a column name",
           "header column " + std::to_string(i + 1) + " has an empty name (a stray comma?)");
    }
    const ColumnSpec* spec = find_column(name);
    if (spec == nullptr && !options.allow_extra_columns) {
      fail_trajectory_csv(file, line, std::string(name), i + 1, "a known column name",
           "unknown column name; expected one of " + all_column_names() +
               " (names are case-sensitive)");
    }
    if (spec != nullptr) {
      for (std::size_t j = 0; j < i; ++j) {
        if (layout.columns[j].spec == spec) {
          fail_trajectory_csv(file, line, std::string(name), i + 1, "each column once",
               "duplicate column (also column " + std::to_string(j + 1) + ")");
        }
      }
    }
    layout.columns.push_back(HeaderColumn{spec, std::string(name)});
  }
  const bool has_time = std::any_of(layout.columns.begin(), layout.columns.end(), [](const HeaderColumn& c) {
    return c.spec != nullptr && c.spec->group == Group::time;
  });
  if (!has_time) fail_trajectory_csv(file, line, "", 0, "a time_s column", "missing column 'time_s'");

  switch (resolve_group(kPositionGroups, layout.columns, file, line, "position")) {
    case Group::geodetic: layout.position_kind = PositionKind::geodetic; break;
    case Group::ecef: layout.position_kind = PositionKind::ecef; break;
    default: layout.position_kind = PositionKind::local_ned; break;
  }
  switch (resolve_group(kAttitudeGroups, layout.columns, file, line, "attitude")) {
    case Group::hpr: layout.attitude_kind = AttitudeKind::heading_pitch_roll; break;
    case Group::quaternion: layout.attitude_kind = AttitudeKind::quaternion; break;
    default: layout.attitude_kind = AttitudeKind::quaternion_ecef; break;
  }
  if (!kinds_compatible(layout.position_kind, layout.attitude_kind)) {
    fail_trajectory_csv(file, line, "", 0, "an Earth-fixed position with an ECEF attitude",
         "an ECEF attitude (qw_ecef, ...) needs an Earth-fixed position (lat_deg,lon_deg,h_m or "
         "x_m,y_m,z_m), not a local NED one");
  }
  for (std::size_t i = 0; i < layout.columns.size(); ++i) {
    const ColumnSpec* spec = layout.columns[i].spec;
    if (spec != nullptr && spec->slot == 0 &&
        (spec->group == Group::quaternion || spec->group == Group::quaternion_ecef)) {
      layout.quaternion_w_column = i;
    }
    if (spec != nullptr && spec->group == Group::time) layout.time_column = i;
  }
}

// An integer time too large for seconds is almost always an integer count of
// nanoseconds (Unix or GPS time in ns has 19 digits: 1717243200123456789):
// the refusal says that time_s is in seconds and, when the value divided by
// 1e9 fits, gives it exactly (the decimal point moved 9 digits, no double).
std::string integer_time_hint(std::string_view field, NumberStatus status) {
  if (status != NumberStatus::out_of_range) return {};
  std::string_view digits = field;
  std::string_view sign;
  if (!digits.empty() && (digits.front() == '+' || digits.front() == '-')) {
    sign = digits.substr(0, 1);
    digits.remove_prefix(1);
  }
  const bool integer = !digits.empty() && std::all_of(digits.begin(), digits.end(), [](char c) {
    return c >= '0' && c <= '9';
  });
  std::string hint = "; time_s is in seconds (from -9223372036.854775808 to 9223372036.854775807 s)";
  if (!integer || digits.size() <= 9) return hint;
  std::string seconds(sign);
  seconds.append(digits.substr(0, digits.size() - 9));
  std::string_view fraction = digits.substr(digits.size() - 9);
  while (!fraction.empty() && fraction.back() == '0') fraction.remove_suffix(1);
  if (!fraction.empty()) {
    seconds += '.';
    seconds.append(fraction);
  }
  if (try_parse_decimal_seconds(seconds).status != NumberStatus::ok) return hint;
  return hint + ": if this is an integer count of nanoseconds, divide it by 1e9 and write '" + seconds + "'";
}

// Whether the record's position is at a geographic pole: latitude +-90 deg,
// or an ECEF position within 1 mm of the z axis (where a tool converting to
// geodetic finds no meridian). A field that does not parse counts as not
// at a pole (its own column reports it).
bool record_at_pole(const HeaderLayout& layout, const std::vector<std::string_view>& fields) {
  double value[3] = {0.0, 0.0, 0.0};
  bool found[3] = {false, false, false};
  for (std::size_t k = 0; k < layout.columns.size() && k < fields.size(); ++k) {
    const ColumnSpec* spec = layout.columns[k].spec;
    if (spec == nullptr || (spec->group != Group::geodetic && spec->group != Group::ecef)) continue;
    const DoubleParse v = try_parse_double(fields[k]);
    if (v.status != NumberStatus::ok) return false;
    value[spec->slot] = v.value;
    found[spec->slot] = true;
  }
  if (layout.position_kind == PositionKind::geodetic) return found[0] && std::abs(value[0]) == 90.0;
  if (layout.position_kind == PositionKind::ecef) return found[0] && found[1] && std::hypot(value[0], value[1]) <= 1e-3;
  return false;
}

// At a pole every direction is south (or north): a tool that writes the
// heading as `nan` there is right that "heading from north" has no meaning.
// imuemu's local NED frame at a pole is Eq. 1.5 at the record's own
// longitude (core/attitude.hpp ned_to_ecef: north there is the northward
// direction of the meridian at lon_deg), so the heading is
// measured from that north; or the attitude is given in ECEF, which has no
// singularity. The knot is refused rather than guessed: its attitude about
// the vertical is the one thing the record does not give.
std::string pole_heading_message(std::string_view field) {
  return "got '" + detail::printable(field) +
         "' at a pole, where heading from north is undefined; imuemu's north at a pole is the northward "
         "direction of the record's own meridian (thesis Eq. 1.5 at latitude +-90 deg and the record's "
         "longitude): write the heading from that north, or give the attitude as qw_ecef,qx_ecef,qy_ecef,qz_ecef "
         "(body to ECEF, defined everywhere)";
}

// One data line against the header (docs/trajectory-format.md): field count,
// number syntax, ranges, the predecessor's time, the unit quaternion.
void parse_record_fields(const HeaderLayout& layout, const std::string& file,
                         const std::vector<std::string_view>& fields, std::size_t line, TrajectoryRecord& record,
                         const TrajectoryLineParser::Predecessor* predecessor) {
  const std::size_t width = layout.columns.size();
  if (fields.size() != width) {
    fail_trajectory_csv(file, line, "", 0, std::to_string(width) + " fields",
         "expected " + std::to_string(width) + " comma-separated fields as named by the header (line " +
             std::to_string(layout.header_line) + "), got " + std::to_string(fields.size()));
  }
  record = TrajectoryRecord{};
  record.position_kind = layout.position_kind;
  record.attitude_kind = layout.attitude_kind;
  record.line = line;
  for (std::size_t i = 0; i < width; ++i) {
    const ColumnSpec* spec = layout.columns[i].spec;
    if (spec == nullptr) continue;  // allowed extra column
    const std::string_view field = fields[i];
    if (spec->group == Group::time) {
      const TimeParse t = try_parse_decimal_seconds(field);
      if (t.status != NumberStatus::ok) {
        fail_trajectory_csv(file, line, layout.columns[i].name, i + 1, std::string(spec->expected),
             "expected " + std::string(spec->expected) + ", got '" + detail::printable(field) + "' (" +
                 std::string(describe(t.status)) + ")" + integer_time_hint(field, t.status));
      }
      record.t_ns = t.ns;
      continue;
    }
    const DoubleParse v = try_parse_double(field);
    if (v.status == NumberStatus::not_finite && spec->group == Group::hpr && spec->slot == 0 &&
        record_at_pole(layout, fields)) {
      fail_trajectory_csv(file, line, layout.columns[i].name, i + 1, std::string(spec->expected), pole_heading_message(field));
    }
    if (v.status != NumberStatus::ok) {
      fail_trajectory_csv(file, line, layout.columns[i].name, i + 1, std::string(spec->expected),
           "expected " + std::string(spec->expected) + ", got '" + detail::printable(field) + "' (" +
               std::string(describe(v.status)) + ")");
    }
    if (v.value < spec->min || v.value > spec->max) {
      fail_trajectory_csv(file, line, layout.columns[i].name, i + 1, std::string(spec->expected),
           "expected " + std::string(spec->expected) + ", got '" + detail::printable(field) + "'");
    }
    switch (spec->group) {
      case Group::geodetic:
      case Group::ecef:
      case Group::local_ned: record.position[spec->slot] = v.value; break;
      default: record.attitude[spec->slot] = v.value; break;
    }
  }
  if (predecessor != nullptr && record.t_ns <= predecessor->t_ns) {
    const std::size_t tc = layout.time_column;
    fail_trajectory_csv(file, line, layout.columns[tc].name, tc + 1, "a time after the previous record's",
         "time " + detail::printable(fields[tc]) + " s is not after the previous record's " +
             detail::printable(predecessor->time_text) + " s (line " + std::to_string(predecessor->line) + ")");
  }
  if (layout.attitude_kind != AttitudeKind::heading_pitch_roll) {
    // The components are finite but may be huge: squaring 1e200 gives inf,
    // which the tolerance test rejects like any other non-unit quaternion.
    double norm = 0.0;
    if (!normalise_unit_quaternion(record.attitude, norm)) {
      const std::size_t qc = layout.quaternion_w_column;
      fail_trajectory_csv(file, line, layout.columns[qc].name, qc + 1, "a unit quaternion",
           "expected a unit quaternion (|q| within 1e-6 of 1), got |q| = " + detail::format_double(norm));
    }
  }
}

}  // namespace

// ---------------------------------------------------------------- value rules

const ColumnRule& position_column_rule(PositionKind kind, int component) noexcept {
  const std::size_t first = kind == PositionKind::geodetic ? kGeodeticFirst
                            : kind == PositionKind::ecef   ? kEcefFirst
                                                           : kLocalNedFirst;
  return kColumns[first + static_cast<std::size_t>(std::clamp(component, 0, 2))];
}

const ColumnRule& attitude_column_rule(AttitudeKind kind, int component) noexcept {
  const std::size_t first = kind == AttitudeKind::heading_pitch_roll ? kHprFirst
                            : kind == AttitudeKind::quaternion       ? kQuaternionFirst
                                                                     : kQuaternionEcefFirst;
  return kColumns[first + static_cast<std::size_t>(std::clamp(component, 0, attitude_component_count(kind) - 1))];
}

int attitude_component_count(AttitudeKind kind) noexcept {
  return kind == AttitudeKind::heading_pitch_roll ? 3 : 4;
}

bool kinds_compatible(PositionKind position, AttitudeKind attitude) noexcept {
  return !(attitude == AttitudeKind::quaternion_ecef && position == PositionKind::local_ned);
}

bool normalise_unit_quaternion(Eigen::Vector4d& q, double& norm) noexcept {
  norm = q.norm();
  if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) return false;
  q /= norm;
  return true;
}

// ---------------------------------------------------------------- line parser

struct TrajectoryLineParser::Layout : HeaderLayout {};

TrajectoryLineParser::TrajectoryLineParser(std::string source_name, TrajectoryReadOptions options)
    : source_name_(std::move(source_name)), options_(options) {}
TrajectoryLineParser::~TrajectoryLineParser() = default;
TrajectoryLineParser::TrajectoryLineParser(TrajectoryLineParser&&) noexcept = default;
TrajectoryLineParser& TrajectoryLineParser::operator=(TrajectoryLineParser&&) noexcept = default;

void TrajectoryLineParser::parse_header(const std::vector<std::string_view>& fields, std::size_t line) {
  auto layout = std::make_unique<Layout>();
  imuemu::io::parse_header(fields, line, source_name_, options_, *layout);
  layout_ = std::move(layout);
}

void TrajectoryLineParser::parse_record(const std::vector<std::string_view>& fields, std::size_t line,
                                        TrajectoryRecord& out, const Predecessor* predecessor) const {
  if (!layout_) throw std::logic_error(source_name_ + ": TrajectoryLineParser::parse_record before a header");
  parse_record_fields(*layout_, source_name_, fields, line, out, predecessor);
}

TrajectoryLineParser::LineKind TrajectoryLineParser::feed(std::string_view line, TrajectoryRecord& out) {
  ++line_number_;
  // Spreadsheet exports often start with a UTF-8 byte order mark.
  if (line_number_ == 1 && line.size() >= 3 && std::memcmp(line.data(), "\xEF\xBB\xBF", 3) == 0) {
    line.remove_prefix(3);
  }
  if (!detail::split_csv_line(line, fields_)) return LineKind::skipped;
  if (!has_header()) {
    parse_header(fields_, line_number_);
    return LineKind::header;
  }
  parse_record(fields_, line_number_, out);
  return LineKind::record;
}

std::size_t TrajectoryLineParser::header_line() const noexcept { return layout_->header_line; }
PositionKind TrajectoryLineParser::position_kind() const noexcept { return layout_->position_kind; }
AttitudeKind TrajectoryLineParser::attitude_kind() const noexcept { return layout_->attitude_kind; }
std::size_t TrajectoryLineParser::time_column() const noexcept { return layout_->time_column; }

// ---------------------------------------------------------------- whole files

Trajectory parse_trajectory_csv(std::string_view text, const std::string& source_name,
                                const TrajectoryReadOptions& options) {
  const std::string& file = source_name;
  detail::CsvLineReader reader(text);
  if (!reader.next()) {
    fail_trajectory_csv(file, 0, "", 0, "a header row",
         "no header row: the file is empty or holds only comments and blank lines");
  }
  TrajectoryLineParser parser(source_name, options);
  parser.parse_header(reader.fields(), reader.line_number());

  Trajectory trajectory;
  trajectory.source = source_name;
  trajectory.position_kind = parser.position_kind();
  trajectory.attitude_kind = parser.attitude_kind();
  // The records this text can hold (its data lines after the header),
  // checked against the knot cap before they are reserved.
  const std::size_t data_lines = detail::count_lines(text);
  if (data_lines > limits::kMaxKnots + 1)
    throw limits::SizeLimitError(file + ": " + std::to_string(data_lines - 1) + " records: more than the " +
                                 std::to_string(limits::kMaxKnots) + " knots a trajectory may hold (split it)");
  trajectory.records.reserve(data_lines);

  bool have_previous = false;
  TrajectoryLineParser::Predecessor previous;
  while (reader.next()) {
    // As for pose lines (docs/pose-wire-format.md §1): a last line without
    // its newline may be a number cut short (`2.` of `2.900`), which would
    // parse; a file still being written must not yield a wrong knot.
    if (reader.unterminated()) {
      fail_trajectory_csv(file, reader.line_number(), "", 0, "a line ending in a newline",
           "the file ends inside this record (no final newline): it is cut off or still being written; a "
           "partial record is not used (add the newline if the line is complete)");
    }
    TrajectoryRecord& record = trajectory.records.emplace_back();
    parser.parse_record(reader.fields(), reader.line_number(), record, have_previous ? &previous : nullptr);
    have_previous = true;
    previous = {record.t_ns, reader.fields()[parser.time_column()], record.line};
  }
  if (trajectory.records.empty()) {
    fail_trajectory_csv(file, 0, "", 0, "at least one record",
         "no records after the header (line " + std::to_string(parser.header_line()) + ")");
  }
  return trajectory;
}

Trajectory read_trajectory_csv(const std::string& path, const TrajectoryReadOptions& options) {
  std::string text;
  if (const int error = read_whole_file(path, text); error != 0) {
    fail_trajectory_csv(path, 0, "", 0, "a readable file",
         "cannot read the trajectory file: " + std::generic_category().message(error));
  }
  return parse_trajectory_csv(text, path, options);
}

}  // namespace imuemu::io
