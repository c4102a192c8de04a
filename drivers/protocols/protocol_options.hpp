// The ONE table of protocol options: every option a protocol encoder takes,
// with its name, type, allowed range, default and help. The scene parser
// (daemon/scene/scene_config.cpp, [imu.<table>] keys) and `imuemu emit`
// (--<table>-<key> flags, daemon/cli/emit_command.cpp) both read it, so a
// protocol option exists in both or in neither, with the same range.
//
// The table only describes and applies values; reading them is the caller's
// (TOML typed values with file:line:column errors in the scene parser,
// command-line text through parse_option_text() in emit).
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <set>
#include <string>
#include <variant>
#include <vector>

#include "drivers/protocols/can_protocols.hpp"
#include "drivers/protocols/stream_protocols.hpp"

namespace imuemu::drivers {

// What the encoder of any protocol is made from.
struct ProtocolOptions {
  StreamEncoderOptions stream;
  CanEncoderOptions can;
};

// text: a string the protocol itself checks (a device's identity or saved
// settings, finish_protocol_options), at most text_max_chars printable ASCII.
enum class OptionType : std::uint8_t { boolean, integer, number, choice, text };
using OptionValue = std::variant<bool, std::int64_t, double, std::string>;

struct ProtocolOption {
  std::string protocol;  // native | mavlink2 | mip | dronecan | j1939
  std::string key;       // in the protocol's table: [imu.mavlink] system_id
  OptionType type = OptionType::boolean;
  std::int64_t integer_min = 0, integer_max = 0;  // integer: inclusive
  double number_min = 0.0, number_max = 0.0;      // number: [min, max] (or (min, max])
  bool number_min_open = false;
  std::vector<std::string> choices;  // choice
  std::size_t text_max_chars = 0;    // text: its length limit...
  std::string text_form;             // ...and its form, for messages ("register writes ID,VALUES;...")
  std::string text_example;          // text: a valid value other than the default (docs, tests)
  std::string default_text;          // as the help and the docs show it
  std::string help;
  // Stores a value (of `type`, already within the range) into the options.
  std::function<void(ProtocolOptions&, const OptionValue&)> apply;
};

// The table, in documentation order.
const std::vector<ProtocolOption>& protocol_option_table();
// The rows of one protocol.
std::vector<const ProtocolOption*> protocol_options_of(const std::string& protocol);
// The name of a protocol's option table: "mavlink" for mavlink2, else the
// protocol's own name. Scene: [imu.<table>]; emit: --<table>-<key, _ as ->.
std::string protocol_option_table_name(const std::string& protocol);
// "--mavlink-system-id"
std::string command_line_flag(const ProtocolOption& option);

// What the option allows, for messages: "an integer in 1..255", "true or
// false", "one of j1939da, iso8855 or sae-j670e", "a number in (0, 1]".
std::string allowed_text(const ProtocolOption& option);

// Command-line text as the option's type (true/false/1/0/yes/no for
// booleans); throws std::invalid_argument "VALUE: what is allowed".
OptionValue parse_option_text(const ProtocolOption& option, const std::string& text);
// A text option's own limits (length, printable ASCII); what the text means
// the protocol checks in finish_protocol_options. Nothing when within them.
std::optional<std::string> text_problem(const ProtocolOption& option, const std::string& text);

// The defaults every device starts from (nominal_sample_rate_hz = rate_hz).
ProtocolOptions default_protocol_options(double rate_hz);

// Once all given options of one protocol are applied (`given` = the keys
// that were set): fills the defaults that depend on other keys (mip:
// gps_time_at_t0_ns implies time_base = gps), then checks what must hold
// between keys. Returns the first problem's key and what is wrong, or
// nothing. The encoders' own validation still runs after.
struct OptionProblem {
  std::string key;
  std::string message;
};
std::optional<OptionProblem> finish_protocol_options(const std::string& protocol, ProtocolOptions& options,
                                                     const std::set<std::string>& given);

}  // namespace imuemu::drivers
