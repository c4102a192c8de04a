// `imuemu protocol-options`: every key of the protocol option table
// (drivers/protocols/protocol_options.hpp), the one table the scene's
// [imu.<protocol>] keys and emit's --<protocol>-<key> options are read
// through: type, allowed values, default and meaning. --markdown prints the
// reference block of docs/scene-format.md (and so of imuemu-scene(5));
// tests/cli/test_protocol_options.cpp keeps the two equal.
#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include "daemon/cli/commands.hpp"
#include "drivers/protocols/protocol_options.hpp"

namespace imuemu::cli {
namespace {

const char* type_name(drivers::OptionType t) {
  switch (t) {
    case drivers::OptionType::boolean:
      return "boolean";
    case drivers::OptionType::integer:
      return "integer";
    case drivers::OptionType::number:
      return "number";
    case drivers::OptionType::choice:
    case drivers::OptionType::text:
      return "string";
  }
  return "";
}

// A Markdown table cell: '|' would end the cell.
std::string cell(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '|') out += "\\|";
    else out += c;
  }
  return out;
}

}  // namespace

int protocol_options(bool markdown) {
  // One section per protocol, in the table's order of first appearance (a
  // protocol's rows need not be contiguous in the table).
  std::vector<std::string> protocols;
  for (const drivers::ProtocolOption& o : drivers::protocol_option_table())
    if (std::find(protocols.begin(), protocols.end(), o.protocol) == protocols.end()) protocols.push_back(o.protocol);
  for (const std::string& protocol : protocols) {
    const std::string table = drivers::protocol_option_table_name(protocol);
    if (markdown) {
      std::cout << "\n#### `[imu." << table << "]` (protocol `" << protocol << "`)\n\n"
                << "| key | type | allowed | default | meaning |\n|---|---|---|---|---|\n";
    } else {
      std::cout << "\n[imu." << table << "] (protocol " << protocol << "; emit: --" << table << "-KEY)\n";
    }
    for (const drivers::ProtocolOption* o : drivers::protocol_options_of(protocol)) {
      if (markdown) {
        std::cout << "| `" << o->key << "` | " << type_name(o->type) << " | " << cell(drivers::allowed_text(*o)) << " | "
                  << cell(o->default_text) << " | " << cell(o->help) << " |\n";
      } else {
        std::cout << "  " << o->key << " (" << type_name(o->type) << "): " << drivers::allowed_text(*o)
                  << "; default " << o->default_text << "\n      " << o->help << "\n";
      }
    }
  }
  return kOk;
}

}  // namespace imuemu::cli
